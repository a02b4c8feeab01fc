"""Where a run ran: the code and rules commits, the library versions, and the machine.

A rerun is bit-identical only on the same code, seed, library builds and kind of machine: the
floating-point kernels TensorFlow picks depend on the CPU's instruction sets and on oneDNN.
`provenance()` records all of that in every finished run's `provenance.json`, so a difference
between two machines can be told apart from a difference in the code.
"""

from __future__ import annotations

import os
import platform
import subprocess
from pathlib import Path

from dqfd_bc_keras import runtime

RULES = (
    "dqfd_bc_keras/experiments/claims.py",
    "dqfd_bc_keras/experiments/metrics.py",
    "dqfd_bc_keras/experiments/arms.py",
    "dqfd_bc_keras/tasks",
    "docs/PREREGISTRATION.md",
)
"""Where the verdict rules live: `rules_commit` is the last commit that changed any of them."""

ISA_FLAGS = ("sse4_2", "avx", "avx2", "fma", "avx512f", "avx512_vnni", "amx_tile")
"""CPU instruction sets that change which kernels TensorFlow and oneDNN run."""


def _git(*args: str) -> str | None:
    root = Path(__file__).resolve().parents[1]
    try:
        done = subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout.strip() if done.returncode == 0 else None


def machine() -> dict:
    """The CPU (model and the instruction sets of `ISA_FLAGS` it has), its cores, and the OS."""
    model, flags = platform.processor() or None, set()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            key, _, value = line.partition(":")
            if key.strip() == "model name" and value.strip():
                model = value.strip()
            elif key.strip() == "flags":
                flags = set(value.split())
    except OSError:
        pass
    return {
        "cpu": model,
        "isa": [flag for flag in ISA_FLAGS if flag in flags],
        "cores": os.cpu_count(),
        "system": platform.platform(),
        "python": platform.python_version(),
    }


def tensorflow_build() -> dict:
    """TensorFlow's version and build, whether oneDNN is on, and the thread pools in force."""
    import tensorflow as tf

    intra_op_threads, inter_op_threads = runtime.tensorflow_threads()
    return {
        "version": tf.__version__,
        "git_version": tf.version.GIT_VERSION,
        "compiler": tf.version.COMPILER_VERSION,
        "build": {key: value for key, value in tf.sysconfig.get_build_info().items() if isinstance(value, bool)},
        "onednn": os.environ.get("TF_ENABLE_ONEDNN_OPTS", "(TensorFlow's default)"),
        "intra_op_threads": intra_op_threads,
        "inter_op_threads": inter_op_threads,
    }


def provenance() -> dict:
    """The code a run ran and the rules that will judge it (commits, None outside a git checkout;
    whether tracked files differed from the commit), the library versions, the machine and
    TensorFlow's build."""
    import gymnasium
    import keras
    import numpy
    import tensorflow

    status = _git("status", "--porcelain", "--untracked-files=no")
    return {
        "code_commit": _git("rev-parse", "HEAD"),
        "rules_commit": _git("log", "-1", "--format=%H", "--", *RULES),
        "dirty": bool(status) if status is not None else None,
        "versions": {m.__name__: m.__version__ for m in (tensorflow, keras, gymnasium, numpy)},
        "machine": machine(),
        "tensorflow": tensorflow_build(),
    }
