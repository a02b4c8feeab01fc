"""The front door: README's two commands, CI running the test command verbatim, quiet TF."""

import os
import re
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def quick_start_commands() -> list[str]:
    readme = (REPO / "README.md").read_text()
    section = readme.split("## Quick start", 1)[1].split("\n## ", 1)[0]
    return re.findall(r"```bash\n(.+?)\n```", section, flags=re.S)


def test_quick_start_is_two_single_line_commands_and_ci_runs_the_second():
    commands = quick_start_commands()
    assert len(commands) == 2 and all("\n" not in c for c in commands)
    install = "python3.11 -m venv .venv && .venv/bin/pip install -q -r requirements.txt"
    assert all(c.startswith(install) for c in commands)
    assert commands[1].endswith("-m pytest -q -n 2")
    ci = (REPO / ".ci" / "run").read_text().splitlines()
    assert commands[1] in ci and "set -euo pipefail" in ci


def test_tensorflow_is_quiet_and_single_threaded():
    code = ("from dqfd_bc_keras import runtime; runtime.configure_tensorflow(); import tensorflow as tf; "
            "print(tf.reduce_sum(tf.ones(3)).numpy(), tf.config.threading.get_intra_op_parallelism_threads(), "
            "tf.config.threading.get_inter_op_parallelism_threads())")
    env = {k: v for k, v in os.environ.items() if not k.startswith(("TF_", "DQFD_"))}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO,
                          env=env, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["3.0", "1", "1"]
    assert done.stderr == ""
