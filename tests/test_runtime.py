"""What the package does to the process that uses it: importing it changes nothing process-wide; the
command lines, and a Python user who calls `dqfd_bc_keras.configure()`, get quiet logs, oneDNN off and
the thread pools they ask for, set before TensorFlow loads."""

import functools
import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
CLEAN = {k: v for k, v in os.environ.items() if not k.startswith(("TF_", "DQFD_", "KERAS_"))}
"""A user's environment: none of the variables `runtime.configure` sets (the tests' own process has them)."""


def python(code: str, **env: str) -> subprocess.CompletedProcess:
    done = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        cwd=REPO,
        env={**CLEAN, "PYTHONPATH": str(REPO), **env},
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    return done


IMPORT_EVERYTHING = """
import ast, importlib, json, logging, os, pkgutil, sys
from pathlib import Path

package = Path("dqfd_bc_keras")
for path in package.rglob("*.py"):  # first every third-party module the package imports: their changes are theirs
    for node in ast.parse(path.read_text()).body:
        names = [a.name for a in node.names] if isinstance(node, ast.Import) else []
        names += [node.module] if isinstance(node, ast.ImportFrom) and node.level == 0 else []
        for name in names:
            if not name.startswith("dqfd_bc_keras"):
                try:
                    importlib.import_module(name.split(".")[0])
                except ImportError:
                    pass
import tensorflow as tf

def state():
    return {
        "environ": dict(os.environ),
        "meta_path": [repr(finder) for finder in sys.meta_path],
        "tensorflow_logger": logging.getLogger("tensorflow").level,
        "threads": [
            tf.config.threading.get_intra_op_parallelism_threads(),
            tf.config.threading.get_inter_op_parallelism_threads(),
        ],
    }

before = state()
import dqfd_bc_keras
from dqfd_bc_keras import DQfD
modules = [m.name for m in pkgutil.walk_packages(dqfd_bc_keras.__path__, "dqfd_bc_keras.")]
modules = [name for name in modules if not name.endswith("__main__")]  # a command line: it runs
for name in modules:
    importlib.import_module(name)
print(json.dumps({"before": before, "after": state(), "modules": len(modules), "DQfD": DQfD.__name__}))
"""


def test_importing_the_package_and_every_module_changes_nothing_process_wide():
    import json

    done = json.loads(python(IMPORT_EVERYTHING).stdout.splitlines()[-1])
    assert done["DQfD"] == "DQfD" and done["modules"] > 50
    before, after = done["before"], done["after"]
    assert after["environ"] == before["environ"]  # no TF_CPP_MIN_LOG_LEVEL, TF_ENABLE_ONEDNN_OPTS, KERAS_BACKEND, …
    assert after["meta_path"] == before["meta_path"]  # no import hook
    assert after["tensorflow_logger"] == before["tensorflow_logger"]
    assert after["threads"] == before["threads"] == [0, 0]  # TensorFlow's defaults, untouched


THREADS = "print(len(os.listdir('/proc/self/task')), *runtime.tensorflow_threads(), os.environ[runtime.ONEDNN_ENV])"
"""After one TensorFlow op: the process's OS threads, the pools as `runtime` reads them, oneDNN's switch."""


@functools.cache
def set_from_python(threads: int) -> list[str]:
    """What a process that sets its pools with TensorFlow's own calls prints: the reference."""
    return python(
        "import os, tensorflow as tf; from dqfd_bc_keras import runtime; "
        f"tf.config.threading.set_intra_op_parallelism_threads({threads}); "
        "tf.config.threading.set_inter_op_parallelism_threads(1); tf.reduce_sum(tf.ones(3)); " + THREADS,
        TF_ENABLE_ONEDNN_OPTS="0",
        TF_CPP_MIN_LOG_LEVEL="3",
    ).stdout.split()


@pytest.mark.slow  # trains in a subprocess
def test_a_command_line_runs_quiet_with_onednn_off_and_one_thread_or_dqfd_tf_threads():
    code = (
        "import os, sys; from dqfd_bc_keras import runtime; from dqfd_bc_keras.commands import cli\n"
        "def main(argv):\n    import tensorflow as tf; tf.reduce_sum(tf.ones(3)); " + THREADS + "; return 0\n"
        "sys.exit(cli.run(main))"
    )
    one = python(code)
    assert one.stdout.split() == set_from_python(1) and one.stdout.split()[1:] == ["1", "1", "0"]
    assert one.stderr == ""  # TensorFlow's C++ banners and logs are off
    two = python(code, DQFD_TF_THREADS="2")
    assert two.stdout.split() == set_from_python(2) and two.stdout.split()[1:] == ["2", "1", "0"]


def test_a_command_line_is_quiet_and_refuses_a_bad_thread_count_in_one_line():
    evaluate = [sys.executable, "evaluate.py", "models/cartpole", "--episodes", "1"]
    done = subprocess.run(evaluate, capture_output=True, text=True, cwd=REPO, env=CLEAN, timeout=300)
    assert done.returncode == 0 and "return 500.00" in done.stdout and done.stderr == "", done.stderr
    done = subprocess.run(
        evaluate, capture_output=True, text=True, cwd=REPO, env={**CLEAN, "DQFD_TF_THREADS": "two"}, timeout=300
    )
    assert (done.returncode, done.stderr) == (
        2,
        "error: DQFD_TF_THREADS='two': expected a positive number of TensorFlow threads\n",
    )


def test_a_python_user_configures_the_process_first_and_is_told_when_it_is_too_late():
    code = (
        "import os, warnings, dqfd_bc_keras; from dqfd_bc_keras import runtime\n"
        "from dqfd_bc_keras.errors import ConfigError\n"
        "try:\n    dqfd_bc_keras.configure(threads=0)\nexcept ConfigError as error:\n    print(error)\n"
        "dqfd_bc_keras.configure(threads=2)\n"
        "import tensorflow as tf; tf.reduce_sum(tf.ones(3)); " + THREADS + "\n"
        "with warnings.catch_warnings(record=True) as caught:\n"
        "    warnings.simplefilter('always'); dqfd_bc_keras.configure(threads=2); dqfd_bc_keras.configure(threads=3)\n"
        "print(*[f'{w.category.__name__}: {w.message}' for w in caught], sep='\\n')"
    )
    done = python(code)
    refused, threads, *warned = done.stdout.splitlines()
    assert refused == "threads='0': expected a positive number of TensorFlow threads"
    assert threads.split() == set_from_python(2)
    assert warned == [  # the same count again is no news; another is
        "DqfdWarning: TensorFlow has run already with 2 intra-op and 1 inter-op threads (0: every core); "
        "call configure(threads=3) before its first op"
    ]
    assert done.stderr == ""


def test_a_process_that_keeps_tensorflow_out_is_configured_without_it(monkeypatch):
    """An SB3 process blocks TensorFlow (`sys.modules["tensorflow"] = None`, as experiments/sb3_pixels.py
    does): its command line configures it all the same, without importing TensorFlow."""
    from dqfd_bc_keras import runtime

    monkeypatch.setitem(sys.modules, "tensorflow", None)
    for name in runtime.environment():
        monkeypatch.setenv(name, os.environ.get(name, ""))  # restored after the test, whatever configure sets
    runtime.configure(threads=3)
    assert sys.modules["tensorflow"] is None and os.environ[runtime.INTRA_ENV] == "3"


SWEEP_FROM_PYTHON = """
import json, os, sys
from pathlib import Path
from dqfd_bc_keras.experiments.suites import SUITES
from dqfd_bc_keras.experiments.sweep import Job, SweepOptions, run_jobs

out = Path(sys.argv[1])
[outcome] = run_jobs([Job(SUITES["quick"][1], 0, out)], out, "one", 1, SweepOptions(workers=1, progress=lambda _: None))
tensorflow = json.loads((outcome.job.directory / "provenance.json").read_text())["tensorflow"]
print(outcome.error or "finished", tensorflow["onednn"], tensorflow["intra_op_threads"], tensorflow["inter_op_threads"])
print(sorted(name for name in os.environ if name.startswith(("TF_", "DQFD_", "KERAS_"))))
"""


@pytest.mark.slow  # trains in a subprocess
def test_a_sweep_worker_configures_itself_and_leaves_its_callers_process_alone(tmp_path):
    """The lab's engine called from Python by a process nobody configured: its worker runs as a
    command does (oneDNN off, one thread, as its provenance.json records), the caller stays as it was."""
    done = subprocess.run(
        [sys.executable, "-c", SWEEP_FROM_PYTHON, str(tmp_path)],
        capture_output=True,
        text=True,
        cwd=REPO,
        env={**CLEAN, "PYTHONPATH": str(REPO)},
        timeout=600,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines()[-2:] == ["finished 0 1 1", "[]"]
