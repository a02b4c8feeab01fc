"""A user's code named by a string, `module:NAME`: a method (`--expert-loss`), a demonstrator rule
(`--expert`), a suite (`experiments run`), a preset's or an env's module (`--task`, `--env`).

One place imports it, so every way it can fail reads the same, in one line that says where to
look: the module is not on the path, the module's own code raised while it was imported (the
file and line), or it has no such name (the names it has of the kind asked for). The module is
found on `sys.path` as Python finds it: `python -m` puts the current directory there, an
installed command does not (PYTHONPATH=. does).
"""

from __future__ import annotations

import contextlib
import importlib
import importlib.util
import inspect
import traceback
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

from dqfd_bc_keras.errors import ConfigError, one_line


class PluginError(ConfigError):
    """A `module:NAME` that cannot give what it names; the message is one line."""


class NotAReference(PluginError):
    """The text is not `module:NAME`."""


class ModuleMissing(PluginError):
    """The module itself is not found."""


class ImportFailed(PluginError):
    """The module is found but raised while it was imported (an ImportError of its own included)."""


class NameMissing(PluginError):
    """The module has no such name."""


class WrongKind(PluginError):
    """The name is there but is not what the caller takes."""


def where(filename: str, line: int | None = None) -> str:
    """A source location as the user would look it up: relative to the working directory when under it."""
    path = Path(filename)
    with contextlib.suppress(OSError, ValueError):  # outside it, or no working directory: as given
        path = path.resolve().relative_to(Path.cwd())
    return f"{path}:{line}" if line else str(path)


def raised_at(error: BaseException, file: str | None) -> str:
    """Where `error` was raised: its innermost frame in the user's `file` (else its innermost frame
    outside the import machinery), as file:line; a SyntaxError names its own line."""
    if isinstance(error, SyntaxError) and error.filename:
        return where(error.filename, error.lineno)
    frames = [frame for frame in traceback.extract_tb(error.__traceback__) if not frame.filename.startswith("<")]
    own = [frame for frame in frames if frame.filename == file]
    frame = (own or frames)[-1] if frames else None
    return where(frame.filename, frame.lineno) if frame else "no source file"


def parse(text: str) -> tuple[str, str] | None:
    """(module, NAME) of `module:NAME` (split at the last colon); None for text that is not one."""
    module, sep, name = text.rpartition(":")
    return (module, name) if sep and module and name else None


def bare_id(env_id: str) -> str:
    """A Gymnasium id without its `module:` prefix, which only says what to import: the id to make."""
    return env_id.rpartition(":")[2]


def import_module(module: str, what: str) -> ModuleType:
    """`module`, imported; `ModuleMissing` when it is not on the path, `ImportFailed` (the error and
    the file:line that raised it) when its own code raises. `what` opens each message."""
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as error:
        if error.name is not None and (module == error.name or module.startswith(f"{error.name}.")):
            raise ModuleMissing(f"{what}: no module named {error.name!r} (is its directory on PYTHONPATH?)") from None
        problem: BaseException = error
    except Exception as error:  # the module's own code raised while it was imported
        problem = error
    try:
        found = importlib.util.find_spec(module)
    except (ImportError, ValueError):
        found = None
    text = f"SyntaxError: {problem.msg}" if isinstance(problem, SyntaxError) else one_line(problem)  # no (file, line)
    raise ImportFailed(
        f"{what}: importing {module} raised {text} ({raised_at(problem, found.origin if found else None)})"
    ) from None


def load(text: str, what: str, kind: Callable[[object], bool] = lambda _: True, noun: str = "attribute") -> object:
    """The object `text` (module:NAME) names, which `kind` must accept (a `noun`). Besides
    `import_module`'s errors: `NotAReference`, `NameMissing` listing the module's public names of
    that kind (those defined in it, for functions and classes), `WrongKind` naming the type found."""
    parsed = parse(text)
    if parsed is None:
        raise NotAReference(f"{what}: expected module:NAME")
    module, name = parsed
    imported = import_module(module, what)
    if not hasattr(imported, name):
        found = getattr(imported, "__file__", None)
        raise NameMissing(
            f"{what}: {module} ({where(found) if found else module}) has no {noun} {name!r}; "
            f"it has {', '.join(_names(imported, kind)) or 'none'}"
        )
    value = getattr(imported, name)
    if not kind(value):
        raise WrongKind(f"{what}: {name} is not a {noun} (it is of type {type(value).__name__})")
    return value


def _names(module: ModuleType, kind: Callable[[object], bool]) -> list[str]:
    """The public names of `module` whose value `kind` accepts, sorted; a function or class only
    where it is defined (not every module that imports it)."""
    return sorted(
        key
        for key, value in vars(module).items()
        if not key.startswith("_")
        and kind(value)
        and not ((inspect.isfunction(value) or inspect.isclass(value)) and value.__module__ != module.__name__)
    )
