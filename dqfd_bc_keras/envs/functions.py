"""`--env module:NAME` where NAME is no registered Gymnasium id but a function or a class of
`module`: a function that returns an env (a factory; a user's wrappers around an env, as rl-zoo3's
`env_wrapper` adds them) is a task; a class is refused with how to register it."""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import gymnasium as gym

from dqfd_bc_keras.envs.compat import as_gymnasium
from dqfd_bc_keras.tasks import ENV_DEFAULTS, ID_NAMESPACE, TaskSpec

FACTORY_PREFIX = f"{ID_NAMESPACE}/factory-"
"""The namespace of the ids `factory_task` registers; the task's name stays `module:function`."""


def factory_task(name: str, factory: Callable[..., gym.Env]) -> TaskSpec:
    """The task `module:function` (`name`): `factory`, registered as `dqfd_bc_keras/factory-<name>-v0`,
    makes its env (with the run's env kwargs as its keyword arguments), in any process that can
    import `module`; no limit of its own but the one its env keeps (`own_limit`)."""
    gym_id = f"{FACTORY_PREFIX}{''.join(c if c.isalnum() or c in '._' else '_' for c in name)}-v0"

    @functools.wraps(factory)  # its signature: the env kwargs are checked against it
    def made(**kwargs: Any) -> gym.Env:
        return as_gymnasium(factory(**kwargs), f"--env {name}")

    gym.registry.pop(gym_id, None)
    gym.register(id=gym_id, entry_point=made, max_episode_steps=None, disable_env_checker=True)
    return TaskSpec(name, gym_id, defaults=ENV_DEFAULTS)


def class_not_id(module: str, name: str) -> str:
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
