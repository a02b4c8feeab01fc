"""Process-wide TensorFlow settings: quiet logs and a thread budget that fits a 2-core CPU.

Imported first by the package, before TensorFlow itself, because the environment variables
below are only read when TensorFlow loads. Every setting can be overridden from the shell.
"""

from __future__ import annotations

import contextlib
import os
import warnings
from collections.abc import Iterator

# The C++ runtime's log lines (tf.data prints a harmless "unknown attribute" ERROR line on
# every Keras fit; real failures still surface as Python exceptions), and oneDNN's banner:
# oneDNN brings nothing to 64-unit MLPs and makes results depend on the CPU's kernels.
os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "3")
os.environ.setdefault("TF_ENABLE_ONEDNN_OPTS", "0")
os.environ.setdefault("KERAS_BACKEND", "tensorflow")

THREADS_ENV = "DQFD_TF_THREADS"
"""Intra-op threads per process (default 1: small graphs gain nothing from more, and the
experiment runner puts one process on each core)."""


def configure_tensorflow() -> None:
    """Set TensorFlow's thread pools once per process; later calls are no-ops."""
    import tensorflow as tf

    tf.get_logger().setLevel("ERROR")
    threads = int(os.environ.get(THREADS_ENV, "1"))
    try:
        tf.config.threading.set_intra_op_parallelism_threads(threads)
        tf.config.threading.set_inter_op_parallelism_threads(1)
    except RuntimeError:
        pass  # the runtime is already initialised (someone ran an op first): keep its pools


@contextlib.contextmanager
def keras_conversions() -> Iterator[None]:
    """Around the package's calls that make Keras 3 convert its variables with `np.array(x)`
    (reading weights into NumPy, saving a model): NumPy 2 warns at each that `__array__` takes no
    `copy` keyword, a DeprecationWarning meant for Keras, not for our users. Silenced there only,
    not process-wide."""
    with warnings.catch_warnings():
        warnings.filterwarnings(
            "ignore", message="__array__ implementation doesn't accept a copy keyword", category=DeprecationWarning
        )
        yield
