"""Train an agent (Algorithm 1). Not implemented yet: arrives with issue C."""

import sys

from dqfd_bc_keras.cli import ArgumentParser


def main() -> int:
    ArgumentParser(prog="train.py", description=__doc__).parse_args()
    print("train.py: not yet implemented (issue C); record demonstrations with "
          "`python -m dqfd_bc_keras.demos record` meanwhile", file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main())
