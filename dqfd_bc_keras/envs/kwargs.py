"""Env kwargs: what a run records of the keyword arguments its env is made with, and how they are
checked against the env's constructor.

A run's env kwargs are JSON values (config.json, the demonstrations' `meta`, the cache key of
`task_spaces`), but some constructors need a tuple: highway-env's `observation_shape` must be
`(84, 84)`, and a list fails in its `(stack,) + shape`. JSON has no tuple, so a tuple is recorded
as `{"__tuple__": [84, 84]}` and becomes a tuple again only where the env is made (`as_python`):

>>> as_json({"config": {"observation_shape": (84, 84)}})
{'config': {'observation_shape': {'__tuple__': [84, 84]}}}
>>> as_python(as_json({"shape": (3, (4, 5))}))
{'shape': (3, (4, 5))}
"""

from __future__ import annotations

import difflib
import inspect
import json
from collections.abc import Mapping
from typing import Any

import gymnasium as gym

from dqfd_bc_keras.envs.atari import is_atari, split_kwargs
from dqfd_bc_keras.envs.frames import FRAME_OPTIONS
from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.plugins import bare_id

TUPLE_TAG = "__tuple__"
"""The key of the one-key object that records a tuple in JSON."""

RESERVED_KWARGS = {
    "render_mode": "is chosen by the command (evaluate.py --video)",
    "max_episode_steps": "is the step limit: use --max-steps N",
}


def as_json(value: Any) -> Any:
    """`value` as JSON values, each tuple as `{"__tuple__": [...]}`; a `TypeError` for anything
    JSON cannot hold (a set, an object)."""
    if isinstance(value, tuple):
        return {TUPLE_TAG: [as_json(v) for v in value]}
    if isinstance(value, list):
        return [as_json(v) for v in value]
    if isinstance(value, Mapping):
        if not all(isinstance(k, str) for k in value):
            raise TypeError(f"keys must be strings, got {list(value)!r}")
        return {k: as_json(v) for k, v in value.items()}
    return json.loads(json.dumps(value))  # numbers, strings, booleans, None; else TypeError


def as_python(value: Any) -> Any:
    """The inverse of `as_json`: each `{"__tuple__": [...]}` a tuple again, as the env is made with it."""
    if isinstance(value, Mapping):
        if set(value) == {TUPLE_TAG} and isinstance(value[TUPLE_TAG], list):
            return tuple(as_python(v) for v in value[TUPLE_TAG])
        return {k: as_python(v) for k, v in value.items()}
    if isinstance(value, list):
        return [as_python(v) for v in value]
    return value


def recorded(env_kwargs: Mapping[str, Any] | None) -> dict[str, Any]:
    """`env_kwargs` as a run records them (`as_json`); a one-line `ConfigError` for a value JSON cannot hold."""
    try:
        return as_json(dict(env_kwargs or {}))
    except TypeError as error:
        raise ConfigError(f"env kwargs must be JSON values or tuples of them: {error}") from None


def kwargs_key(env_kwargs: Mapping[str, Any] | None) -> str:
    """`env_kwargs` as one canonical, hashable string (a cache key), tuples kept apart from lists."""
    return json.dumps(recorded(env_kwargs), sort_keys=True)


def check_env_kwargs(env_id: str, env_kwargs: Mapping[str, Any]) -> None:
    """A `ConfigError` naming the first keyword of `env_kwargs` that env `env_id`'s constructor
    does not take (with the nearest one it does), checked on its signature before any env is made.
    The frame options (`observations.FRAME_OPTIONS`) are ours, never the constructor's."""
    for key, why in RESERVED_KWARGS.items():
        if key in env_kwargs:
            raise ConfigError(f"--env-kwargs {key}: not an env kwarg here; it {why}")
    if is_atari(env_id):
        split_kwargs({k: v for k, v in env_kwargs.items() if k not in FRAME_OPTIONS})  # the ALE's, checked
        return
    parameters = constructor_parameters(env_id)
    if parameters is None or any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters.values()):
        return  # nothing to check against: gym.make will say
    takes = [
        name
        for name, p in parameters.items()
        if p.kind is not inspect.Parameter.VAR_POSITIONAL and name not in ("self", *RESERVED_KWARGS)
    ]
    for key in env_kwargs:
        if key not in parameters and key not in FRAME_OPTIONS:
            near = difflib.get_close_matches(key, [*takes, *FRAME_OPTIONS], n=1)
            hint = f"did you mean {near[0]!r}? " if near else ""
            raise ConfigError(
                f"--env-kwargs {key}: {env_id} takes no keyword argument {key!r} ({hint}it takes: "
                f"{', '.join(takes) or 'none'})"
            )


def effective_kwargs(env_id: str, env_kwargs: Mapping[str, Any]) -> dict[str, Any]:
    """The kwargs env `env_id` is made with when given `env_kwargs`: its constructor's defaults,
    then its registration's, then `env_kwargs`, as JSON values (what a Minari `env_spec` stores);
    without `render_mode`, which only changes what is drawn, nor the frame options, which are ours."""
    parameters = constructor_parameters(env_id) or {}
    defaults = {name: p.default for name, p in parameters.items() if p.default is not inspect.Parameter.empty}
    merged = {**defaults, **gym.spec(bare_id(env_id)).kwargs, **as_python(dict(env_kwargs))}
    for ours in ("render_mode", *FRAME_OPTIONS):
        merged.pop(ours, None)
    return json.loads(json.dumps(merged, default=repr))


def constructor_parameters(env_id: str) -> Mapping[str, inspect.Parameter] | None:
    """The parameters of the callable that env `env_id`'s registration makes it with; None when
    they cannot be read (a C extension, an entry point that does not import)."""
    entry_point = gym.spec(bare_id(env_id)).entry_point
    if entry_point is None:
        return None
    try:
        creator = entry_point if callable(entry_point) else gym.envs.registration.load_env_creator(entry_point)
        return inspect.signature(creator).parameters
    except (TypeError, ValueError, ImportError, AttributeError):
        return None
