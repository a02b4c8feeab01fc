"""dqfd_bc_keras: deep Q-learning from demonstrations with a behavioural-cloning model and a
Bayesian supervised expert loss (Kim, Symmetry 2022), in Keras 3 / TensorFlow.

Importing the package registers the task presets as Gymnasium ids (`dqfd_bc_keras/<task>-v0`).
"""

from . import runtime  # noqa: F401  (first: sets TensorFlow's environment before it loads)
from .envs import TASKS, make_plain_env, make_task, register_tasks

register_tasks()

__all__ = ["TASKS", "make_plain_env", "make_task"]
__version__ = "0.1.0"
