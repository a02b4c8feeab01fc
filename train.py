"""Train an agent from a checkout: `python train.py …` is the `dqfd-train` command
(dqfd_bc_keras/commands/train.py; `python train.py --help` lists its flags)."""

import sys

from dqfd_bc_keras.commands.train import cli, main  # noqa: F401  (main: tests call it in-process)

if __name__ == "__main__":
    sys.exit(cli())
