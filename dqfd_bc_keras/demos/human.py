"""A person's demonstrations: the env in a window, the keyboard as the policy, each finished
episode written to the file as it ends (`python -m dqfd_bc_keras.demos play`).

What is recorded is what every demonstrator records (`recording.EpisodeRecorder`): the learner's
observations, the task's rewards, the plain returns, the flags at the limit and each episode's
reset seed, with `expert: "human"`, the key map and the frame rate in the meta. The file is
rewritten atomically after every finished episode, so quitting, closing the window, Ctrl-C or a
kill loses at most the episode in play. An episode starts when the person presses Enter or an
action key; P pauses, Backspace discards the episode in play, Esc quits (`keys.CONTROLS`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym

from dqfd_bc_keras.demos.dataset import DemoDataset, concatenate
from dqfd_bc_keras.demos.keys import KeyMap, key_map, played_like
from dqfd_bc_keras.demos.minari import dataset_dir
from dqfd_bc_keras.demos.minari_export import check_exportable, to_minari
from dqfd_bc_keras.demos.npz import load, save
from dqfd_bc_keras.demos.recording import EpisodeRecorder
from dqfd_bc_keras.demos.window import Window
from dqfd_bc_keras.envs.atari import is_atari, split_kwargs
from dqfd_bc_keras.envs.make import get_task, make_task, step_limit
from dqfd_bc_keras.errors import ConfigError, OutputExistsError
from dqfd_bc_keras.files import check_writable

HUMAN = "human"
"""The `expert` of a person's demonstrations."""
ENV_FPS = 30
"""Steps per second for an env that is no preset and names no rate of its own."""


def default_fps(task: str, env: gym.Env, env_kwargs: Mapping[str, Any] | None) -> float:
    """The preset's rate (`keys.played_like`: also a preset's env given as `--env`); for an Atari
    game real time (60 frames/s over its frame skip); else the env's `render_fps` (highway-env's
    is 2), at most `ENV_FPS`."""
    spec = get_task(task)
    preset = played_like(spec)
    if preset is not None and preset.fps is not None:
        return preset.fps
    if is_atari(spec.env_id):
        return 60 / split_kwargs(dict(env_kwargs or {}))[0].frame_skip
    return min(float(env.metadata.get("render_fps") or ENV_FPS), ENV_FPS)


def _previous(out: str, append: bool, force: bool, task: str, timeout: str, env_kwargs) -> DemoDataset | None:
    """The episodes `--append` continues (checked to be a person's, on the same task, kwargs and
    spaces), or None; an existing `out` is refused unless `append` or `force`."""
    minari = out.startswith("minari:")
    if not minari and not out.endswith(".npz"):
        raise ConfigError(f"--out must be an .npz file or minari:DATASET_ID, got {out!r}")
    if append and minari:
        raise ConfigError("--append continues an .npz file; record to one and export it to Minari (demos export)")
    if minari:
        dataset_id = out.removeprefix("minari:")
        check_exportable(task, timeout, dict(env_kwargs or {}), dataset_id)
        if dataset_dir(dataset_id).exists() and not force:
            raise OutputExistsError(f"{out}: a Minari dataset of that id exists; pass --force to replace it")
        return None
    check_writable(out)  # before the window opens: a played episode is never lost to an unwritable --out
    if not append:
        if Path(out).exists() and not force:
            raise OutputExistsError(f"{out} exists; pass --append to add episodes to it or --force to overwrite it")
        return None
    if not Path(out).exists():
        return None
    previous = load(out, task=task, timeout=timeout, env_kwargs=env_kwargs)
    if previous.meta.expert != HUMAN:
        raise ConfigError(
            f"{out}: holds demonstrations by {previous.meta.expert!r}, not a person's; choose another --out"
        )
    return previous


def _check_same_play(out: str, previous: DemoDataset, keys: KeyMap, fps: float, limit: int) -> None:
    """Appended episodes are played as the file's were: one key map, frame rate and step limit per file."""
    m = previous.meta
    for what, was, now, flag in (
        ("key map", m.keys, keys.keys, "--keys"),
        ("frame rate", m.fps, fps, "--fps"),
        ("step limit", m.max_steps, limit, "--max-steps"),
    ):
        if was != now:
            raise ConfigError(f"{out}: its episodes were played with {what} {was}, not {now}: give {flag} {was}")


CONTROLS_TEXT = "Enter start · P pause · Backspace discard the episode · Esc quit"


def _keys_and_pace(
    task: str, env: gym.Env, keys: Mapping[str, int] | str | None, fps: float | None, env_kwargs: Mapping | None
) -> tuple[KeyMap, float]:
    """The key map and the steps per second `task` is played with on `env`: the given ones, else its own."""
    keymap = key_map(get_task(task), env, keys)
    fps = float(fps) if fps is not None else default_fps(task, env, env_kwargs)
    if fps <= 0:
        raise ConfigError(f"fps must be > 0, got {fps}")
    return keymap, fps


def legend(keymap: KeyMap) -> str:
    """The key map as the window shows it."""
    return "keys: " + " · ".join(keymap.legend())


def controls(
    task: str,
    *,
    keys: Mapping[str, int] | str | None = None,
    fps: float | None = None,
    max_steps: int | None = None,
    env_kwargs: dict[str, Any] | None = None,
) -> list[str]:
    """How `play` would play `task`, without a window (`play --list-keys`): the action keys as the
    window lists them, where the map comes from, the pace and the control keys."""
    env = make_task(task, max_steps=max_steps, env_kwargs=env_kwargs)
    try:
        keymap, fps = _keys_and_pace(task, env, keys, fps, env_kwargs)
    finally:
        env.close()
    return [f"{legend(keymap)} (from {keymap.source})", f"pace: {fps:g} steps/s (--fps changes it)", CONTROLS_TEXT]


def play(
    task: str,
    out: str | Path,
    episodes: int | None = None,
    *,
    keys: Mapping[str, int] | str | None = None,
    fps: float | None = None,
    seed: int | None = None,
    append: bool = False,
    force: bool = False,
    timeout: str = "bootstrap",
    max_steps: int | None = None,
    env_kwargs: dict[str, Any] | None = None,
    report: Callable[[str], None] | None = print,
) -> DemoDataset | None:
    """A person plays `task` in a window for `episodes` episodes (None: until they quit); every
    finished episode is written to `out` (an .npz file, or `minari:DATASET_ID`) as it ends.

    `keys`: a key map (keys.py) or its JSON, else the preset's or the env's own. `fps`: steps per
    second (default: the preset's). Episode i resets with `seed` + i (with `append`, after the
    file's last seed). Returns the dataset written (with the episodes appended to), None if no
    episode finished. `report` gets one line per finished episode."""
    out = str(out)
    if episodes is not None and episodes < 1:
        raise ConfigError(f"episodes must be ≥ 1, got {episodes}")
    previous = _previous(out, append, force, task, timeout, env_kwargs)
    limit = step_limit(task, max_steps)
    env = make_task(task, timeout, max_steps, render_mode="rgb_array", env_kwargs=env_kwargs)
    try:
        keymap, fps = _keys_and_pace(task, env, keys, fps, env_kwargs)
        if previous is not None:
            _check_same_play(out, previous, keymap, fps, limit)
        known = [s for s in previous.meta.episode_seeds if s is not None] if previous is not None else []
        first = seed if seed is not None else max(known, default=-1) + 1
        recorder = EpisodeRecorder(
            env, task=task, source=HUMAN, seed=first, env_kwargs=env_kwargs, keys=keymap.keys, fps=fps
        )
        window = Window(f"dqfd_bc_keras - {task}")
        try:
            return _record(Player(window, env, recorder, keymap, fps, limit), previous, out, episodes, report)
        finally:
            window.close()
    finally:
        env.close()


STATES = {
    "waiting": "press Enter or an action key to start",
    "paused": "paused: P to go on",
    "playing": "playing at {fps:g} steps/s",
}
"""What the window says in each state of an episode."""


@dataclass
class Player:
    """One person's session: the window, the task env, its recorder, the keys and the rate."""

    window: Window
    env: gym.Env
    recorder: EpisodeRecorder
    keymap: KeyMap
    fps: float
    limit: int

    def episode(self, seed: int, title: str, saved: str) -> tuple[str, float, int]:
        """Play one episode reset with `seed`: ("over" | "discarded" | "quit", its plain return, its steps).
        It waits for Enter or an action key pressed (a key still held from the last episode is not),
        then steps at `fps` with the keys down as the action. `title` and `saved` are shown."""
        obs, _ = self.env.reset(seed=seed)
        self.recorder.reset(obs, seed)
        state, ret, steps, action = "waiting", 0.0, 0, None
        while True:
            got = self.window.poll()
            if got.closed or "quit" in got.controls:
                return "quit", ret, steps
            if "discard" in got.controls:
                return "discarded", ret, steps
            if "pause" in got.controls and state != "waiting":
                state = "paused" if state == "playing" else "playing"
            if state == "waiting" and ("start" in got.controls or got.pressed & self.keymap.names()):
                state = "playing"
            if state == "playing":
                action = self.keymap.action(got.down, action)
            over = False
            if state == "playing" and action is not None:
                obs, reward, terminated, truncated, info = self.env.step(action)
                self.recorder.step(action, obs, float(reward), terminated, truncated, info)
                ret, steps, over = ret + info["plain_reward"], steps + 1, terminated or truncated
            lines = [
                f"{self.recorder.task} · {title} · {saved}",
                f"return {ret:g} · step {steps} · {self.limit - steps} steps left",
                STATES[state].format(fps=self.fps),
                legend(self.keymap),
                CONTROLS_TEXT,
            ]
            self.window.draw(self.env.render(), lines)
            self.window.tick(self.fps)
            if over:
                return "over", ret, steps


def _record(
    player: Player,
    previous: DemoDataset | None,
    out: str,
    episodes: int | None,
    report: Callable[[str], None] | None,
) -> DemoDataset | None:
    """Episodes until `episodes` are kept or the person quits, each written as it ends; returns what was written."""
    written, seed, kept = None, player.recorder.seed, 0
    before = previous.n_episodes if previous is not None else 0  # `--append`: the numbers go on from the file's
    try:
        while episodes is None or kept < episodes:
            title = f"episode {before + kept + 1}{'' if episodes is None else f' of {before + episodes}'} (seed {seed})"
            saved = f"{written.n_episodes if written else before} saved in {Path(out).name}"
            outcome, ret, steps = player.episode(seed, title, saved)
            seed += 1
            if outcome == "quit":
                break
            if outcome == "over":
                kept += 1
                recorded = player.recorder.dataset()
                written = recorded if previous is None else concatenate([previous, recorded], HUMAN)
                _write(written, out)
                if report is not None:
                    report(f"{title}: return {ret:g} in {steps} steps; {out} holds {written.n_episodes} episode(s)")
    except KeyboardInterrupt as interrupt:
        kept_text = f"{out} holds the {written.n_episodes} finished episode(s)" if written else "no episode finished"
        raise type(interrupt)(kept_text) from None
    return written


def _write(dataset: DemoDataset, out: str) -> None:
    """The whole dataset, atomically: a kill leaves the file as it was after the last finished episode."""
    if out.startswith("minari:"):
        to_minari(dataset, out.removeprefix("minari:"), force=True)
    else:
        save(dataset, out, force=True)
