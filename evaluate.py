"""Evaluate a trained agent from a checkout: `python evaluate.py …` is the `dqfd-evaluate` command
(dqfd_bc_keras/commands/evaluate.py; `python evaluate.py --help` lists its flags)."""

import sys

from dqfd_bc_keras.commands.evaluate import cli, main, progress_lines, time  # noqa: F401  (tests use them in-process)

if __name__ == "__main__":
    sys.exit(cli())
