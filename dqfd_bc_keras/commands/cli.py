"""What every command-line entry point shares: TensorFlow's process settings (`runtime.configure`),
one-line errors and exit code 2, near misses answered with a suggestion. Light on purpose (no
TensorFlow): a command parses its arguments before it imports anything heavy."""

from __future__ import annotations

import argparse
import ast
import difflib
import json
import re
import signal
import sys
import warnings
from collections.abc import Callable, Sequence
from typing import Any, TypedDict

from dqfd_bc_keras import runtime
from dqfd_bc_keras.errors import DqfdError, DqfdWarning
from dqfd_bc_keras.seeds import MAX_SEED

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
    from dqfd_bc_keras.tasks import TASKS

    group = parser.add_mutually_exclusive_group(required=required)
    group.add_argument(
        "--task",
        metavar="{" + ",".join(sorted(TASKS)) + "}",
        type=task_preset,
        help="task preset, or your own as module:preset" + (f" (default: {default})" if default else ""),
    )
    group.add_argument(
        "--env",
        metavar="ID",
        type=env_id,
        help="any Gymnasium env id instead of a preset, e.g. Acrobot-v1 or my_module:MyEnv-v0, or "
        "my_module:make_env, a function returning an env (generic defaults: tasks.ENV_DEFAULTS)",
    )
    parser.add_argument(
        "--max-steps",
        type=positive_int,
        metavar="N",
        help="episode step limit (required for an env registered without one)",
    )
    parser.add_argument(
        "--env-kwargs",
        nargs="+",
        action="extend",
        type=env_kwarg,
        metavar="KEY=VALUE",
        help="keyword arguments of the env's constructor; each value is JSON (use_lidar=false, "
        "config='{\"lanes_count\": 3}'), else a Python literal (is_slippery=False, "
        "observation_shape=84,84 or '(84, 84)', a tuple, kept one), else a plain string if it is a word: "
        "letters, digits and _ . - : / with a letter, not starting with - (obs_type=ram, "
        "map_name=8x8); anything else, e.g. a value that does not parse, is an error",
    )
    parser.set_defaults(default_task=default)


def preset_default(field: str) -> str:
    """Config `field`'s default as the task presets set it, for a help text: its one value, or the
    most common one, then each other with its presets (`10; 5 on cartpole, cartpole-200`). Generated,
    so that a help text cannot state a default the presets do not have."""
    from dqfd_bc_keras.core.config import Config
    from dqfd_bc_keras.tasks import TASKS

    presets: dict[object, list[str]] = {}
    for name in sorted(TASKS):
        presets.setdefault(getattr(Config.for_task(name), field), []).append(name)
    common, *others = sorted(presets, key=lambda value: -len(presets[value]))
    shown = [_shown(common), *(f"{_shown(value)} on {', '.join(presets[value])}" for value in others)]
    return "; ".join(shown)


def _shown(value: object) -> str:
    return f"{value:,}" if isinstance(value, int) and not isinstance(value, bool) else str(value)


def chosen_task(args: argparse.Namespace) -> str | None:
    """The task of `add_task_arguments`' flags: --env, else --task, else the default."""
    return args.env or args.task or args.default_task


def task_preset(text: str) -> str:
    """argparse type of `--task`: a preset's name, or `module:preset` (importing `module` registers
    it). A Gymnasium id suggests `--env`, a near miss the preset it resembles."""
    from dqfd_bc_keras.plugins import PluginError, import_module, parse
    from dqfd_bc_keras.tasks import TASKS, find_preset

    if find_preset(text) is not None:
        return text
    parsed = parse(text)
    if parsed is not None:
        try:
            import_module(parsed[0], repr(text))  # a module missing or raising says so, not "use --env"
        except PluginError as error:
            raise argparse.ArgumentTypeError(str(error)) from None
    if ":" in text or re.search(r"-v\d+$", text):
        raise argparse.ArgumentTypeError(
            f"{text!r} is a Gymnasium env id, not a task preset: did you mean --env {text}?"
        )
    near = difflib.get_close_matches(text, TASKS, n=1)
    hint = (
        f"; did you mean {near[0]}?"
        if near
        else f" (choose from {', '.join(map(repr, sorted(TASKS)))}; any Gymnasium env: --env ID)"
    )
    raise argparse.ArgumentTypeError(f"invalid choice: {text!r}{hint}")


def env_id(text: str) -> str:
    """argparse type of `--env`: a registered Gymnasium id (`module:Env-v0` imports `module`), or a
    preset's name; an unknown id that resembles a preset suggests `--task`."""
    from dqfd_bc_keras.envs.make import get_task
    from dqfd_bc_keras.errors import ConfigError
    from dqfd_bc_keras.tasks import TASKS

    try:
        get_task(text)
    except ConfigError as error:
        near = difflib.get_close_matches(text.lower(), TASKS, n=1)
        hint = f"; did you mean --task {near[0]}?" if near else ""
        raise argparse.ArgumentTypeError(f"{error}{hint}") from None
    return text


class EnvSettings(TypedDict, total=False):
    """The Config fields `--max-steps` and `--env-kwargs` give."""

    max_steps: int
    env_kwargs: dict[str, Any]


def env_settings(args: argparse.Namespace) -> EnvSettings:
    """The Config fields given by `--max-steps` and `--env-kwargs` (only those given)."""
    settings: EnvSettings = {}
    if args.max_steps is not None:
        settings["max_steps"] = args.max_steps
    if args.env_kwargs:
        settings["env_kwargs"] = dict(args.env_kwargs)
    return settings


WORD = re.compile(r"(?=[^-]*[A-Za-z])[A-Za-z0-9_][A-Za-z0-9_.:/-]*")
"""A value `--env-kwargs` keeps as a plain string: letters, digits and `_ . : / -`, with at least one
letter, not starting with `-` (`rgb_array`, `8x8`, `human-ish`)."""
MISSPELLED_CONSTANTS = {
    "true": ("true", "True"),
    "false": ("false", "False"),
    "none": ("null", "None"),
    "null": ("null", "None"),
}
"""Words that mean a constant but are none in JSON or Python (`FALSE`, `none`): their JSON and Python
spellings, suggested instead of keeping them as a string (a truthy one)."""


def env_kwarg(text: str) -> tuple[str, object]:
    """argparse type of `--env-kwargs`: KEY=VALUE, the value as JSON, else as a Python literal
    (`ast.literal_eval`: `False`, `None`, `'ram'`, tuples), else as a string when it is a `WORD`.
    A value kept as a string by mistake is passed on silently ("False" is truthy), so anything
    else is refused, naming the key and why. Values are JSON values (a tuple as `{"__tuple__": [...]}`:
    `envs.kwargs`), as config.json stores them for every later env of the run."""
    key, sep, value = text.partition("=")
    key = key.strip()
    if not sep or not key.isidentifier():
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE with KEY a Python identifier, got {text!r}")
    try:
        return key, json.loads(value)
    except ValueError as error:  # JSONDecodeError, or an integer of more digits than Python converts
        json_error = str(error)
    try:
        parsed = ast.literal_eval(value.strip())
    except (ValueError, SyntaxError, TypeError, MemoryError, RecursionError) as error:
        literal_error = f"{type(error).__name__}: {str(error).splitlines()[0] if str(error) else 'malformed'}"
    else:
        from dqfd_bc_keras.envs.kwargs import as_json as recorded_value  # gymnasium: only once needed

        try:
            return key, recorded_value(parsed)
        except TypeError as error:
            raise argparse.ArgumentTypeError(
                f"{key}={value}: a Python {type(parsed).__name__}, which JSON cannot hold ({error})"
            ) from None
    if value.lower() in MISSPELLED_CONSTANTS:
        as_json, as_python = MISSPELLED_CONSTANTS[value.lower()]
        raise argparse.ArgumentTypeError(
            f"{key}={value} is neither JSON nor Python: write {key}={as_json} or "
            f"{key}={as_python}, or {key}='\"{value}\"' for the string"
        )
    if WORD.fullmatch(value):
        return key, value
    start = value.lstrip()[:1]
    why = (
        f"is not valid JSON ({json_error})"
        if start in ("{", "[", '"')
        else f"is not a valid Python literal ({literal_error})"
        if start in ("(", "'")
        else "is neither JSON, a Python literal nor a word (letters, digits, _ . : / -, with a letter)"
    )
    raise argparse.ArgumentTypeError(
        f"{key}={value} {why}; a string that is not a word is written as JSON: {key}='\"...\"'"
    )


def positive_int(text: str) -> int:
    """argparse type for counts that must be ≥ 1 (episodes, steps, seeds)."""
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {value}")
    return value


def positive_float(text: str) -> float:
    """argparse type for a rate that must be > 0 and finite (frames per second)."""
    value = float(text)
    if not 0 < value < float("inf"):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text}")
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


def raise_terminated(signum: int, frame: object) -> None:
    """The SIGTERM handler of every process of ours: SIGTERM stops it as Ctrl-C does."""
    raise Terminated


_default_showwarning = warnings.showwarning


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Our own warnings as one line on stderr; everyone else's as Python prints them."""
    if issubclass(category, DqfdWarning):
        print(f"warning: {message}", file=sys.stderr)
    else:
        _default_showwarning(message, category, filename, lineno, file, line)


RESUMABLE = "a training run continues from its last checkpoint with --resume"


def run(
    main: Callable[[Sequence[str] | None], int], argv: Sequence[str] | None = None, interrupted: str = RESUMABLE
) -> int:
    """Call `main` in a process configured as every command's is (`runtime.configure`: quiet, oneDNN
    off, `DQFD_TF_THREADS` or 1 thread, set before the command loads TensorFlow), turning every
    failure a user can meet into one line on stderr: a user error or an OS error (full disk,
    read-only path, a directory where a file belongs) exits 2, Ctrl-C 130 and SIGTERM 143 (saying
    `interrupted`: what the interruption left)."""
    signal.signal(signal.SIGTERM, raise_terminated)
    warnings.showwarning = _show_warning
    try:
        runtime.configure()
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
        print(f"interrupted ({name}); {error.args[0] if error.args else interrupted}", file=sys.stderr)  # what it left
        return code
