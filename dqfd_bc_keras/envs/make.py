"""Tasks: the paper's (ALGORITHM.md §6) and ours as presets, or any Gymnasium env by its id.

A task is a preset name (the registry in `tasks/`: cartpole, cartpole-200, mountaincar,
mountaincar-goals, acrobot, lunarlander, or a user's `module:preset`) or the id of any registered
Gymnasium env with a `Discrete` action space and an observation space that `observations` can
flatten (`"module:Env-v0"` imports `module` first, as `gym.make` does); `get_task` turns either
into a `TaskSpec`. Keyword arguments for the env's constructor (`env_kwargs`, e.g. FlappyBird's
`use_lidar=False`) go with the task everywhere an env is made; `task_spaces` checks them and the
spaces once.

A task env is built from the plain Gymnasium env (made with `env_kwargs`) with no time limit
of its own, then (the wrappers are in `wrappers.py`)

    FlattenObservation (observations that are not a flat Box)        the networks' input
    FallPenalty (CartPole) or GoalCount (MountainCar goal variant)   reward shaping
    TimeLimitMode                                                    the step limit, in one of three modes

so the shaping wrappers only ever see the physics' own terminations and a truncation can
never be mistaken for a fall. Every step's `info["plain_reward"]` is the reward the plain
env (CartPole-v1 / MountainCar-v0) would have paid, so training logs can report the plain
return next to the shaped one; `evaluation` always scores on the plain env itself.

>>> env = make_task("cartpole-200", timeout="naive")
>>> obs, info = env.reset(seed=0)
>>> obs.shape
(4,)
"""

from __future__ import annotations

import copy
import difflib
import functools
import inspect
import json
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Protocol

import gymnasium as gym
import numpy as np

from dqfd_bc_keras.envs.atari import ATARI_DEFAULTS, ATARI_STEP_LIMIT, is_atari, split_kwargs, wrap_atari
from dqfd_bc_keras.envs.minatar_pixels import MinAtarPixels
from dqfd_bc_keras.envs.network_input import NetworkInput, resolve_torso
from dqfd_bc_keras.envs.observations import (
    FlattenObservation,
    FrameObservation,
    ObservationLayout,
    is_flat,
    observation_layout,
)
from dqfd_bc_keras.envs.wrappers import FallPenalty, ForgetLastAction, GoalCount, TimeFeature, TimeLimitMode
from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.plugins import bare_id, import_module, parse
from dqfd_bc_keras.tasks import ENV_DEFAULTS, TASKS, TaskSpec, find_preset
from dqfd_bc_keras.tasks.minatar import pace, require_minatar

SUPPORTED_SPACES = (
    "a Discrete action space starting at 0 and an observation of Box, Discrete, MultiDiscrete or "
    "MultiBinary parts (Dicts and Tuples of them are flattened), or frames (a 2-D or 3-D uint8 or "
    "bool Box)"
)

RESERVED_KWARGS = {
    "render_mode": "is chosen by the command (evaluate.py --video)",
    "max_episode_steps": "is the step limit: use --max-steps N",
}


def get_task(name: str) -> TaskSpec:
    """The preset called `name` (or `module:preset`, registered by `module`), else the Gymnasium
    env with that id (`env_task`)."""
    return find_preset(name) or env_task(name)


@functools.cache
def env_task(env_id: str) -> TaskSpec:
    """Any registered Gymnasium env as a task: no shaping, its own time limit and threshold.

    A one-line `ConfigError` for an id that is not registered (after importing the module of a
    `module:Env-v0` id); its spaces are checked by `task_spaces`, with the run's env kwargs.
    """
    module, bare = parse(env_id) or (None, env_id)
    imported = None if module is None else import_module(module, f"unknown task {env_id!r}")
    try:
        spec = gym.spec(bare)
    except gym.error.Error as error:
        if inspect.isclass(getattr(imported, bare, None)):
            raise ConfigError(_class_not_id(module, bare)) from None
        raise ConfigError(
            f"unknown task {env_id!r}: neither a preset ({', '.join(sorted(TASKS))}) nor a "
            f"Gymnasium env id ({type(error).__name__}: {error})"
        ) from None
    threshold = None if spec.reward_threshold is None else float(spec.reward_threshold)
    if is_atari(env_id):  # preprocessed (atari.py); the ALE's own cap of 108,000 frames as the limit
        return TaskSpec(
            env_id,
            env_id,
            max_steps=spec.max_episode_steps or ATARI_STEP_LIMIT,
            solved_return=threshold,
            defaults=ATARI_DEFAULTS,
        )
    return TaskSpec(env_id, env_id, max_steps=spec.max_episode_steps, solved_return=threshold, defaults=ENV_DEFAULTS)


def _class_not_id(module: str, name: str) -> str:
    """What to pass instead of `--env module:name` when `name` is a class of `module`: the ids
    registered with an entry point in `module`, or how to register the class."""
    ids = [
        env_id
        for env_id, spec in gym.registry.items()
        if isinstance(spec.entry_point, str) and spec.entry_point.startswith(f"{module}:")
    ]
    if ids:
        how = f"{module} registers {', '.join(ids)}: pass --env {module}:{ids[0]}"
    else:
        how = (
            f'register the class in {module} with gymnasium.register(id="{name}-v0", '
            f'entry_point="{module}:{name}") and pass --env {module}:{name}-v0'
        )
    return f"{module}:{name} is a class, not an env id: --env takes a registered Gymnasium id; {how}"


@dataclass(frozen=True)
class TaskSpaces:
    """What the networks see of a task made with given env kwargs: the observation layout and the actions."""

    layout: ObservationLayout
    n_actions: int

    @property
    def obs_dim(self) -> int:
        return self.layout.dim

    def input_dim(self, timeout: str) -> int:
        """The networks' input width: the flattened observation, and the time feature in time-aware mode."""
        return self.layout.dim + (timeout == "time-aware")

    def network_input(self, torso: str = "auto", timeout: str = "bootstrap") -> NetworkInput:
        """What the networks take in this task, read by torso `torso` (`networks.resolve_torso`)."""
        if self.layout.image and timeout == "time-aware":
            raise ConfigError(
                "timeout='time-aware' appends the time left to a vector observation; this task "
                "observes frames: use timeout=bootstrap"
            )
        return NetworkInput(self.input_dim(timeout), self.layout.frames, resolve_torso(torso, self.layout.frames))


def task_spaces(name: str, env_kwargs: Mapping[str, Any] | None = None) -> TaskSpaces:
    """The spaces of task `name` made with `env_kwargs`, checked once per process: a one-line
    `ConfigError` for a keyword the env does not take and for spaces the networks cannot take."""
    return _task_spaces(name, _kwargs_key(env_kwargs))


class EnvSettings(Protocol):
    """What `checked_spaces` reads of a config (`config.Config`; envs never imports it)."""

    task: str
    env_kwargs: dict[str, Any]
    torso: str
    timeout: str


def checked_spaces(config: EnvSettings) -> TaskSpaces:
    """The spaces of `config`'s env, made once with its env kwargs, refused in one `ConfigError`
    line when the networks cannot take them as the config asks (its torso, the time feature of
    `timeout='time-aware'`). Called where a config is about to make envs: `Config.validate`
    checks values alone, so the lab reads configs of tasks whose envs it need not make."""
    spaces = task_spaces(config.task, config.env_kwargs)
    spaces.network_input(config.torso, config.timeout)
    return spaces


def check_env_kwargs(env_id: str, env_kwargs: Mapping[str, Any]) -> None:
    """A `ConfigError` naming the first keyword of `env_kwargs` that env `env_id`'s constructor
    does not take (with the nearest one it does), checked on its signature before any env is made."""
    for key, why in RESERVED_KWARGS.items():
        if key in env_kwargs:
            raise ConfigError(f"--env-kwargs {key}: not an env kwarg here; it {why}")
    if is_atari(env_id):
        split_kwargs(env_kwargs)  # the preprocessing's options and the ALE's keywords, checked
        return
    parameters = _constructor_parameters(env_id)
    if parameters is None or any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters.values()):
        return  # nothing to check against: gym.make will say
    takes = [
        name
        for name, p in parameters.items()
        if p.kind is not inspect.Parameter.VAR_POSITIONAL and name not in ("self", *RESERVED_KWARGS)
    ]
    for key in env_kwargs:
        if key not in parameters:
            near = difflib.get_close_matches(key, takes, n=1)
            hint = f"did you mean {near[0]!r}? " if near else ""
            raise ConfigError(
                f"--env-kwargs {key}: {env_id} takes no keyword argument {key!r} ({hint}it takes: "
                f"{', '.join(takes) or 'none'})"
            )


def effective_kwargs(env_id: str, env_kwargs: Mapping[str, Any]) -> dict[str, Any]:
    """The kwargs env `env_id` is made with when given `env_kwargs`: its constructor's defaults,
    then its registration's, then `env_kwargs`, as JSON values (what a Minari `env_spec` stores);
    without `render_mode`, which only changes what is drawn."""
    parameters = _constructor_parameters(env_id) or {}
    defaults = {name: p.default for name, p in parameters.items() if p.default is not inspect.Parameter.empty}
    merged = {**defaults, **gym.spec(bare_id(env_id)).kwargs, **env_kwargs}
    merged.pop("render_mode", None)
    return json.loads(json.dumps(merged, default=repr))


def _constructor_parameters(env_id: str) -> Mapping[str, inspect.Parameter] | None:
    """The parameters of the callable that env `env_id`'s registration makes it with; None when
    they cannot be read (a C extension, an entry point that does not import)."""
    entry_point = gym.spec(bare_id(env_id)).entry_point
    try:
        creator = entry_point if callable(entry_point) else gym.envs.registration.load_env_creator(entry_point)
        return inspect.signature(creator).parameters
    except (TypeError, ValueError, ImportError, AttributeError):
        return None


def _kwargs_key(env_kwargs: Mapping[str, Any] | None) -> str:
    """`env_kwargs` as one canonical, hashable string (a cache key)."""
    try:
        return json.dumps(dict(env_kwargs or {}), sort_keys=True)
    except TypeError as error:
        raise ConfigError(f"env kwargs must be JSON values: {error}") from None


@functools.cache
def _task_spaces(name: str, kwargs_key: str) -> TaskSpaces:
    env_kwargs = json.loads(kwargs_key)
    env = _make(name, env_kwargs, max_episode_steps=-1)
    obs_space, action_space = env.observation_space, env.action_space
    env.close()
    if not (isinstance(action_space, gym.spaces.Discrete) and int(action_space.start) == 0):
        raise ConfigError(f"{name} has action space {action_space}; supported: {SUPPORTED_SPACES}")
    env_id = get_task(name).env_id
    stack = split_kwargs(env_kwargs)[0].frame_stack if is_atari(env_id) else 1
    return TaskSpaces(observation_layout(obs_space, name, stack), int(action_space.n))


def _make(name: str, env_kwargs: Mapping[str, Any] | None, learning: bool = True, **options: Any) -> gym.Env:
    """`gym.make` of task `name`'s plain env with `env_kwargs`; a bad keyword is one `ConfigError`
    line. An Atari env gets its preprocessing (`atari.py`): the learner's when `learning`, else
    the evaluation's (raw rewards, whole games); a MinAtar env its fresh sticky action at each
    reset and its frames in MinAtar's colours (`minatar_pixels.py`)."""
    env_id, env_kwargs = get_task(name).env_id, dict(env_kwargs or {})
    minatar = bare_id(env_id).startswith("MinAtar/")
    if minatar:
        require_minatar()
    check_env_kwargs(env_id, env_kwargs)
    if is_atari(env_id):
        atari, make_kwargs = split_kwargs(env_kwargs)
        return wrap_atari(gym.make(bare_id(env_id), **options, **make_kwargs), atari, learning)
    try:
        env = gym.make(env_id, **options, **env_kwargs)
        return MinAtarPixels(ForgetLastAction(env), pace(env.unwrapped.game.env_name)) if minatar else env
    except (TypeError, ValueError, AssertionError) as error:
        if not env_kwargs:
            raise
        detail = " ".join(str(error).split())
        raise ConfigError(
            f"--env-kwargs {json.dumps(env_kwargs)}: {env_id} refused them ({type(error).__name__}: {detail})"
        ) from None


def _observe(env: gym.Env, name: str, env_kwargs: Mapping[str, Any] | None) -> gym.Env:
    """`env` with its observations as the networks take them: a flat Box unchanged, frames as
    uint8, anything else flattened."""
    if is_flat(env.observation_space):
        return env
    layout = task_spaces(name, env_kwargs).layout
    if layout.image:
        return env if env.observation_space.dtype == np.uint8 else FrameObservation(env)
    return FlattenObservation(env, layout)


def _unlimited(
    name: str, env_kwargs: Mapping[str, Any] | None, learning: bool = True, render_mode: str | None = None
) -> gym.Env:
    """Task `name`'s env as the networks observe it, without a step limit: what the learner's env
    and the plain env both start from, so that each puts its limit outside, on the agent's steps
    (a limit inside an Atari env's frame skip would count the emulator's frames)."""
    return _observe(
        _make(name, env_kwargs, learning, max_episode_steps=-1, **_rendering(render_mode)), name, env_kwargs
    )


def task_slug(name: str) -> str:
    """`name` as one path component: an env id's namespace slash and module colon become dashes."""
    return name.replace("/", "-").replace(":", "-")


def step_limit(name: str, max_steps: int | None = None) -> int:
    """The step limit in force: `max_steps`, else the task's; an error if neither exists."""
    limit = get_task(name).max_steps if max_steps is None else max_steps
    if limit is None:
        raise ConfigError(
            f"{name} has no time limit of its own: set one with --max-steps N (from Python: DQfD(env, max_steps=N))"
        )
    return limit


def _rendering(render_mode: str | None) -> dict[str, str]:
    """`render_mode` for `gym.make` only when asked for: a user's env need not take the argument."""
    return {} if render_mode is None else {"render_mode": render_mode}


def make_task(
    name: str,
    timeout: str = "bootstrap",
    max_steps: int | None = None,
    render_mode: str | None = None,
    env_kwargs: Mapping[str, Any] | None = None,
) -> gym.Env:
    """Build the task env `name` with the paper's settings; `max_steps` overrides the limit,
    `env_kwargs` go to the env's constructor."""
    spec, limit = get_task(name), step_limit(name, max_steps)
    if timeout == "time-aware":
        task_spaces(name, env_kwargs).network_input("auto", timeout)  # frames take no time feature: one line
    env = _unlimited(name, env_kwargs, render_mode=render_mode)
    if spec.fall_penalty is not None:
        env = FallPenalty(env, spec.fall_penalty)
    if spec.goal_reward is not None:
        env = GoalCount(env, spec.goal_reward)
    env = TimeLimitMode(env, limit, timeout)
    return TimeFeature(env, limit) if timeout == "time-aware" else env


def make_plain_env(
    name: str,
    timeout: str = "bootstrap",
    max_steps: int | None = None,
    render_mode: str | None = None,
    env_kwargs: Mapping[str, Any] | None = None,
) -> gym.Env:
    """The unmodified Gymnasium env of task `name` (made with `env_kwargs`), with its own time
    limit (an env without one, as MinAtar's and the ALE's, gets the training limit); observations
    as the networks take them, and an Atari env's preprocessing without the learner's reward
    clipping and lives. The limit counts the agent's steps, as training's does.

    With `timeout="time-aware"` the observation also carries the time feature the agent was
    trained with (fraction of the training limit `max_steps` left); rewards and ends are untouched.
    """
    registered = gym.spec(bare_id(get_task(name).env_id)).max_episode_steps
    limit = registered if registered is not None else step_limit(name, max_steps)
    env = gym.wrappers.TimeLimit(_unlimited(name, env_kwargs, learning=False, render_mode=render_mode), limit)
    if timeout == "time-aware":
        env = TimeFeature(env, step_limit(name, max_steps))
    return env


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
    (a saved run's, given its env again)."""
    if isinstance(env, str):
        return env, {}, None
    spec = getattr(env, "spec", None) if isinstance(env, gym.Env) else None
    limit = None if spec is None else spec.max_episode_steps
    if spec is not None and spec.id in gym.registry and not spec.additional_wrappers:
        registered = gym.spec(spec.id)
        kwargs = {k: v for k, v in spec.kwargs.items() if k != "render_mode" and registered.kwargs.get(k) != v}
        try:
            return (
                _importable_id(spec),
                json.loads(json.dumps(kwargs)),
                None if limit == registered.max_episode_steps else limit,
            )
        except TypeError:
            pass  # kwargs no later process could pass: registered as an object below
    if isinstance(env, gym.Env):
        name, instance = type(env.unwrapped).__name__, env
        make: Callable[[], gym.Env] = lambda: _copy_or_same(instance)
    elif callable(env):
        name, make = getattr(env, "__qualname__", type(env).__name__).replace(".<locals>.", "."), env
    else:
        raise ConfigError(
            f"env must be a Gymnasium id, a preset name, a gymnasium.Env or a factory of one, got {type(env).__name__}"
        )
    if env_id is None:
        base, k = f"{PYTHON_ENV_PREFIX}{''.join(c if c.isalnum() else '_' for c in name)}", 0
        while f"{base}-v{k}" in gym.registry:
            k += 1
        env_id = f"{base}-v{k}"
    if gym.registry.pop(env_id, None) is not None:  # another object under the id: the spaces found were the old one's
        _task_spaces.cache_clear()
    gym.register(id=env_id, entry_point=make, max_episode_steps=None, disable_env_checker=True)
    return env_id, {}, limit


def _importable_id(spec: gym.envs.registration.EnvSpec) -> str:
    """`package:ID` for an env a third-party package registers (`minigrid:MiniGrid-Empty-5x5-v0`),
    as `--env` takes it: a later process imports the package, which registers the id again."""
    entry = spec.entry_point
    module = entry.partition(":")[0] if isinstance(entry, str) else getattr(entry, "__module__", "")
    package = module.partition(".")[0]
    return spec.id if package in ("", "gymnasium", "dqfd_bc_keras", "__main__") else f"{package}:{spec.id}"


def _copy_or_same(env: gym.Env) -> gym.Env:
    try:
        return copy.deepcopy(env)
    except Exception:
        return env


def register_tasks() -> None:
    """Register every preset as `dqfd_bc_keras/<task>-v0`; `gym.make(id, timeout=...)` works."""
    for spec in TASKS.values():
        if spec.gym_id not in gym.registry:
            gym.register(
                id=spec.gym_id,
                entry_point=functools.partial(make_task, spec.name),
                max_episode_steps=None,
                disable_env_checker=True,
            )
