"""Frames: an observation the networks take as `uint8` frames for a convolutional torso (a Box of
2 or 3 dimensions of `uint8` or `bool` values ≥ 0), and how it is read.

Frames are read channels-last, (H, W, C); a stack that comes first, (C, H, W) with C ≤
`MAX_CHANNELS` and both sides longer (highway-env's (4, 84, 84) grey stack), is moved last
(`FrameObservation`), so the replay, the networks and the demonstrations see (84, 84, 4). A
frame's values are brought to [0, 1] in the network by 1/high, the space's upper bound (pixels:
1/255; a grid of ids 0–10 declared as such: 1/10). Two env kwargs of ours say otherwise where
the space cannot (`FrameOptions`): `frame_layout=channels_first|channels_last` for a shape that
could be either, and `frame_scale=none` for values that are not pixels but declare a high of 255
(MiniGrid's `ImgObsWrapper` view of object ids 0–10), or `frame_scale=X` for a factor of your own.

>>> frames_of(gym.spaces.Box(0, 255, (4, 84, 84), np.uint8))
Frames(shape=(84, 84, 4), scale=0.00392156862745098, stack=1, channels_first=True)
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, TypeGuard

import gymnasium as gym
import numpy as np

from dqfd_bc_keras.errors import ConfigError

MAX_CHANNELS = 4
"""A 3-D frame whose first axis is at most this long, and both others longer, is channels-first."""
FRAME_LAYOUTS = ("auto", "channels_last", "channels_first")
FRAME_OPTIONS = ("frame_layout", "frame_scale")
"""Env kwargs that say how frames are read; they never reach the env's constructor."""


def is_frames(space: gym.Space) -> TypeGuard[gym.spaces.Box]:
    """A top-level observation the networks take as frames: a Box of 2 or 3 dimensions of uint8
    or bool values ≥ 0 (a grid of pixels or of binary cells)."""
    return (
        isinstance(space, gym.spaces.Box)
        and len(space.shape) in (2, 3)
        and space.dtype in (np.uint8, np.bool_)
        and bool(np.all(space.low >= 0))
    )


@dataclass(frozen=True)
class FrameOptions:
    """How frames are read, from the env kwargs `frame_layout` and `frame_scale`."""

    layout: str = "auto"
    """"auto": channels-first only when the shape says so (`MAX_CHANNELS`); or "channels_last" or
    "channels_first", for a shape that could be either."""
    scale: float | None = None
    """None: 1/high ("auto"); 1.0 for values that are not pixels ("none"); or the given factor."""


AS_GIVEN = FrameOptions()
"""No frame option given: the layout and scale the space says."""


def split_frame_options(env_kwargs: Mapping[str, Any] | None) -> tuple[FrameOptions, dict[str, Any]]:
    """The `FrameOptions` in `env_kwargs` and the kwargs left for the env; a one-line
    `ConfigError` for a value neither option takes."""
    rest = dict(env_kwargs or {})
    layout, scale = rest.pop("frame_layout", "auto"), rest.pop("frame_scale", "auto")
    if layout not in FRAME_LAYOUTS:
        raise ConfigError(f"--env-kwargs frame_layout={layout}: expected one of {', '.join(FRAME_LAYOUTS)}")
    if scale in ("auto", "none"):
        return FrameOptions(layout, None if scale == "auto" else 1.0), rest
    if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not (scale > 0 and math.isfinite(scale)):
        raise ConfigError(
            f"--env-kwargs frame_scale={scale}: expected auto (1/the space's high), none (values as "
            "they are: not pixels) or a positive number"
        )
    return FrameOptions(layout, float(scale)), rest


@dataclass(frozen=True)
class Frames:
    """An observation kept as `uint8` frames: its shape, the scale that brings it to [0, 1] in the
    network, and how many frames are stacked on its last axis (Atari's 4, newest last; else 1)."""

    shape: tuple[int, ...]
    """(H, W) or (H, W, C), as the networks take it (the env's own shape, or its channels moved last)."""
    scale: float
    """1/255 for pixels bounded by 255; 1 for 0/1 cells (MinAtar's bool grids)."""
    stack: int = 1
    channels_first: bool = False
    """The env gives (C, H, W): each observation is transposed to `shape` (`as_frames`)."""

    @property
    def frame_shape(self) -> tuple[int, ...]:
        """The shape of one stored frame: the observation without its stack axis."""
        return self.shape[:-1] if self.stack > 1 else self.shape


def frames_of(space: gym.spaces.Box, stack: int = 1, options: FrameOptions = AS_GIVEN) -> Frames:
    """The `Frames` of a frame space (`is_frames`) read as `options` say: by default 1/high as the
    scale (high ≥ 1) and channels-first only when the shape says so."""
    shape = tuple(int(n) for n in space.shape)
    first = _channels_first(shape, options.layout)
    high = float(np.max(space.high)) if space.dtype != np.bool_ else 1.0
    scale = 1.0 / max(high, 1.0) if options.scale is None else options.scale
    return Frames((*shape[1:], shape[0]) if first else shape, scale, int(stack), first)


def _channels_first(shape: tuple[int, ...], layout: str) -> bool:
    """Whether frames of `shape` give their channels first: as `layout` says, or, on "auto", when
    a 3-D shape's first axis is at most `MAX_CHANNELS` long and shorter than both sides
    ((4, 84, 84) is; (84, 84, 4), MiniGrid's (7, 7, 3) and a 4×4 board of 16 planes are not)."""
    if layout == "channels_first" and len(shape) != 3:
        raise ConfigError(f"--env-kwargs frame_layout=channels_first: the frames {shape} have no channel axis")
    if layout != "auto":
        return layout == "channels_first"
    return len(shape) == 3 and shape[0] <= MAX_CHANNELS < min(shape[1:])


def as_frames(obs: Any, channels_first: bool = False) -> np.ndarray:
    """One observation or a batch of them as the networks' uint8 frames: channels moved last if
    the env gives them first."""
    x = np.asarray(obs, dtype=np.uint8)
    return np.moveaxis(x, -3, -1) if channels_first else x


class FrameObservation(gym.ObservationWrapper, gym.utils.RecordConstructorArgs):
    """Frames as the networks' `uint8` arrays (MinAtar's bool grids become 0/1 bytes; channels
    given first are moved last)."""

    def __init__(self, env: gym.Env, channels_first: bool = False) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, channels_first=channels_first)
        gym.ObservationWrapper.__init__(self, env)
        self.channels_first = channels_first
        space = env.observation_space
        assert isinstance(space, gym.spaces.Box)  # `_observe` wraps frames only
        low, high = as_frames(space.low, channels_first), as_frames(space.high, channels_first)
        self.observation_space = gym.spaces.Box(low, high, dtype=np.uint8)

    def observation(self, observation: Any) -> np.ndarray:
        return as_frames(observation, self.channels_first)
