"""Process-wide TensorFlow settings, made only when an entry point asks: quiet logs, oneDNN off and
a thread budget that fits a 2-core CPU.

Importing the package sets none of them (a library must not change its caller's process). The
command lines (`commands/cli.run`), the lab's workers, the tests and the scripts call `configure()`
before TensorFlow loads; a Python user calls `dqfd_bc_keras.configure()` to get the numbers the
command lines give. Every setting but the thread count can be overridden from the shell.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import warnings
from collections.abc import Iterator

from dqfd_bc_keras.errors import ConfigError, DqfdWarning

THREADS_ENV = "DQFD_TF_THREADS"
"""Intra-op threads per process (default 1: small graphs gain nothing from more, and the
experiment runner puts one process on each core)."""
ONEDNN_ENV = "TF_ENABLE_ONEDNN_OPTS"
INTRA_ENV, INTER_ENV = "TF_NUM_INTRAOP_THREADS", "TF_NUM_INTEROP_THREADS"
"""The variables TensorFlow reads for its thread pools when its runtime starts (its first op)."""
DEFAULTS = {
    # The C++ runtime's log lines (tf.data prints a harmless "unknown attribute" ERROR line on
    # every Keras fit; real failures still surface as Python exceptions).
    "TF_CPP_MIN_LOG_LEVEL": "3",
    # oneDNN brings nothing to 64-unit MLPs and makes results depend on the CPU's kernels: with it
    # off, a rerun on another CPU of the same instruction set gives the same numbers.
    ONEDNN_ENV: "0",
    "KERAS_BACKEND": "tensorflow",
}
"""Set unless the shell set them: they are read when TensorFlow (or Keras) loads."""


def threads_wanted(threads: int | None = None) -> int:
    """`threads`, else `DQFD_TF_THREADS`, else 1; a count below 1 or not a number is refused."""
    text = str(threads) if threads is not None else os.environ.get(THREADS_ENV, "1")
    source = "threads" if threads is not None else THREADS_ENV
    if not text.strip().isdigit() or int(text) < 1:
        raise ConfigError(f"{source}={text!r}: expected a positive number of TensorFlow threads")
    return int(text)


def environment(threads: int | None = None) -> dict[str, str]:
    """The variables `configure` sets: for this process, or for a worker started elsewhere (Ray)."""
    settings = {name: os.environ.get(name, value) for name, value in DEFAULTS.items()}
    return {**settings, INTRA_ENV: str(threads_wanted(threads)), INTER_ENV: "1"}


def tensorflow_threads() -> tuple[int, int]:
    """The intra-op and inter-op thread counts TensorFlow runs with (0: its default, every core):
    set from Python, else read from the environment when its runtime started."""
    import tensorflow as tf

    intra = tf.config.threading.get_intra_op_parallelism_threads() or int(os.environ.get(INTRA_ENV, "0"))
    inter = tf.config.threading.get_inter_op_parallelism_threads() or int(os.environ.get(INTER_ENV, "0"))
    return intra, inter


def configure(threads: int | None = None) -> None:
    """Quiet logs, oneDNN off and `threads` intra-op threads (default `DQFD_TF_THREADS`, else 1)
    and one inter-op thread, for this process and the processes it starts. Call it before
    TensorFlow loads: oneDNN and the C++ log level are read only then. Later, the threads are still
    set if TensorFlow has run no op yet; once it has, a different count is a `DqfdWarning` (the
    process keeps the pools it has)."""
    settings = environment(threads)
    loaded = sys.modules.get("tensorflow") is not None  # None: blocked (an SB3 process keeps TensorFlow out)
    running = tensorflow_threads() if loaded else (0, 0)
    os.environ.update(settings)
    logging.getLogger("tensorflow").setLevel(logging.ERROR)  # tf.get_logger(), without importing TensorFlow
    if not loaded:
        return
    import tensorflow as tf

    wanted = (int(settings[INTRA_ENV]), 1)
    try:
        tf.config.threading.set_intra_op_parallelism_threads(wanted[0])
        tf.config.threading.set_inter_op_parallelism_threads(wanted[1])
    except RuntimeError:  # the runtime has started: its pools are fixed
        if running != wanted:
            warnings.warn(
                f"TensorFlow has run already with {running[0]} intra-op and {running[1]} inter-op threads "
                f"(0: every core); call configure(threads={wanted[0]}) before its first op",
                DqfdWarning,
                stacklevel=2,
            )


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
