"""dqfd_bc_keras: deep Q-learning from demonstrations with a behavioural-cloning model and a
Bayesian supervised expert loss (Kim, Symmetry 2022), in Keras 3 / TensorFlow.

Importing the package registers the task presets as Gymnasium ids (`dqfd_bc_keras/<task>-v0`)
and the custom Keras objects (`BCModel`) under the package name `dqfd_bc_keras`, so saved
models load with `keras.saving.load_model(path)` in safe mode.
"""

from . import runtime

runtime.configure_tensorflow()  # before any TensorFlow op: thread pools, quiet logs

from .bc import BCModel  # noqa: E402  (registers the Keras custom object)
from .envs import TASKS, make_plain_env, make_task, register_tasks  # noqa: E402

register_tasks()

__all__ = ["TASKS", "BCModel", "make_plain_env", "make_task"]
__version__ = "0.1.0"
