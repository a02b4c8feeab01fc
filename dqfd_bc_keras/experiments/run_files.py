"""One complete run directory read into a `FinishedRun`: every file the lab reads of it checked,
and a missing, truncated or older file named in a `RunFileError`.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Any, cast

import numpy as np

from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.envs.episodes import EvalResult
from dqfd_bc_keras.errors import OLDER, ConfigError
from dqfd_bc_keras.training.records import DemoSummary, DemoUpdate, EpisodeRow, EvalRow, R

RUN_FILES = (
    "config.json",
    "metrics.csv",
    "evals.csv",
    "eval.json",
    "provenance.json",
    "demonstrations.json",
    "dynamic_demos.json",
)
"""What the lab reads of a run directory; the first five are in every complete run, demonstrations.json
in every run of a method with demonstrations, dynamic_demos.json once D_demo has been updated."""
REQUIRED = RUN_FILES[:5]


@dataclass(frozen=True)
class Provenance:
    """provenance.json: the code and the claims rules a run was trained with (what the lab reads of it)."""

    code_commit: str | None
    """None: trained outside a git checkout."""
    rules_commit: str | None
    dirty: bool | None
    """Trained from a working tree with uncommitted changes: the commit alone does not reproduce it."""
    versions: dict[str, str]

    @classmethod
    def of(cls, fields: dict) -> Provenance:
        _require(fields, [f.name for f in dataclasses.fields(cls)])
        return cls(**{f.name: fields[f.name] for f in dataclasses.fields(cls)})


@dataclass
class FinishedRun:
    """One complete run directory, parsed: what every table and figure of the lab reads."""

    path: Path
    """Where it was read from (inside an archive: the archive's path / the run's directory)."""
    config: Config
    metrics: list[EpisodeRow]
    evals: list[EvalRow]
    final: EvalResult
    """eval.json: the final evaluation."""
    demonstrations: DemoSummary | None
    """demonstrations.json; None for plain DQN, the one method without demonstrations."""
    dynamic_demos: list[DemoUpdate]
    """dynamic_demos.json: one entry per dynamic-demonstration update."""
    provenance: Provenance

    def column(self, name: str) -> np.ndarray:
        """metrics.csv's column `name`, one value per episode (an empty cell: NaN)."""
        return np.array([row[name] for row in self.metrics], dtype=float)

    @property
    def demo_transitions(self) -> int:
        """Demonstration transitions the run started from (0 for plain DQN)."""
        return 0 if self.demonstrations is None else self.demonstrations.transitions

    @property
    def demonstrator_return(self) -> float | None:
        """Mean plain return of those demonstrations: None for plain DQN."""
        return None if self.demonstrations is None else float(np.mean(self.demonstrations.plain_returns))


class RunFileError(ConfigError):
    """A file of a complete run is missing or unreadable; `file` is relative to the suite."""

    def __init__(self, file: PurePosixPath, problem: str) -> None:
        super().__init__(f"{file}: {problem}")
        self.file, self.problem = file, problem


class _Lacking(KeyError):
    """The fields a run file lacks."""


def _require(fields: dict, names: Iterable[str]) -> None:
    """`_Lacking` the `names` that the JSON object `fields` does not hold."""
    if not isinstance(fields, dict):
        raise TypeError(f"expected a JSON object, got {fields!r:.40}")
    missing = [name for name in names if name not in fields]
    if missing:
        raise _Lacking(missing)


def _text(path: Path, file: PurePosixPath) -> str:
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise RunFileError(file, "not UTF-8 text") from None


def _read_csv(path: Path, file: PurePosixPath, record: type[R]) -> list[R]:
    """The rows of `path` as `record`s; a truncated or garbled file is refused."""
    text = _text(path, file)
    if text and not text.endswith("\n"):
        raise RunFileError(file, "ends in the middle of a line (truncated?)")
    reader = csv.reader(io.StringIO(text))
    try:
        header, *lines = list(reader) or [[]]
    except csv.Error as error:
        raise RunFileError(file, f"line {reader.line_num}: {error}") from None
    missing = [c for c in record.columns() if c not in header]
    if missing:
        raise RunFileError(file, f"no column(s) {missing} in the header: {OLDER}")
    rows: list[R] = []
    for line, values in enumerate(lines, start=2):  # one row per line: no field holds a newline
        if len(values) != len(header):
            raise RunFileError(file, f"line {line} has {len(values)} of {len(header)} fields (truncated?)")
        try:
            rows.append(record.from_row(dict(zip(header, values, strict=True))))
        except ValueError as error:
            raise RunFileError(file, f"line {line}: {error}") from None
    return rows


def _read_json(path: Path, file: PurePosixPath, kind: type) -> dict | list:
    """The JSON object (`kind` dict) or array (`kind` list) in `path`."""
    try:
        value: Any = json.loads(_text(path, file))
    except json.JSONDecodeError as error:
        raise RunFileError(file, f"not valid JSON ({error})") from None
    if not isinstance(value, kind):
        raise RunFileError(file, f"expected a JSON {'object' if kind is dict else 'array'}")
    return cast("dict | list", value)  # mypy narrows by a variable class to object


def _config(fields: dict) -> Config:
    """config.json's Config; every field must be there (the value of one it lacks is not known)."""
    return Config.from_dict(fields)


FINAL_FIELDS = ("task", "policy", "seed", "returns", "lengths", "timeout")
"""What eval.json holds of `EvalResult` in every run (goals only where the task counts them,
env_kwargs only where there are any)."""


def _final(fields: dict) -> EvalResult:
    """eval.json's `EvalResult` (written by its `to_dict`)."""
    _require(fields, FINAL_FIELDS)
    if not fields["returns"] or len(fields["returns"]) != len(fields["lengths"]):
        raise ValueError("returns and lengths must be lists of one value per episode")
    return EvalResult(
        fields["task"],
        fields["policy"],
        int(fields["seed"]),
        [float(value) for value in fields["returns"]],
        [int(value) for value in fields["lengths"]],
        [int(value) for value in fields["goals"]] if "goals" in fields else None,
        fields["timeout"],
        dict(fields.get("env_kwargs", {})),
    )


def _summary(fields: dict) -> DemoSummary:
    """demonstrations.json's `DemoSummary`, every field of which it must hold."""
    _require(fields, DemoSummary.columns())
    return DemoSummary.from_row(fields)


def _updates(entries: list) -> list[DemoUpdate]:
    """dynamic_demos.json's `DemoUpdate`s, every field of which each entry must hold."""
    for entry in entries:
        _require(entry, DemoUpdate.columns())
    return [DemoUpdate.from_row(entry) for entry in entries]


def read_run(directory: Path, relative: PurePosixPath, shown: Path) -> FinishedRun:
    """The complete run in `directory` (`relative` to its suite); RunFileError names a bad file."""

    def read(name: str, kind: type, parse: Callable):
        value = _read_json(directory / name, relative / name, kind)
        try:
            return parse(value)
        except _Lacking as error:
            raise RunFileError(relative / name, f"no {error.args[0]}: {OLDER}") from None
        except (TypeError, ValueError) as error:
            raise RunFileError(relative / name, str(error)) from None

    for name in REQUIRED:
        if not (directory / name).is_file():
            raise RunFileError(relative / name, "missing (the run has eval.json, so it should be complete)")
    metrics = _read_csv(directory / "metrics.csv", relative / "metrics.csv", EpisodeRow)
    if not metrics:
        raise RunFileError(relative / "metrics.csv", "no episodes")
    config = read("config.json", dict, _config)
    demonstrations = None
    if config.uses_demos:
        if not (directory / "demonstrations.json").is_file():
            raise RunFileError(
                relative / "demonstrations.json", f"missing (the run learns from demonstrations): {OLDER}"
            )
        demonstrations = read("demonstrations.json", dict, _summary)
    updates = directory / "dynamic_demos.json"
    return FinishedRun(
        shown,
        config,
        metrics,
        _read_csv(directory / "evals.csv", relative / "evals.csv", EvalRow),
        read("eval.json", dict, _final),
        demonstrations,
        read("dynamic_demos.json", list, _updates) if updates.is_file() else [],
        read("provenance.json", dict, Provenance.of),
    )
