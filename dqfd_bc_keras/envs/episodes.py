"""A policy played on an env for one complete episode per seed: the one loop behind greedy
evaluations, videos, recorded demonstrations, dynamic demonstrations' roll-outs and the experts'
returns. It steps the env it is given, so the wrappers on it (`wrappers.CountInteractions`)
count every step as they always do, and an episode ends at terminated or truncated alike.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import NamedTuple, Protocol

import gymnasium as gym
import numpy as np


class Watcher(Protocol):
    """Sees every episode as it is played (`recording.EpisodeRecorder`): its first observation, then each step."""

    def reset(self, obs: np.ndarray) -> None: ...

    def step(
        self, action: int, next_obs: np.ndarray, reward: float, terminated: bool, truncated: bool, info: dict
    ) -> None: ...


class Played(NamedTuple):
    """Per episode: its undiscounted return, its steps, and `info["goals"]` at its end (0 where absent)."""

    returns: list[float]
    lengths: list[int]
    goals: list[int]


def play(
    env: gym.Env,
    policy: Callable[[np.ndarray], int],
    seeds: Iterable[int],
    watcher: Watcher | None = None,
    progress: Callable[[int], None] | None = None,
) -> Played:
    """One episode of `policy` on `env` per seed, reset with it; `progress(done)` is called after
    each episode. The env is left open: its caller may play on it again."""
    played = Played([], [], [])
    for done, seed in enumerate(seeds, 1):
        obs, info = env.reset(seed=int(seed))
        if watcher is not None:
            watcher.reset(obs)
        total, steps, over = 0.0, 0, False
        while not over:
            action = policy(obs)
            obs, reward, terminated, truncated, info = env.step(action)
            if watcher is not None:
                watcher.step(action, obs, reward, terminated, truncated, info)
            total, steps, over = total + float(reward), steps + 1, terminated or truncated
        played.returns.append(total)
        played.lengths.append(steps)
        played.goals.append(int(info.get("goals", 0)))
        if progress is not None:
            progress(done)
    return played
