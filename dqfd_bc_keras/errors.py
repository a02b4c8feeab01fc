"""Typed errors for user mistakes: the command-line tools turn each into one line and exit 2."""

from __future__ import annotations


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
