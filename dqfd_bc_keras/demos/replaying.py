"""Replaying a demonstrations file (`python -m dqfd_bc_keras.demos show FILE`): each episode is
reset with its recorded seed, its recorded actions are applied, and every observation, reward and
flag the env gives is checked against the file's, so a file from another version of the env (or
of its package) says so in one line instead of teaching the learner another game. The episodes
are shown in the window, written as MP4s, or only checked. Any demonstrator's file replays: a
person's, a scripted expert's, a model's, the agent's own.

Episodes replay in the file's order on one env, as they were played: an Atari life after the
first continues the game the one before it left (the env ignores the seed of such a reset).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import gymnasium as gym
import numpy as np

from dqfd_bc_keras.demos.dataset import DemoDataset
from dqfd_bc_keras.demos.npz import load
from dqfd_bc_keras.demos.window import Window
from dqfd_bc_keras.envs.episodes import check_video, video_env
from dqfd_bc_keras.envs.make import get_task, make_task, step_limit, task_slug
from dqfd_bc_keras.errors import ConfigError, DemoFileError

SHOW_FPS = 30
"""Steps per second to show a program's demonstrations at, on a task without a rate of its own."""


def _same(path: Path, episode: int, step: int, what: str, got: object, recorded: np.ndarray, env_id: str) -> None:
    """A `DemoFileError` unless the env gave exactly what the file recorded."""
    got = np.asarray(got).astype(recorded.dtype)
    if not np.array_equal(got, recorded):
        gap = np.max(np.abs(got.astype(np.float64) - recorded.astype(np.float64)))
        raise DemoFileError(
            path,
            f"episode {episode}, step {step}: the env gives another {what} than the file holds (largest "
            f"difference {gap:.3g}); was it recorded with another version of {env_id} or of its package?",
        )


@dataclass
class Screen:
    """Where a replay is shown: the window, the episode's title, the rate and the step limit."""

    window: Window
    title: str
    fps: float
    limit: int

    def frame(self, env: gym.Env, step: int, ret: float, paused: bool) -> bool | None:
        """Draw the frame after `step` steps and wait; True to pause or go on (P), None to quit."""
        got = self.window.poll()
        if got.closed or "quit" in got.controls:
            return None
        paused ^= "pause" in got.controls
        state = "paused: P to go on" if paused else f"replaying at {self.fps:g} steps/s, checked against the file"
        progress = f"return {ret:g} · step {step} · {self.limit - step} steps left"
        self.window.draw(env.render(), [self.title, progress, state, "P pause · Esc quit"])
        self.window.tick(self.fps)
        return paused


def _replay(
    path: Path, env: gym.Env, index: int, seed: int, episode: DemoDataset, screen: Screen | None
) -> float | None:
    """Replay episode `index` from its seed, checking each step; its plain return, None if the person quit."""
    obs, _ = env.reset(seed=seed)
    env_id = episode.meta.env_id
    _same(path, index, 0, "first observation", obs, episode.obs[0], env_id)
    ret, t, paused = 0.0, 0, False
    while t < len(episode):
        if screen is not None:
            answer = screen.frame(env, t, ret, paused)
            if answer is None:
                return None
            paused = answer
            if paused:
                continue
        obs, reward, terminated, truncated, info = env.step(int(episode.actions[t]))
        for what, value, recorded in (
            ("observation", obs, episode.next_obs[t]),
            ("reward", reward, episode.rewards[t]),
            ("termination", terminated, episode.terminated[t]),
            ("truncation", truncated, episode.truncated[t]),
        ):
            _same(path, index, t + 1, what, value, recorded, env_id)
        ret += info["plain_reward"]
        t += 1
    return ret


def show(
    path: str | Path,
    *,
    window: bool = True,
    video: str | Path | None = None,
    fps: float | None = None,
    report: Callable[[str], None] | None = print,
) -> DemoDataset:
    """Replay the demonstrations in `path` and check them step by step; show them in a window (at
    `fps`, default the rate they were played at, else the preset's), or with `video` write one MP4
    per episode in that directory instead, or with neither only check. Returns the dataset.
    Raises `DemoFileError` at the first step the env does not give what the file holds."""
    path = Path(path)
    dataset = load(path)
    m = dataset.meta
    seeds = [seed for seed in m.episode_seeds if seed is not None]
    if len(seeds) < len(m.episode_seeds):
        raise DemoFileError(
            path,
            f"episode {m.episode_seeds.index(None)} has no recorded reset seed (a file of format 1, or an "
            "episode reset without one), so it cannot be replayed",
        )
    if fps is not None and fps <= 0:
        raise ConfigError(f"fps must be > 0, got {fps}")
    fps = fps or m.fps or get_task(m.task).fps or SHOW_FPS
    prefix = f"{task_slug(m.task)}-demo"
    if video is not None:
        check_video(video, prefix)
    render = "rgb_array" if window or video is not None else None
    env = make_task(m.task, m.timeout, m.max_steps, render_mode=render, env_kwargs=m.env_kwargs)
    if video is not None:
        env, window = video_env(env, video, prefix), False
    screen = Window(f"dqfd_bc_keras - {path.name}") if window else None
    limit = step_limit(m.task, m.max_steps)
    try:
        for i, (seed, episode) in enumerate(zip(seeds, dataset.episodes(), strict=True)):
            title = f"{path.name} · episode {i + 1} of {dataset.n_episodes} (seed {seed}) · by {m.expert}"
            ret = _replay(path, env, i, seed, episode, Screen(screen, title, fps, limit) if screen else None)
            if ret is None:
                break
            if report is not None:
                report(f"episode {i}: {len(episode)} steps, return {ret:g} (seed {seed}): replayed exactly")
    finally:
        env.close()  # RecordVideo writes the last episode's file
        if screen is not None:
            screen.close()
    return dataset
