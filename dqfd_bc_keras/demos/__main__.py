"""`python -m dqfd_bc_keras.demos record|inspect|export|...`: the demonstrations' command line
(commands/demos.py)."""

import sys

from dqfd_bc_keras.commands.cli import run
from dqfd_bc_keras.commands.demos import main

sys.exit(run(main))
