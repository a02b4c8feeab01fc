"""Typed errors for user mistakes: the command-line tools turn each into one line and exit 2."""

from __future__ import annotations

import re


class DqfdError(Exception):
    """Base class of every error a user can cause (bad file, bad option, bad model)."""


class ConfigError(DqfdError, ValueError):
    """An option has a value the algorithm cannot use; the message names the value."""


class DemoFileError(DqfdError, ValueError):
    """A demonstration dataset cannot be used; the message names the file and the problem."""

    def __init__(self, path: object, problem: str) -> None:
        super().__init__(f"{path}: {problem}")
        self.path = path
        self.problem = problem


class ModelFileError(DqfdError, ValueError):
    """A saved model is missing, corrupt or does not fit the task."""


class OutputExistsError(DqfdError, FileExistsError):
    """Writing would replace an existing result and the user did not ask for that."""


class RunDirectoryError(DqfdError):
    """A run directory cannot be written or resumed (in use, not a directory, a failed write);
    the message names the path."""


class DirectoryInUseError(RunDirectoryError):
    """Another live process holds the run directory's lock."""


class BrokenRunError(RunDirectoryError):
    """A run's checkpoint or config is corrupt or does not fit: it can only be started over."""


class DivergedError(DqfdError):
    """Training produced a non-finite loss: the run stops before saving it, keeping the last
    good checkpoint."""


class DqfdWarning(UserWarning):
    """Something a user should know that does not stop the run; the command-line tools print it
    as one line, `warning: …`."""


def one_line(error: BaseException) -> str:
    """An exception as one short line: its type and the first line of its message, without
    TensorFlow's op decorations (`{{function_node …}}`, `[Op:SaveV2]`)."""
    text = str(getattr(error, "message", None) or error).strip()
    text = re.sub(r"\{\{.*?\}\}\s*|\s*\[Op:\w+\]", "", text.splitlines()[0] if text else "")
    return f"{type(error).__name__}: {text}" if text else type(error).__name__


OLDER = "written by an older version? Read the run with that version, or train it again"
"""What a run file lacking a field of today's format is told: its value is not known (a default
may have changed since), so it is refused rather than filled in."""
