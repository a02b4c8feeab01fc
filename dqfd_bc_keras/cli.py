"""What every command-line entry point shares: one-line errors and exit code 2, near misses
answered with a suggestion. Light on purpose (no TensorFlow): a command parses its arguments
before it imports anything heavy."""

from __future__ import annotations

import argparse
import difflib
import json
import re
import signal
import sys
import warnings
from collections.abc import Callable, Sequence

from .errors import DqfdError, DqfdWarning
from .seeds import MAX_SEED

EXIT_USAGE = 2


class ArgumentParser(argparse.ArgumentParser):
    """argparse, but a bad argument is one line on stderr (no usage block) and exit code 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        print(f"{self.prog}: error: {message}", file=sys.stderr)
        sys.exit(EXIT_USAGE)


def add_task_arguments(parser: argparse.ArgumentParser, default: str | None = None, required: bool = False) -> None:
    """`--task PRESET` or `--env ID` (any Gymnasium env with Discrete actions; `module:Env-v0`
    imports `module` first), with `--max-steps N` and `--env-kwargs KEY=VALUE …`; read the
    choice with `chosen_task` and the env settings with `env_settings`."""
    from .tasks import TASKS

    group = parser.add_mutually_exclusive_group(required=required)
    group.add_argument("--task", metavar="{" + ",".join(sorted(TASKS)) + "}", type=task_preset,
                       help="task preset, or your own as module:preset" + (f" (default: {default})" if default else ""))
    group.add_argument("--env", metavar="ID", type=env_id, help="any Gymnasium env id instead of a preset, e.g. Acrobot-v1 "
                       "or my_module:MyEnv-v0 (generic defaults: tasks.ENV_DEFAULTS)")
    parser.add_argument("--max-steps", type=positive_int, metavar="N",
                        help="episode step limit (required for an env registered without one)")
    parser.add_argument("--env-kwargs", nargs="+", action="extend", type=env_kwarg, metavar="KEY=VALUE",
                        help="keyword arguments of the env's constructor, values as JSON (use_lidar=false, "
                             'obs_type=\'"ram"\', config=\'{"lanes_count": 3}\'), else a plain string')
    parser.set_defaults(default_task=default)


def chosen_task(args: argparse.Namespace) -> str | None:
    """The task of `add_task_arguments`' flags: --env, else --task, else the default."""
    return args.env or args.task or args.default_task


def task_preset(text: str) -> str:
    """argparse type of `--task`: a preset's name, or `module:preset` (importing `module` registers
    it). A Gymnasium id suggests `--env`, a near miss the preset it resembles."""
    from .tasks import TASKS, find_preset

    if find_preset(text) is not None:
        return text
    if ":" in text or re.search(r"-v\d+$", text):
        raise argparse.ArgumentTypeError(f"{text!r} is a Gymnasium env id, not a task preset: did you mean --env {text}?")
    near = difflib.get_close_matches(text, TASKS, n=1)
    hint = (f"; did you mean {near[0]}?" if near else
            f" (choose from {', '.join(map(repr, sorted(TASKS)))}; any Gymnasium env: --env ID)")
    raise argparse.ArgumentTypeError(f"invalid choice: {text!r}{hint}")


def env_id(text: str) -> str:
    """argparse type of `--env`: a registered Gymnasium id (`module:Env-v0` imports `module`), or a
    preset's name; an unknown id that resembles a preset suggests `--task`."""
    from .envs import get_task
    from .errors import ConfigError
    from .tasks import TASKS

    try:
        get_task(text)
    except ConfigError as error:
        near = difflib.get_close_matches(text.lower(), TASKS, n=1)
        hint = f"; did you mean --task {near[0]}?" if near else ""
        raise argparse.ArgumentTypeError(f"{error}{hint}") from None
    return text


def env_settings(args: argparse.Namespace) -> dict[str, object]:
    """The Config fields given by `--max-steps` and `--env-kwargs` (only those given)."""
    settings: dict[str, object] = {}
    if args.max_steps is not None:
        settings["max_steps"] = args.max_steps
    if args.env_kwargs:
        settings["env_kwargs"] = dict(args.env_kwargs)
    return settings


def env_kwarg(text: str) -> tuple[str, object]:
    """argparse type of `--env-kwargs`: KEY=VALUE, the value parsed as JSON, else kept as a string."""
    key, sep, value = text.partition("=")
    if not sep or not key.strip().isidentifier():
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE with KEY a Python identifier, got {text!r}")
    try:
        return key.strip(), json.loads(value)
    except json.JSONDecodeError:
        return key.strip(), value


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


_default_showwarning = warnings.showwarning


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Our own warnings as one line on stderr; everyone else's as Python prints them."""
    if issubclass(category, DqfdWarning):
        print(f"warning: {message}", file=sys.stderr)
    else:
        _default_showwarning(message, category, filename, lineno, file, line)


RESUMABLE = "a training run continues from its last checkpoint with --resume"


def run(main: Callable[[Sequence[str] | None], int], argv: Sequence[str] | None = None,
        interrupted: str = RESUMABLE) -> int:
    """Call `main`, turning every failure a user can meet into one line on stderr: a user error
    or an OS error (full disk, read-only path, a directory where a file belongs) exits 2,
    Ctrl-C 130 and SIGTERM 143 (saying `interrupted`: what the interruption left)."""
    signal.signal(signal.SIGTERM, _terminate)
    warnings.showwarning = _show_warning
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
        print(f"interrupted ({name}); {interrupted}", file=sys.stderr)
        return code
