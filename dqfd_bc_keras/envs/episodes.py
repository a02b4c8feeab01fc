"""A policy played on an env for one complete episode per seed: the one loop behind greedy
evaluations, videos, recorded demonstrations, dynamic demonstrations' roll-outs and the experts'
returns; and `EvalResult`, what greedy episodes of a policy scored (light: the lab reads it
without TensorFlow). It steps the env it is given, so the wrappers on it (`wrappers.CountInteractions`)
count every step as they always do, and an episode ends at terminated or truncated alike.
"""

from __future__ import annotations

import statistics
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple, Protocol, SupportsFloat

import gymnasium as gym
import numpy as np

from dqfd_bc_keras.envs.make import get_task
from dqfd_bc_keras.errors import ConfigError


class Policy(Protocol):
    """What plays an episode: obs → an int action (a checked `recording.Demonstrator`, a greedy network)."""

    def __call__(self, obs: np.ndarray, /) -> int: ...


class Watcher(Protocol):
    """Sees every episode as it is played (`recording.EpisodeRecorder`): its first observation and
    the seed the env was reset with (to play it again), then each step."""

    def reset(self, obs: np.ndarray, seed: int | None) -> None: ...

    def step(
        self, action: int, next_obs: np.ndarray, reward: SupportsFloat, terminated: bool, truncated: bool, info: dict
    ) -> None: ...


class Played(NamedTuple):
    """Per episode: its undiscounted return, its steps, and `info["goals"]` at its end (0 where absent)."""

    returns: list[float]
    lengths: list[int]
    goals: list[int]


def play(
    env: gym.Env,
    policy: Policy,
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
            watcher.reset(obs, int(seed))
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


def check_video(directory: str | Path, prefix: str) -> None:
    """A one-line `ConfigError` before anything is played if MP4s named `prefix` cannot be written
    in `directory`: no encoder (moviepy), a file in its place, videos that would be overwritten."""
    try:
        import moviepy  # noqa: F401  (RecordVideo's encoder)
    except ImportError:
        raise ConfigError("--video needs moviepy: pip install -r requirements-extras.txt") from None
    directory = Path(directory)
    if directory.is_file():
        raise ConfigError(f"--video {directory}: is a file, not a directory")
    if any(directory.glob(f"{prefix}-episode-*.mp4")):
        raise ConfigError(
            f"--video {directory}: already holds {prefix} videos, which would be overwritten; choose another directory"
        )


def video_env(env: gym.Env, directory: str | Path, prefix: str) -> gym.Env:
    """`env` writing each episode as `directory/prefix-episode-K.mp4` (Gymnasium's `RecordVideo`;
    its last file is written when it is closed). Call `check_video` first."""
    return gym.wrappers.RecordVideo(
        env, str(directory), episode_trigger=lambda _: True, name_prefix=prefix, disable_logger=True
    )


@dataclass
class EvalResult:
    """Greedy episodes of one policy: returns and lengths on the plain env, goals on the task env."""

    task: str
    policy: str
    """"q" (the Q-network), "bc" (the BC model) or, for any other callable, "custom"."""
    seed: int
    """Episode i was reset with seed + i."""
    returns: list[float]
    lengths: list[int]
    goals: list[int] | None = None
    """Flags reached per episode (goal-count tasks only)."""
    timeout: str = "bootstrap"
    env_kwargs: dict[str, Any] = field(default_factory=dict)

    @property
    def mean_return(self) -> float:
        return statistics.fmean(self.returns)

    @property
    def std_return(self) -> float:
        return statistics.pstdev(self.returns)

    def to_dict(self) -> dict:
        result = {
            "task": self.task,
            "env_id": get_task(self.task).env_id,
            "policy": self.policy,
            "timeout": self.timeout,
            "episodes": len(self.returns),
            "seed": self.seed,
            "returns": self.returns,
            "mean_return": self.mean_return,
            "std_return": self.std_return,
            "min_return": min(self.returns),
            "max_return": max(self.returns),
            "lengths": self.lengths,
        }
        if self.goals is not None:
            result.update(goals=self.goals, mean_goals=statistics.fmean(self.goals))
        if self.env_kwargs:
            result["env_kwargs"] = self.env_kwargs
        return result

    def summary(self) -> str:
        n, env_id = len(self.returns), get_task(self.task).env_id
        lines = [
            f"{self.task}{'' if env_id == self.task else f' ({env_id})'}, {self.policy} policy, {n} greedy episodes "
            f"(seeds {self.seed}..{self.seed + n - 1})",
            f"return {self.mean_return:.2f} ± {self.std_return:.2f}  "
            f"(min {min(self.returns):g}, max {max(self.returns):g}, {solved_text(self.task)})",
            f"length {statistics.fmean(self.lengths):.1f} steps on average",
        ]
        if self.goals is not None:
            lines.append(f"goals per episode {statistics.fmean(self.goals):.2f} on average: {self.goals}")
        return "\n".join(lines)


def solved_text(task: str) -> str:
    threshold = get_task(task).solved_return
    return "no solved threshold" if threshold is None else f"solved at {threshold:g}"
