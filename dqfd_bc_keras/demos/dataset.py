"""Demonstration datasets in memory: transitions of complete episodes in time order, their
metadata, and the invariants every dataset holds however it was made (recorded, loaded from a
file, converted from Minari).

The arrays (`ARRAYS`), one row per transition:

    obs (N, d) float32   actions (N,) int64   rewards (N,) float32   next_obs (N, d) float32
    terminated (N,) bool   truncated (N,) bool   episode_ids (N,) int64

`obs` are the flat vectors the networks take (`observations`: a Dict is flattened), or, for a
task observed in frames, uint8 arrays (N, *meta.obs_shape); `meta.observation` names the env's
own space. Every episode is complete (its last transition is
terminated or truncated), so n-step returns can be read off directly. `meta.episode_seeds` holds
each episode's reset seed, so an episode can be played again (the env reset with it, the actions
re-applied).
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dqfd_bc_keras.errors import DemoFileError

FORMAT_VERSION = 2

ARRAYS: dict[str, tuple[type, int]] = {
    # name: (dtype, number of dimensions)
    "obs": (np.float32, 2),
    "actions": (np.int64, 1),
    "rewards": (np.float32, 1),
    "next_obs": (np.float32, 2),
    "terminated": (np.bool_, 1),
    "truncated": (np.bool_, 1),
    "episode_ids": (np.int64, 1),
}


@dataclass(frozen=True)
class DemoMeta:
    """Where a dataset comes from; stored as the JSON string `meta`."""

    task: str
    env_id: str
    timeout: str
    obs_dim: int
    n_actions: int
    expert: str
    epsilon: float
    seed: int
    episode_returns: list[float]
    """Return of each episode under the task's rewards (what the learner sees)."""
    plain_returns: list[float]
    """Return of each episode under the plain env's rewards (what the field reports)."""
    format_version: int = FORMAT_VERSION
    env_kwargs: dict[str, Any] = dataclasses.field(default_factory=dict)
    """The keyword arguments the env was made with."""
    observation: str = ""
    """The env's own observation space and how it was flattened ("" in files that predate it)."""
    obs_shape: list[int] | None = None
    """The shape of one observation kept as uint8 frames; None for flat float32 vectors."""
    max_steps: int | None = None
    """The step limit the episodes were played under (the task env's `TimeLimitMode`); None: not recorded."""
    episode_seeds: list[int | None] = dataclasses.field(default_factory=list)
    """The seed each episode's `env.reset` got, one per episode in order; None where not known."""
    keys: dict[str, int] = dataclasses.field(default_factory=dict)
    """The key map a person played with (pygame key names, "+"-joined combos, "" = no key); empty for programs."""
    fps: float | None = None
    """The frame rate (steps per second) a person played at; None for programs."""

    @property
    def obs_dtype(self) -> type:
        return np.float32 if self.obs_shape is None else np.uint8

    @property
    def obs_ndim(self) -> int:
        """Dimensions of the obs array: 2 for vectors (N, d), 1 + the frames' for frames."""
        return 2 if self.obs_shape is None else 1 + len(self.obs_shape)


@dataclass(frozen=True)
class DemoDataset:
    """Demonstration transitions in time order, one complete episode after another."""

    obs: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    next_obs: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    episode_ids: np.ndarray
    meta: DemoMeta

    def __len__(self) -> int:
        return len(self.actions)

    @property
    def n_episodes(self) -> int:
        return len(self.meta.episode_returns)

    def episodes(self) -> list[DemoDataset]:
        """The dataset split into one dataset per episode (ids restart at 0)."""
        starts = np.flatnonzero(np.diff(self.episode_ids, prepend=-1))
        ends = np.append(starts[1:], len(self))
        return [
            DemoDataset(
                **{name: getattr(self, name)[a:b] for name in ARRAYS if name != "episode_ids"},
                episode_ids=np.zeros(b - a, np.int64),
                meta=dataclasses.replace(
                    self.meta,
                    episode_returns=[self.meta.episode_returns[i]],
                    plain_returns=[self.meta.plain_returns[i]],
                    episode_seeds=[self.meta.episode_seeds[i]],
                ),
            )
            for i, (a, b) in enumerate(zip(starts, ends, strict=True))
        ]

    @property
    def mean_return(self) -> float:
        """The demonstrator's mean episode return (the run's rewards): the teacher's level."""
        return float(np.mean(self.meta.episode_returns))

    def obs_scale(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(mean, std) of the demonstrated states, per feature: the networks' input scaling; None
        for frames, which the networks scale to [0, 1] themselves."""
        if self.meta.obs_shape is not None:
            return None
        return self.obs.mean(axis=0), self.obs.std(axis=0)

    def summary(self) -> str:
        """A few human-readable lines: provenance, size and returns."""
        m = self.meta
        returns = np.asarray(m.episode_returns)
        plain = np.asarray(m.plain_returns)
        fps = "" if m.fps is None else f" at {m.fps:g} fps"
        return "\n".join(
            [
                f"task         {m.task} ({m.env_id}, timeout={m.timeout}, obs_dim={m.obs_dim}, "
                f"n_actions={m.n_actions})",
                *([f"env kwargs   {json.dumps(m.env_kwargs)}"] if m.env_kwargs else []),
                *([f"observation  {m.observation}"] if m.observation else []),
                f"expert       {m.expert} (epsilon={m.epsilon:g}, seed={m.seed})",
                f"episodes     {self.n_episodes} (seeds {seeds_text(m.episode_seeds)})",
                *([f"keys         {json.dumps(m.keys)}{fps}"] if m.keys else []),
                f"transitions  {len(self)}",
                f"returns      {' '.join(f'{r:g}' for r in returns)}",
                f"mean ± std   {returns.mean():.1f} ± {returns.std():.1f}  "
                f"(plain env: {plain.mean():.1f} ± {plain.std():.1f})",
            ]
        )


def seeds_text(seeds: Sequence[int | None]) -> str:
    """Episode seeds in a few characters: "0..9" when consecutive, else the list."""
    if all(s is None for s in seeds):
        return "not recorded"
    known = [s for s in seeds if s is not None]
    if len(known) == len(seeds) > 1 and known == list(range(known[0], known[0] + len(known))):
        return f"{known[0]}..{known[-1]}"
    return ", ".join("?" if s is None else str(s) for s in seeds)


def concatenate(parts: Sequence[DemoDataset], source: str) -> DemoDataset:
    """One dataset of the episodes of `parts`, in order, episode ids renumbered 0, 1, 2, …"""
    first = parts[0].meta
    offsets = np.cumsum([0] + [p.n_episodes for p in parts[:-1]])
    arrays = {name: np.concatenate([getattr(p, name) for p in parts]) for name in ARRAYS if name != "episode_ids"}
    arrays["episode_ids"] = np.concatenate([p.episode_ids + off for p, off in zip(parts, offsets, strict=True)])
    meta = dataclasses.replace(
        first,
        expert=source,
        episode_returns=[r for p in parts for r in p.meta.episode_returns],
        plain_returns=[r for p in parts for r in p.meta.plain_returns],
        episode_seeds=[s for p in parts for s in p.meta.episode_seeds],
    )
    return DemoDataset(**arrays, meta=meta)


def check_layout(path: Path, meta: DemoMeta, layout: dict[str, tuple[np.dtype, tuple[int, ...]]]) -> None:
    """The dtype and shape of every array (`layout`: name → (dtype, shape)), against each other
    and `meta`: read from a file's .npy headers before any array is loaded, so a header claiming
    more rows than the data holds is named, not allocated. Raises DemoFileError."""
    for name, (dtype, ndim) in ARRAYS.items():
        got, shape = layout[name]
        if name in ("obs", "next_obs"):
            dtype, ndim = meta.obs_dtype, meta.obs_ndim
        if got != dtype or len(shape) != ndim:
            raise DemoFileError(
                path, f"{name} must be {np.dtype(dtype).name} with {ndim} dimension(s), got {got} with shape {shape}"
            )
    n = layout["actions"][1][0]
    if n == 0 or meta.episode_returns == []:
        raise DemoFileError(path, "the dataset is empty")
    for name, (_, shape) in layout.items():
        if shape[0] != n:
            raise DemoFileError(path, f"{name} has {shape[0]} rows, actions has {n}")
    for name in ("obs", "next_obs"):
        shape = layout[name][1]
        if meta.obs_shape is not None and list(shape[1:]) != list(meta.obs_shape):
            raise DemoFileError(
                path, f"{name} has frames of shape {list(shape[1:])}, meta says obs_shape={list(meta.obs_shape)}"
            )
        if meta.obs_shape is None and shape[1] != meta.obs_dim:
            raise DemoFileError(path, f"{name} has {shape[1]} features, meta says obs_dim={meta.obs_dim}")


def validate(path: Path, ds: DemoDataset) -> None:
    """Every invariant a learner relies on that does not need the environment (dtypes, shapes,
    finite values, actions in range, complete episodes in time order); raises DemoFileError
    naming `path` (a file, or a `minari:` id) and the first failure."""
    check_layout(path, ds.meta, {name: (getattr(ds, name).dtype, getattr(ds, name).shape) for name in ARRAYS})
    n, m = len(ds.actions), ds.meta
    for name in ("obs", "rewards", "next_obs"):
        if not np.isfinite(getattr(ds, name)).all():
            raise DemoFileError(path, f"{name} holds non-finite values (NaN or inf)")
    if ds.actions.min() < 0 or ds.actions.max() >= m.n_actions:
        raise DemoFileError(
            path, f"actions must lie in [0, {m.n_actions}), got values in [{ds.actions.min()}, {ds.actions.max()}]"
        )
    starts = np.flatnonzero(np.diff(ds.episode_ids)) + 1
    if (np.diff(ds.episode_ids) < 0).any() or ds.episode_ids[0] != 0 or ds.episode_ids[-1] != len(starts):
        raise DemoFileError(path, "episode_ids must count 0, 1, 2, … in time order")
    if len(starts) + 1 != len(m.episode_returns):
        raise DemoFileError(
            path, f"{len(starts) + 1} episodes in episode_ids, {len(m.episode_returns)} returns in meta"
        )
    if len(m.episode_seeds) != len(m.episode_returns):
        raise DemoFileError(
            path, f"{len(m.episode_returns)} episodes, {len(m.episode_seeds)} seeds in meta's episode_seeds"
        )
    ends = np.append(starts - 1, n - 1)
    if not (ds.terminated[ends] | ds.truncated[ends]).all():
        raise DemoFileError(path, "an episode does not end with terminated or truncated")
    inner = np.setdiff1d(np.arange(n - 1), ends)
    if not np.array_equal(ds.next_obs[inner], ds.obs[inner + 1]):
        raise DemoFileError(path, "next_obs does not match the following obs inside an episode")
