"""An env the Python API is given as an object or a factory (`DQfD(env=...)`), as a task: the id
it was made from, when that id makes the same env again in any process, else an id registered in
this process for the object itself.

An env configured after `gym.make` (highway-env's `env.unwrapped.configure({...})`, then `reset`)
or whose spaces were changed after it is not what its id makes: its id is used only when the env
made again from it has the object's observation and action spaces (and, for an env keeping a
`config` dict as highway-env does, the same config); otherwise the run trains on copies of the
object, with one warning saying why (a later process cannot make it: `DQfD.load(path, env=...)`).
"""

from __future__ import annotations

import copy
import functools
import warnings
from collections.abc import Callable
from typing import Any, TypeVar

import gymnasium as gym

from dqfd_bc_keras.envs.compat import as_gymnasium, keywords_taken
from dqfd_bc_keras.envs.kwargs import as_json
from dqfd_bc_keras.envs.make import TASKS, forget_spaces, get_task
from dqfd_bc_keras.errors import ConfigError, DqfdWarning
from dqfd_bc_keras.plugins import bare_id

T = TypeVar("T")

PYTHON_ENV_PREFIX = "dqfd_bc_keras/python-"
"""The namespace of the ids `env_id_of` registers for env objects: no later process can make them."""


def env_id_of(
    env: str | gym.Env | Callable[[], gym.Env], env_id: str | None = None
) -> tuple[str, dict[str, Any], int | None]:
    """A task name for `env`, its env kwargs and the step limit it was given: a name as it is; an
    env made by `gym.make` from a registered id (unwrapped since), that id, the JSON keyword
    arguments and the `max_episode_steps` it was made with where they differ from the registry's;
    any other env object or a zero-argument factory, a new id `dqfd_bc_keras/python-<Class>-v<k>`
    registered in this process, whose every `gym.make` calls the factory or returns a deep copy of
    the instance (the instance itself when it cannot be copied: then training, evaluation and
    demonstrations step the same object, and its evaluations reset it with their own seeds), with
    the instance's own limit if it has a spec. `env_id` registers the object under that id instead
    (a saved run's, given its env again). An env its id does not make again (`_differs_from_its_id`)
    is an object too."""
    if isinstance(env, str):
        return env, {}, None
    spec = getattr(env, "spec", None) if isinstance(env, gym.Env) else None
    limit = None if spec is None else spec.max_episode_steps
    if isinstance(env, gym.Env) and spec is not None and spec.id in gym.registry and not spec.additional_wrappers:
        registered = gym.spec(spec.id)
        kwargs = {k: v for k, v in spec.kwargs.items() if k != "render_mode" and registered.kwargs.get(k) != v}
        try:
            recorded = as_json(kwargs)
        except TypeError:
            recorded = None  # kwargs no later process could pass: registered as an object below
        differs = None if recorded is None else _differs_from_its_id(env, spec)
        if recorded is not None and differs is None:
            return _importable_id(spec), recorded, None if limit == registered.max_episode_steps else limit
        if differs is not None:
            warnings.warn(
                f"{spec.id} made again from its id is not the env given ({differs}): training on copies "
                "of the object itself, which no later process can make (DQfD.load(path, env=...) gives it again)",
                DqfdWarning,
                stacklevel=3,
            )
    return _registered(env, env_id), {}, limit


def unmade_env(task: object) -> bool:
    """Whether `task` names a Python env object (`DQfD(env=<object>)`, `env_id_of`) that this process
    has not been given again: its id was registered only in the process that made it."""
    return isinstance(task, str) and task.startswith(PYTHON_ENV_PREFIX) and task not in gym.registry


def stand_in(task: str, env_id: str) -> None:
    """Let the Gymnasium id `env_id` (`module:ID` imports its module first) make the env of a run
    trained on a Python env object, `task`: registered under `task` in this process, so that the run
    is loaded, evaluated and resumed here in its own config. A one-line `ConfigError` for an id
    that is not a registered Gymnasium env (a preset's shaping is not the object's env)."""
    get_task(env_id)  # its module imported, an unknown id refused in one line
    if env_id in TASKS or env_id not in gym.registry and bare_id(env_id) not in gym.registry:
        raise ConfigError(
            f"{env_id}: a run trained on a Python env object ({task}) is given its env again as a Gymnasium "
            "id that makes the same env (e.g. CartPole-v1, my_package:MyEnv-v0)"
        )
    _registered(functools.partial(gym.make, bare_id(env_id)), task)


def _registered(env: gym.Env | Callable[[], gym.Env], env_id: str | None) -> str:
    """The id `env` is registered under in this process (`env_id`, or a new one from its class's
    name), whose every `gym.make` calls the factory or copies the instance."""
    factory: Callable[..., Any]
    if callable(env) and not _is_env(env):
        name, factory = getattr(env, "__qualname__", type(env).__name__).replace(".<locals>.", "."), env
        what = f"env={name}()"
    elif _is_env(env):
        name, what = type(getattr(env, "unwrapped", env)).__name__, "env"
        factory = functools.partial(_copy_or_same, env)
    else:
        raise ConfigError(
            f"env must be a Gymnasium id, a preset name, a gymnasium.Env or a factory of one, got {type(env).__name__}"
        )

    def make(**asked: Any) -> gym.Env:
        """The env, as `gym.make(id, render_mode=...)` asks for it: a factory that takes `render_mode`
        (`stand_in`'s `gym.make`) is given it; an env made without it cannot render so."""
        made = as_gymnasium(factory(**{key: asked[key] for key in keywords_taken(factory, tuple(asked))}), what)
        mode = asked.get("render_mode")
        if mode is not None and made.render_mode != mode:
            raise ConfigError(
                f"{what} renders {made.render_mode!r}, not {mode!r} as a video or a window needs: "
                f"give an env made with render_mode={mode!r}"
            )
        return made

    if env_id is None:
        base, k = f"{PYTHON_ENV_PREFIX}{''.join(c if c.isalnum() else '_' for c in name)}", 0
        while f"{base}-v{k}" in gym.registry:
            k += 1
        env_id = f"{base}-v{k}"
    if gym.registry.pop(env_id, None) is not None:  # another object under the id: the spaces found were the old one's
        forget_spaces()
    gym.register(id=env_id, entry_point=make, max_episode_steps=None, disable_env_checker=True)
    return env_id


def _is_env(env: object) -> bool:
    """A `gymnasium.Env`, or an object with `reset` and `step` that `compat.as_gymnasium` may hold."""
    if isinstance(env, type):  # a class: a factory of its instances
        return False
    return isinstance(env, gym.Env) or all(callable(getattr(env, name, None)) for name in ("reset", "step"))


def _importable_id(spec: gym.envs.registration.EnvSpec) -> str:
    """`package:ID` for an env a third-party package registers (`minigrid:MiniGrid-Empty-5x5-v0`),
    as `--env` takes it: a later process imports the package, which registers the id again."""
    entry = spec.entry_point
    module = entry.partition(":")[0] if isinstance(entry, str) else getattr(entry, "__module__", "")
    package = module.partition(".")[0]
    return spec.id if package in ("", "gymnasium", "dqfd_bc_keras", "__main__") else f"{package}:{spec.id}"


def _copy_or_same(env: T) -> T:
    try:
        return copy.deepcopy(env)
    except Exception:
        return env


def _differs_from_its_id(env: gym.Env, spec: gym.envs.registration.EnvSpec) -> str | None:
    """How `env` differs from the env its spec makes (its spaces, or a `config` dict it keeps, as
    highway-env's), or None when they agree."""
    try:
        made = gym.make(spec.id, max_episode_steps=-1, **{k: v for k, v in spec.kwargs.items() if k != "render_mode"})
    except Exception as error:
        return f"it cannot be made again: {type(error).__name__}"
    try:
        for what in ("observation_space", "action_space"):
            given, again = getattr(env, what), getattr(made, what)
            if given != again:
                return f"{what} {given} given, {again} made"
        config, again = getattr(env.unwrapped, "config", None), getattr(made.unwrapped, "config", None)
        if isinstance(config, dict) and repr(config) != repr(again):
            return "its config was changed after gym.make"
        return None
    finally:
        made.close()
