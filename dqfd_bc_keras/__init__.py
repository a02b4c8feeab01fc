"""dqfd_bc_keras: deep Q-learning from demonstrations with a behavioural-cloning model and a
Bayesian supervised expert loss (Kim, Symmetry 2022), in Keras 3 / TensorFlow.

Importing the package is light, so that a command's `--help` answers at once: it does not import
TensorFlow. It changes nothing in the caller's process (no import hook, no environment variable, no
TensorFlow setting) except what every Gymnasium package does: it registers the task presets as
Gymnasium ids (`dqfd_bc_keras/<task>-v0`). `configure()` sets what the command lines set (quiet logs,
oneDNN off, one thread): call it first for their numbers. Saved models load with
`dqfd_bc_keras.load_model(path)`, which registers the package's custom Keras objects (`BCModel`, …) first.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from dqfd_bc_keras.envs.make import TASKS, make_plain_env, make_task, register_tasks
from dqfd_bc_keras.runtime import configure

if TYPE_CHECKING:
    import keras

    from dqfd_bc_keras.core.bc import BCModel
    from dqfd_bc_keras.model import DQfD

__all__ = ["TASKS", "BCModel", "DQfD", "configure", "load_model", "make_plain_env", "make_task"]
__version__ = "0.1.0"

register_tasks()  # as every Gymnasium package does on import: `gym.make("dqfd_bc_keras/cartpole-v0")`


def load_model(path: str | Path) -> keras.Model:
    """A saved `.keras` model (a run's q_network.keras or bc_model.keras, a shipped model) in
    Keras' safe mode, with the package's custom objects registered; a file that is missing, not a
    .keras archive or unreadable is a one-line `ModelFileError`."""
    from dqfd_bc_keras.evaluation import load_model as load  # registers BCModel, EnsembleDense, FusedAdam, …

    return load(path)


def __getattr__(name: str) -> Any:
    """`dqfd_bc_keras.BCModel` and `dqfd_bc_keras.DQfD`, imported (with TensorFlow) only when asked for."""
    if name == "BCModel":
        from dqfd_bc_keras.core.bc import BCModel

        return BCModel
    if name == "DQfD":
        from dqfd_bc_keras.model import DQfD

        return DQfD
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
