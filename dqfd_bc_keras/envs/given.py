"""Observations given from outside the env loop (`DQfD.predict`, Stable-Baselines3's `evaluate_policy`
through a VecEnv): one observation of the env's own space, or a batch of them on a leading axis,
checked against the space before the networks see it. What is not one is refused in one line saying
what was expected and what came: a wrong shape, `reset()`'s `(obs, info)` pair, None, text, an empty
batch, a state outside a Discrete space, a one-hot vector where the space gives the state's index.
A batch is told from one observation by its rank alone: an array of the space's shape is one, with
one more leading axis it is a batch (a Discrete space's states: a scalar, or a vector of them).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np

from dqfd_bc_keras.envs.frames import as_frames
from dqfd_bc_keras.envs.observations import ObservationLayout, describe
from dqfd_bc_keras.errors import ConfigError


class _Refused(Exception):
    """What was given instead of an observation (its text ends the one-line error)."""


def network_input(layout: ObservationLayout, obs: Any, where: str = "predict") -> tuple[np.ndarray, int | None]:
    """`obs` as the networks take it (frames as uint8, anything else flattened) and the batch's
    length (None for one observation), or a `ConfigError` naming what `where` expected."""
    try:
        if isinstance(obs, tuple) and len(obs) == 2 and isinstance(obs[1], dict) and not _is_tuple(layout.space):
            raise _Refused("a pair (obs, info) as reset() returns it: pass obs alone (obs, info = env.reset())")
        batch = _batch(layout.kept, obs)
        if batch == 0:
            raise _Refused("an empty batch")
    except _Refused as given:
        raise ConfigError(
            f"{where}: expected an observation of {describe(layout.space)} or a batch of them, got {given}"
        ) from None
    if layout.frames is not None:
        return as_frames(obs, layout.frames.channels_first), batch
    return layout.flatten(obs, batch), batch


def _is_tuple(space: gym.Space) -> bool:
    return isinstance(space, gym.spaces.Tuple)


def _batch(space: gym.Space, obs: Any) -> int | None:
    """None when `obs` is one observation of `space`, the batch's length when it is a batch."""
    if isinstance(space, gym.spaces.Dict):
        if not isinstance(obs, Mapping):
            raise _Refused(_what(obs))
        missing = [key for key in space.spaces if key not in obs]
        if missing:
            raise _Refused(f"a mapping without the key(s) {', '.join(map(repr, missing))}")
        return _same_batch([_batch(part, obs[key]) for key, part in space.spaces.items()])
    if isinstance(space, gym.spaces.Tuple):
        indices = getattr(space, "indices", range(len(space.spaces)))  # observations._Kept: parts dropped
        if not isinstance(obs, (tuple, list)) or len(obs) <= max(indices):
            raise _Refused(_what(obs))
        return _same_batch([_batch(part, obs[i]) for i, part in zip(indices, space.spaces, strict=True)])
    x = _array(obs)
    assert space.shape is not None  # the rest of `_numeric`'s kept spaces: Box, Discrete, Multi*
    shape = tuple(space.shape)
    if x.shape == shape:
        batch = None
    elif x.shape[1:] == shape and x.ndim == len(shape) + 1:
        batch = len(x)
    else:
        raise _Refused(_what(obs))
    _check_values(space, x)
    return batch


def _same_batch(batches: list[int | None]) -> int | None:
    if len(set(batches)) > 1:
        raise _Refused(f"parts of different batch lengths ({', '.join(str(b or 'one') for b in batches)})")
    return batches[0]


def _array(obs: Any) -> np.ndarray:
    """`obs` as a numeric array, or refused (None, text, objects, ragged sequences)."""
    try:
        x = np.asarray(obs)
    except ValueError:
        raise _Refused(f"a ragged {type(obs).__name__}") from None
    if x.dtype.kind not in "biuf":
        raise _Refused(_what(obs))
    return x


def _check_values(space: gym.Space, x: np.ndarray) -> None:
    """Values the space can give: finite numbers; integer states in range for Discrete and
    MultiDiscrete (a float, a one-hot vector are not states); 0/1 bits; an integer Box's (frames')
    whole numbers within its bounds."""
    if x.dtype.kind == "f" and not np.all(np.isfinite(x)):
        raise _Refused(f"{x.dtype} values that are not finite (NaN or inf)")
    if isinstance(space, (gym.spaces.Discrete, gym.spaces.MultiDiscrete)):
        if x.dtype.kind not in "iu":
            one_hot = x.ndim and np.all((x == 0) | (x == 1)) and np.all(x.sum(axis=-1) == 1)
            hint = " (a one-hot vector? give the state's index)" if one_hot else ""
            raise _Refused(f"{x.dtype} values {_sample(x)}{hint}; its states are integers")
        low = np.asarray(space.start)
        high = low + (space.n if isinstance(space, gym.spaces.Discrete) else space.nvec)
        if np.any(x < low) or np.any(x >= high):
            raise _Refused(f"the state(s) {_sample(x)}, outside [{_bounds(low)}, {_bounds(high)})")
    elif isinstance(space, gym.spaces.MultiBinary) and not np.all((x == 0) | (x == 1)):
        raise _Refused(f"values {_sample(x)} that are not bits (0 or 1)")
    elif isinstance(space, gym.spaces.Box) and space.dtype.kind in "biu" and not _holds(space, x):
        raise _Refused(
            f"values {_sample(x)} that a {space.dtype} Box in [{_bounds(space.low)}, {_bounds(space.high)}] cannot hold"
        )


def _holds(space: gym.spaces.Box, x: np.ndarray) -> bool:
    """Whole numbers within the bounds of an integer (or bool) Box."""
    whole = x.dtype.kind != "f" or bool(np.all(x == np.round(x)))
    return whole and bool(np.all(x >= space.low)) and bool(np.all(x <= space.high))


def _bounds(values: np.ndarray) -> str:
    flat = np.unique(np.asarray(values).reshape(-1))
    return str(flat[0]) if len(flat) == 1 else f"{flat.min()}…{flat.max()}"


def _sample(x: np.ndarray) -> str:
    flat = x.reshape(-1)
    return np.array2string(flat[:6], separator=", ") + ("…" if flat.size > 6 else "")


def _what(obs: Any) -> str:
    """A short text of what was given: its type, and an array's dtype and shape."""
    if obs is None:
        return "None"
    if isinstance(obs, str):
        return f"the str {obs[:40]!r}"
    if isinstance(obs, (np.ndarray, list, tuple)) or np.isscalar(obs):
        try:
            x = np.asarray(obs)
        except ValueError:
            return f"a ragged {type(obs).__name__}"
        kind = "an array" if isinstance(obs, np.ndarray) else a_kind(obs)
        return f"{kind} of {x.dtype} of shape {x.shape}"
    return a_kind(obs)


def a_kind(value: object) -> str:
    """'a str', 'an int': the type of `value` as a message names it."""
    name = type(value).__name__
    return f"{'an' if name[0] in 'aeiou' else 'a'} {name}"
