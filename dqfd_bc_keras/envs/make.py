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

import functools
import importlib
import inspect
import json
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Protocol

import gymnasium as gym
import numpy as np

from dqfd_bc_keras.envs.atari import ATARI_DEFAULTS, ATARI_QUICK, ATARI_STEP_LIMIT, is_atari, split_kwargs, wrap_atari
from dqfd_bc_keras.envs.compat import adapted
from dqfd_bc_keras.envs.frames import FrameObservation, split_frame_options
from dqfd_bc_keras.envs.functions import class_not_id, factory_task
from dqfd_bc_keras.envs.kwargs import as_json, as_python, check_env_kwargs, kwargs_key
from dqfd_bc_keras.envs.minatar_pixels import MinAtarPixels, minatar_game
from dqfd_bc_keras.envs.network_input import NetworkInput, resolve_torso
from dqfd_bc_keras.envs.observations import FlattenObservation, ObservationLayout, is_flat, observation_layout
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


def get_task(name: str) -> TaskSpec:
    """The preset called `name` (or `module:preset`, registered by `module`), else the Gymnasium
    env with that id (`env_task`). A preset of a package's env (`minigrid:MiniGrid-…`) imports the
    package, which registers the id; a one-line `ConfigError` if it is not installed."""
    spec = find_preset(name)
    if spec is None:
        return env_task(name)
    if (parsed := parse(spec.env_id)) is not None:
        try:
            importlib.import_module(parsed[0])
        except ModuleNotFoundError:
            raise ConfigError(f"task {name!r} needs the {parsed[0]} package: pip install {parsed[0]}") from None
    return spec


@functools.cache
def env_task(env_id: str) -> TaskSpec:
    """Any registered Gymnasium env as a task: no shaping, its own time limit and threshold.

    A one-line `ConfigError` for an id that is not registered (after importing the module of a
    `module:Env-v0` id); its spaces are checked by `task_spaces`, with the run's env kwargs.
    `module:function`, a function of `module` that returns an env (a factory, which may wrap
    one: rl-zoo3's `env_wrapper`), is a task too (`factory_task`).
    """
    module, bare = parse(env_id) or (None, env_id)
    imported = None if module is None else import_module(module, f"unknown task {env_id!r}")
    try:
        spec = gym.spec(bare)
    except gym.error.Error as error:
        found = getattr(imported, bare, None)
        if module is not None and inspect.isclass(found):
            raise ConfigError(class_not_id(module, bare)) from None
        if inspect.isfunction(found):
            return factory_task(env_id, found)
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
            quick=ATARI_QUICK,
        )
    return TaskSpec(env_id, env_id, max_steps=spec.max_episode_steps, solved_return=threshold, defaults=ENV_DEFAULTS)


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


def forget_spaces() -> None:
    """Forget every task's spaces found in this process: an id registered again for another env
    object (`objects.env_id_of`) must be looked at again."""
    _task_spaces.cache_clear()


def task_spaces(name: str, env_kwargs: Mapping[str, Any] | None = None) -> TaskSpaces:
    """The spaces of task `name` made with `env_kwargs`, checked once per process: a one-line
    `ConfigError` for a keyword the env does not take and for spaces the networks cannot take."""
    return _task_spaces(name, kwargs_key(env_kwargs))


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


@functools.cache
def _task_spaces(name: str, key: str) -> TaskSpaces:
    env_kwargs = json.loads(key)
    env = _make(name, env_kwargs, max_episode_steps=-1)
    obs_space, action_space = env.observation_space, env.action_space
    env.close()
    if not (isinstance(action_space, gym.spaces.Discrete) and int(action_space.start) == 0):
        raise ConfigError(f"{name} has action space {action_space}; supported: {SUPPORTED_SPACES}")
    frame_options, env_kwargs = split_frame_options(env_kwargs)
    stack = split_kwargs(env_kwargs)[0].frame_stack if is_atari(get_task(name).env_id) else 1
    return TaskSpaces(observation_layout(obs_space, name, stack, frame_options), int(action_space.n))


def actions_of(env: gym.Env) -> int:
    """The actions of a task's env, whose action space `_task_spaces` found Discrete."""
    assert isinstance(env.action_space, gym.spaces.Discrete)
    return int(env.action_space.n)


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
    env_kwargs = as_python(split_frame_options(env_kwargs)[1])  # the frames' options are ours
    if is_atari(env_id):
        atari, make_kwargs = split_kwargs(env_kwargs)
        return wrap_atari(gym.make(bare_id(env_id), **options, **make_kwargs), atari, learning)
    try:
        env = adapted(gym.make(env_id, **options, **env_kwargs))
        return MinAtarPixels(ForgetLastAction(env), pace(minatar_game(env).env_name)) if minatar else env
    except (TypeError, ValueError, AssertionError) as error:
        if not env_kwargs:
            raise
        detail = " ".join(str(error).split())
        lists = " (a tuple is written as a Python literal: (84, 84), not [84, 84])" if "list" in detail else ""
        raise ConfigError(
            f"--env-kwargs {json.dumps(as_json(env_kwargs))}: {env_id} refused them "
            f"({type(error).__name__}: {detail}){lists}"
        ) from None


def _observe(env: gym.Env, name: str, env_kwargs: Mapping[str, Any] | None) -> gym.Env:
    """`env` with its observations as the networks take them: a flat Box unchanged, frames as
    uint8, anything else flattened."""
    if is_flat(env.observation_space):
        return env
    layout = task_spaces(name, env_kwargs).layout
    if layout.frames is None:
        return FlattenObservation(env, layout)
    if env.observation_space.dtype == np.uint8 and not layout.frames.channels_first:
        return env
    return FrameObservation(env, layout.frames.channels_first)


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


def step_limit(name: str, max_steps: int | None = None, env_kwargs: Mapping[str, Any] | None = None) -> int:
    """The step limit in force: `max_steps`, else the task's registered one, else the count after
    which its env (made with `env_kwargs`) ends its own episodes (`own_limit`); an error if none exists."""
    limit = get_task(name).max_steps if max_steps is None else max_steps
    if limit is None:
        limit = own_limit(name, env_kwargs)
    if limit is None:
        raise ConfigError(
            f"{name} has no time limit of its own: set one with --max-steps N (from Python: DQfD(env, max_steps=N))"
        )
    return limit


def own_limit(name: str, env_kwargs: Mapping[str, Any] | None = None) -> int | None:
    """The steps after which task `name`'s env, made with `env_kwargs`, truncates its own episodes
    when no limit is registered for it: a `TimeLimit` inside it (a factory's wrapped env), else
    its unwrapped env's integer `max_steps` (MiniGrid's); None when it shows neither."""
    return _own_limit(name, kwargs_key(env_kwargs))


@functools.cache
def _own_limit(name: str, key: str) -> int | None:
    env = _make(name, json.loads(key), max_episode_steps=-1)
    try:
        inner: gym.Env = env
        while isinstance(inner, gym.Wrapper):
            if isinstance(inner, gym.wrappers.TimeLimit):
                return int(inner._max_episode_steps)
            inner = inner.env
        steps = getattr(inner, "max_steps", None)
        return steps if isinstance(steps, int) and not isinstance(steps, bool) and steps > 0 else None
    finally:
        env.close()


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
    spec, limit = get_task(name), step_limit(name, max_steps, env_kwargs)
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
    limit = registered if registered is not None else step_limit(name, max_steps, env_kwargs)
    env = gym.wrappers.TimeLimit(_unlimited(name, env_kwargs, learning=False, render_mode=render_mode), limit)
    return TimeFeature(env, step_limit(name, max_steps, env_kwargs)) if timeout == "time-aware" else env


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
