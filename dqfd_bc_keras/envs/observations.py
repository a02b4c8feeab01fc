"""Observations: any supported Gymnasium space as what the networks take: a flat float32 vector,
or frames kept in their own shape for a convolutional torso.

A one-dimensional `Box` passes unchanged. A `Box` of 2 or 3 dimensions of `uint8` or `bool`
values at the top level (MinAtar's 10×10×C grids, Atari's 84×84×4 frames, MiniGrid's 7×7×3 view
alone) is a frame: it stays `uint8` (`frames.Frames`, where channels-first stacks and values that
are not pixels are told apart), and the replay stores it as such.
Every other supported space is flattened by `FlattenObservation`, always in this order (the order
of `gymnasium.spaces.flatten`):

    Box of any shape        its values in C order (row by row), as float32
    Discrete(n, start)      a one-hot vector of n (x − start is the hot index)
    MultiDiscrete(nvec)     one one-hot vector per entry, entries in C order
    MultiBinary(shape)      its bits in C order
    Dict                    its parts in the space's key order (Gymnasium sorts a plain dict's keys)
    Tuple                   its parts in index order; Dicts and Tuples nest

Parts that are not numeric (MiniGrid's `mission` text, a Graph, a Sequence) are dropped, with
one warning naming them. Inside a Dict or a Tuple, a grid is flattened with the rest (MiniGrid's
7×7×3 view), and an image (`uint8`, 2 or 3 dimensions, bounds 0 and 255, more than
`MAX_IMAGE_VALUES` values) is refused: one network input cannot be both a frame and a vector.

>>> layout = observation_layout(gym.spaces.Dict({"a": gym.spaces.Discrete(3), "b": gym.spaces.Box(0, 1, (2, 2))}))
>>> layout.dim, layout.flatten({"a": 1, "b": [[1, 2], [3, 4]]}).tolist()
(7, [0.0, 1.0, 0.0, 1.0, 2.0, 3.0, 4.0])
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any, TypeGuard, TypeVar

import gymnasium as gym
import numpy as np

from dqfd_bc_keras.envs.frames import AS_GIVEN, FrameOptions, Frames, frames_of, is_frames
from dqfd_bc_keras.errors import ConfigError, DqfdWarning

MAX_IMAGE_VALUES = 64 * 64
"""Inside a Dict, a uint8 grid 0–255 larger than 64×64 values is taken for an image (refused);
at or below it, for a small symbolic grid that a dense layer can read (flattened)."""

NUMERIC = (gym.spaces.Box, gym.spaces.Discrete, gym.spaces.MultiDiscrete, gym.spaces.MultiBinary)


def describe(space: gym.Space) -> str:
    """A short text of `space`: kinds, shapes and dtypes, without Box bounds or Text's charset."""
    if isinstance(space, gym.spaces.Box):
        return f"Box{space.shape} {space.dtype}"
    if isinstance(space, gym.spaces.Discrete):
        return f"Discrete({space.n})" if int(space.start) == 0 else f"Discrete({space.n}, start={space.start})"
    if isinstance(space, (gym.spaces.MultiDiscrete, gym.spaces.MultiBinary)):
        return repr(space)
    if isinstance(space, gym.spaces.Dict):
        return "Dict(" + ", ".join(f"{key}: {describe(part)}" for key, part in space.spaces.items()) + ")"
    if isinstance(space, gym.spaces.Tuple):
        return "Tuple(" + ", ".join(describe(part) for part in space.spaces) + ")"
    return type(space).__name__


def is_image(space: gym.Space) -> TypeGuard[gym.spaces.Box]:
    """A frame of pixels: uint8, 2 or 3 dimensions, bounds 0 and 255, more than MAX_IMAGE_VALUES values."""
    return (
        isinstance(space, gym.spaces.Box)
        and space.dtype == np.uint8
        and len(space.shape) in (2, 3)
        and bool(np.all(space.low == 0))
        and bool(np.all(space.high == 255))
        and int(np.prod(space.shape)) > MAX_IMAGE_VALUES
    )


def is_flat(space: gym.Space) -> TypeGuard[gym.spaces.Box]:
    """A one-dimensional Box: the networks take it as it is."""
    return isinstance(space, gym.spaces.Box) and len(space.shape) == 1


@dataclass(frozen=True)
class ObservationLayout:
    """How an env's observations become a network's input: which parts, in which order, how wide."""

    space: gym.Space
    """The env's own observation space."""
    kept: gym.Space
    """`space` without its non-numeric parts (the same object when nothing is dropped)."""
    dropped: tuple[str, ...]
    """Paths of the dropped parts, e.g. ("mission",)."""
    dim: int
    """Features of the flat vector (of a frame observation: its values)."""
    frames: Frames | None = None
    """Set when the observation is kept as uint8 frames for a convolutional torso."""

    @property
    def flat(self) -> bool:
        """True when observations pass unchanged (a one-dimensional Box)."""
        return is_flat(self.space)

    @property
    def image(self) -> bool:
        """True when observations are frames (`Frames`), not vectors."""
        return self.frames is not None

    def flatten(self, obs: Any, batch: int | None = None) -> np.ndarray:
        """One observation as a (dim,) float32 vector, or, with `batch`, `batch` observations whose
        leaves carry a leading axis of that length (a Minari episode) as (batch, dim)."""
        flat = _flatten(self.kept, obs, 1 if batch is None else batch)
        return flat[0] if batch is None else flat

    def to_dict(self) -> dict:
        """What `config.json` records: the env's space, its shape, the features and what was dropped."""
        shape = getattr(self.space, "shape", None)
        frames = (
            None
            if self.frames is None
            else {
                "shape": list(self.frames.shape),
                "scale": self.frames.scale,
                "stack": self.frames.stack,
                **({"channels_first": True} if self.frames.channels_first else {}),  # (C, H, W) read as `shape`
            }
        )
        return {
            "space": describe(self.space),
            "shape": None if shape is None else list(shape),
            "features": self.dim,
            "flattened": not (self.flat or self.image),
            "dropped": list(self.dropped),
            "frames": frames,
        }

    def text(self) -> str:
        """One line: the space and how it becomes the network's input."""
        if self.flat:
            return describe(self.space)
        if self.frames is not None:
            stack = f", {self.frames.stack} stacked" if self.frames.stack > 1 else ""
            moved = f", channels moved last to {self.frames.shape}" if self.frames.channels_first else ""
            return f"{describe(self.space)} as uint8 frames{stack}{moved}"
        dropped = f"; dropped {', '.join(self.dropped)}" if self.dropped else ""
        return f"{describe(self.space)} flattened to {self.dim} features{dropped}"


def observation_layout(
    space: gym.Space, env_id: str = "the env", stack: int = 1, options: FrameOptions = AS_GIVEN
) -> ObservationLayout:
    """The layout of `space` (frames stacked `stack` deep on the last axis and read as `options`
    say, for a frame space), or a one-line `ConfigError` for images inside a Dict or Tuple, for
    spaces with no numeric part and for frame options given for observations that are no frames;
    warns once, naming them, when parts are dropped."""
    if is_frames(space):
        return ObservationLayout(space, space, (), int(np.prod(space.shape)), frames_of(space, stack, options))
    if options != AS_GIVEN:
        raise ConfigError(
            f"--env-kwargs frame_layout/frame_scale: {env_id} observes {describe(space)}, not frames "
            "(a 2-D or 3-D uint8 or bool Box)"
        )
    if is_flat(space):
        return ObservationLayout(space, space, (), int(space.shape[0]))
    dropped: list[str] = []
    kept = _numeric(space, "", dropped, env_id)
    if kept is None:
        raise ConfigError(
            f"{env_id} has observation space {describe(space)}, which has no numeric part; "
            "supported: Box, Discrete, MultiDiscrete, MultiBinary and Dicts or Tuples of them"
        )
    if dropped:
        warnings.warn(
            f"{env_id}: dropping non-numeric observation part(s) {', '.join(dropped)} (of {describe(space)})",
            DqfdWarning,
            stacklevel=2,
        )
    return ObservationLayout(space, kept if dropped else space, tuple(dropped), int(gym.spaces.flatdim(kept)))


def _numeric(space: gym.Space, path: str, dropped: list[str], env_id: str) -> gym.Space | None:
    """`space` with its non-numeric parts removed (their paths appended to `dropped`); None if nothing is left."""
    if is_image(space):
        where = f" (part {path})" if path else ""
        raise ConfigError(
            f"{env_id} observes images{where}: {describe(space)} inside a Dict or Tuple "
            "is not supported (the convolutional torso takes frames as the whole observation: "
            "wrap the env to observe the image alone)"
        )
    if isinstance(space, NUMERIC):
        return space
    if isinstance(space, gym.spaces.Dict):
        named = _numeric_parts(space.spaces.items(), path, dropped, env_id)
        return gym.spaces.Dict(list(named.items())) if named else None  # a list keeps the order
    if isinstance(space, gym.spaces.Tuple):
        indexed = _numeric_parts(enumerate(space.spaces), path, dropped, env_id)
        if not indexed:
            return None
        return gym.spaces.Tuple(tuple(indexed.values())) if len(indexed) == len(space.spaces) else _Kept(space, indexed)
    dropped.append(path or type(space).__name__)
    return None


Key = TypeVar("Key", str, int)


def _numeric_parts(
    items: Iterable[tuple[Key, gym.Space]], path: str, dropped: list[str], env_id: str
) -> dict[Key, gym.Space]:
    """The numeric parts (`_numeric`) of a Dict's or a Tuple's `items`, by key, in order."""
    parts = {key: _numeric(part, f"{path}.{key}" if path else str(key), dropped, env_id) for key, part in items}
    return {key: part for key, part in parts.items() if part is not None}


class _Kept(gym.spaces.Tuple):
    """A Tuple with some parts dropped: remembers which indices of the original it keeps."""

    def __init__(self, original: gym.spaces.Tuple, parts: dict[int, gym.Space]) -> None:
        super().__init__(tuple(parts.values()))
        self.indices = tuple(parts)


def _flatten(space: gym.Space, x: Any, batch: int) -> np.ndarray:
    """(batch, flatdim(space)) float32, in `gymnasium.spaces.flatten`'s order."""
    if isinstance(space, (gym.spaces.Box, gym.spaces.MultiBinary)):
        return np.asarray(x, dtype=np.float32).reshape(batch, -1)
    if isinstance(space, gym.spaces.Discrete):
        index = np.asarray(x, dtype=np.int64).reshape(batch) - int(space.start)
        return np.eye(int(space.n), dtype=np.float32)[index]
    if isinstance(space, gym.spaces.MultiDiscrete):
        indices = (np.asarray(x, dtype=np.int64) - space.start).reshape(batch, -1)
        return np.concatenate(
            [np.eye(int(n), dtype=np.float32)[indices[:, i]] for i, n in enumerate(space.nvec.reshape(-1))], axis=1
        )
    if isinstance(space, gym.spaces.Dict):
        return np.concatenate([_flatten(part, x[key], batch) for key, part in space.spaces.items()], axis=1)
    assert isinstance(space, gym.spaces.Tuple)  # the last of `_numeric`'s kept spaces
    kept = getattr(space, "indices", range(len(space.spaces)))
    return np.concatenate([_flatten(part, x[i], batch) for i, part in zip(kept, space.spaces, strict=True)], axis=1)


class FlattenObservation(gym.ObservationWrapper, gym.utils.RecordConstructorArgs):
    """Observations as `layout` flattens them: a float32 Box of `layout.dim` features."""

    def __init__(self, env: gym.Env, layout: ObservationLayout) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, layout=layout)  # env.spec remakes it (check_env does)
        gym.ObservationWrapper.__init__(self, env)
        self.layout = layout
        flat = gym.spaces.flatten_space(layout.kept)
        assert isinstance(flat, gym.spaces.Box)  # numeric parts flatten to a Box
        self.observation_space = gym.spaces.Box(
            flat.low.astype(np.float32), flat.high.astype(np.float32), dtype=np.float32
        )

    def observation(self, observation: Any) -> np.ndarray:
        return self.layout.flatten(observation)
