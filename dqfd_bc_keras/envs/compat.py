"""What the loops may assume of any env's `reset` and `step`, made true beneath the wrappers
Gymnasium's `gym.make` adds (its env checker included):

* the Gymnasium API: `reset` returns (obs, info) and `step` (obs, reward, terminated, truncated,
  info). An env written for gym 0.21 (`reset` returns the observation alone, perhaps takes no
  seed; `step` returns (obs, reward, done, info)) is adapted: `done` is `terminated`, unless its
  `info["TimeLimit.truncated"]` says the episode was cut, which is `truncated` (that API's own
  convention); a seed goes to its `seed(s)` method when its `reset` takes none;
* a `gymnasium.Env`: an env object of another library or of one's own that is not one (a class
  written for the old `gym` package) but has `reset`, `step` and Gymnasium's spaces is held by
  one (`as_gymnasium`), so that Gymnasium's wrappers take it;
* a reward that is a number: a numpy scalar or an array of one value (`np.array([r])`) becomes a
  float; a reward of any other shape is one `ConfigError` line (which value would be the reward?).

Gymnasium 1.x removed its own adapter (`EnvCompatibility`; Shimmy has it); this one is the part
of it that a loop needs.
"""

from __future__ import annotations

import inspect
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np

from dqfd_bc_keras.errors import ConfigError

GYM_MAKE_WRAPPERS = (gym.wrappers.PassiveEnvChecker, gym.wrappers.OrderEnforcing, gym.wrappers.TimeLimit)
"""The wrappers `gym.make` puts around the env it creates: the adapter goes beneath them."""


class GymnasiumApi(gym.Wrapper):
    """An env's `reset` and `step` as the Gymnasium API returns them, with a float reward."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self._reset_takes = keywords_taken(env.reset, ("seed", "options"))

    @property  # gym.Env declares `spec` an attribute, gym.Wrapper a property as this one
    def spec(self) -> gym.envs.registration.EnvSpec | None:  # type: ignore[override]
        """The env's own: the adapter is no wrapper a later `gym.make` should add (Minari, `env.spec`)."""
        return self.env.spec

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        given: dict[str, Any] = {"seed": seed, "options": options}
        seeds = getattr(self.env, "seed", None)
        if seed is not None and "seed" not in self._reset_takes and callable(seeds):
            seeds(seed)  # gym 0.21: reset() alone, seeded by seed(s)
        result = self.env.reset(**{key: given[key] for key in self._reset_takes})
        if isinstance(result, tuple) and len(result) == 2 and isinstance(result[1], dict):
            return result
        return result, {}

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        result = self.env.step(action)
        if len(result) == 4:  # gym 0.21: (obs, reward, done, info)
            obs, reward, done, info = result
            cut = bool(info.get("TimeLimit.truncated", False))
            result = (obs, reward, bool(done) and not cut, bool(done) and cut, info)
        obs, reward, terminated, truncated, info = result
        return obs, scalar_reward(reward, self.env), terminated, truncated, info


def keywords_taken(method: Any, names: tuple[str, ...]) -> tuple[str, ...]:
    """Those of `names` that `method` takes (all of them when its signature cannot be read)."""
    try:
        parameters = inspect.signature(method).parameters
    except (TypeError, ValueError):
        return names
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters.values()):
        return names
    return tuple(name for name in names if name in parameters)


def scalar_reward(reward: Any, env: gym.Env) -> Any:
    """`reward` as a float when it is a numpy scalar or one value; a number passes as it is."""
    if isinstance(reward, (int, float)):
        return reward
    value = np.asarray(reward)
    if value.size != 1 or not np.issubdtype(value.dtype, np.number):
        raise ConfigError(
            f"{env.spec.id if env.spec else type(env.unwrapped).__name__} returned a reward of shape "
            f"{value.shape} ({value.dtype}): expected a number (a float, or an array of one value)"
        )
    return float(value.reshape(()))


def adapted(env: gym.Env) -> gym.Env:
    """`env` (as `gym.make` returned it) with `GymnasiumApi` beneath `gym.make`'s own wrappers."""
    outer, inner = None, env
    while isinstance(inner, GYM_MAKE_WRAPPERS):
        outer, inner = inner, inner.env
    if outer is None:
        return GymnasiumApi(inner)
    outer.env = GymnasiumApi(inner)
    return env


class ForeignEnv(gym.Env):
    """A `gymnasium.Env` holding an env object that is not one: its own `reset`, `step`, `seed`,
    `render` and `close` are called (the `GymnasiumApi` above adapts what they return)."""

    def __init__(self, env: Any) -> None:
        self.env = env
        self.observation_space, self.action_space = env.observation_space, env.action_space
        self.metadata = dict(getattr(env, "metadata", None) or {})
        self.render_mode = getattr(env, "render_mode", None)
        for method in ("reset", "step", "seed", "render", "close"):  # its own, signatures and all
            if callable(getattr(env, method, None)):
                setattr(self, method, getattr(env, method))


def as_gymnasium(env: Any, what: str) -> gym.Env:
    """`env` as a `gymnasium.Env`: itself, or held by a `ForeignEnv` when it has `reset`, `step` and
    Gymnasium's spaces; else a one-line `ConfigError` saying what `what` (the argument) takes."""
    if isinstance(env, gym.Env):
        return env
    missing = [name for name in ("reset", "step") if not callable(getattr(env, name, None))]
    spaces = [getattr(env, name, None) for name in ("observation_space", "action_space")]
    if missing or not all(isinstance(space, gym.spaces.Space) for space in spaces):
        lacks = f"no {' nor '.join(missing)} method" if missing else "no gymnasium.spaces as its spaces"
        raise ConfigError(
            f"{what}: {type(env).__name__} is not an env ({lacks}): give a gymnasium.Env, or an object "
            "with reset, step, observation_space and action_space (gymnasium.spaces)"
        )
    return ForeignEnv(env)
