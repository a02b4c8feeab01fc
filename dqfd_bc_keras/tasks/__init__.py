"""The registry of task presets: one module per family holds everything about it.

A family module (cartpole.py, mountaincar.py, acrobot.py, lunarlander.py, minatar.py, and
minatar_asterix.py, minatar_seaquest.py, minatar_space_invaders.py for the other MinAtar games, minigrid.py)
declares, for each of its presets, which plain Gymnasium env it wraps and how (ALGORITHM.md §6), the
preset's Config defaults and its scripted experts; what the lab judges it by is the lab's (experiments/lab_settings.py).
Adding a family to the package is one such module (imported below) and its tests. A preset of your
own registers from your module the same way, and `--task my_module:my-task` imports `my_module` first:

    from dqfd_bc_keras.tasks import TaskSpec, register_task

    register_task(TaskSpec("pendulum-bins", "my_envs:BinnedPendulum-v0", family="pendulum-bins", max_steps=200,
                           defaults={"total_steps": 30_000}, experts={"strong": swing_up}))

This package imports neither TensorFlow nor Gymnasium: reading a config.json loads neither.
"""

# isort: off
from dqfd_bc_keras.tasks import cartpole, mountaincar, acrobot, lunarlander, minatar  # noqa: F401  (they register, in this order)
from dqfd_bc_keras.tasks import minatar_asterix, minatar_seaquest, minatar_space_invaders  # noqa: F401  (then these)
from dqfd_bc_keras.tasks import minigrid  # noqa: F401  (and MiniGrid's room)

# isort: on
from dqfd_bc_keras.tasks.registry import (
    ENV_DEFAULTS,
    ID_NAMESPACE,
    NOT_REMADE,
    TASKS,
    Rule,
    TaskSpec,
    check_demonstrator,
    families,
    family_preset,
    find_preset,
    register_task,
)

__all__ = [
    "ENV_DEFAULTS",
    "ID_NAMESPACE",
    "NOT_REMADE",
    "TASKS",
    "Rule",
    "TaskSpec",
    "check_demonstrator",
    "families",
    "family_preset",
    "find_preset",
    "register_task",
]
