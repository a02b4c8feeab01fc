"""Sample efficiency against SB3's DQN: `python benchmarks/bench_sample_efficiency.py …` is the lab's
`python -m dqfd_bc_keras.experiments efficiency …` (dqfd_bc_keras/experiments/baselines.py), kept
for the commands the docs and the archived results give."""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from dqfd_bc_keras.commands.cli import run
from dqfd_bc_keras.experiments.__main__ import main as lab
from dqfd_bc_keras.experiments.baselines import PROTOCOL, SB3_METHOD, sb3_run, sb3_settings  # noqa: F401  (tests)
from dqfd_bc_keras.experiments.zoo import ZOO  # noqa: F401  (tests)


def main(argv: Sequence[str] | None = None) -> int:
    return lab(["efficiency", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":
    sys.exit(run(main))
