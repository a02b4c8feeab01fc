"""What every command-line entry point shares: one-line errors and exit code 2."""

from __future__ import annotations

import argparse
import signal
import sys
from collections.abc import Callable, Sequence

from .errors import DqfdError
from .seeds import MAX_SEED

EXIT_USAGE = 2


class ArgumentParser(argparse.ArgumentParser):
    """argparse, but a bad argument is one line on stderr (no usage block) and exit code 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        print(f"{self.prog}: error: {message}", file=sys.stderr)
        sys.exit(EXIT_USAGE)


def add_task_arguments(parser: argparse.ArgumentParser, default: str | None = None, required: bool = False) -> None:
    """`--task PRESET` or `--env ID` (any Gymnasium env with a flat Box observation and Discrete
    actions; `module:Env-v0` imports `module` first); read the choice with `chosen_task`."""
    from .envs import TASKS

    group = parser.add_mutually_exclusive_group(required=required)
    group.add_argument("--task", choices=sorted(TASKS),
                       help="task preset" + (f" (default: {default})" if default else ""))
    group.add_argument("--env", metavar="ID", help="any Gymnasium env id instead of a preset, e.g. Acrobot-v1 "
                       "or my_module:MyEnv-v0 (generic defaults; see config.EnvConfig)")
    parser.set_defaults(default_task=default)


def chosen_task(args: argparse.Namespace) -> str | None:
    """The task of `add_task_arguments`' flags: --env, else --task, else the default."""
    return args.env or args.task or args.default_task


def positive_int(text: str) -> int:
    """argparse type for counts that must be ≥ 1 (episodes, steps, seeds)."""
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {value}")
    return value


def seed(text: str) -> int:
    """argparse type for a seed: an integer in [0, MAX_SEED]."""
    value = int(text)
    if not 0 <= value <= MAX_SEED:
        raise argparse.ArgumentTypeError(f"must be in [0, {MAX_SEED}], got {value}")
    return value


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised like Ctrl-C so that it stops a run the same way (a run is resumable from
    its last checkpoint at any moment)."""


def _terminate(signum: int, frame: object) -> None:
    raise Terminated


def run(main: Callable[[Sequence[str] | None], int], argv: Sequence[str] | None = None) -> int:
    """Call `main`, turning every failure a user can meet into one line on stderr: a user error
    or an OS error (full disk, read-only path, a directory where a file belongs) exits 2,
    Ctrl-C 130 and SIGTERM 143."""
    signal.signal(signal.SIGTERM, _terminate)
    try:
        return main(argv)
    except DqfdError as error:
        print(f"error: {error}", file=sys.stderr)
        return EXIT_USAGE
    except OSError as error:
        where = f"{error.filename}: " if error.filename else ""
        print(f"error: {where}{error.strerror or error}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt as error:
        name, code = ("SIGTERM", 143) if isinstance(error, Terminated) else ("Ctrl-C", 130)
        print(f"interrupted ({name}); a training run continues from its last checkpoint with --resume",
              file=sys.stderr)
        return code
