"""Suites as the lab reads them: each complete run parsed into a `FinishedRun`, and the suite as
one archive of exactly the files the report reads, so results can be re-derived elsewhere.

A source is a suite directory or such an archive (`export_archive`); `open_suite` gives either
as a directory, so every reader of the lab reads files from one place.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import io
import json
import lzma
import os
import tarfile
import tempfile
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

import numpy as np

from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.envs.episodes import EvalResult
from dqfd_bc_keras.errors import OLDER, ConfigError
from dqfd_bc_keras.files import atomic_path
from dqfd_bc_keras.runs.writers import COMPLETE
from dqfd_bc_keras.training.records import DemoSummary, DemoUpdate, EpisodeRow, EvalRow

SWEEP_LOG = "sweeps.jsonl"
"""One line per sweep in the suite directory: what ran, on how many workers, in how many seconds, from
which commits."""

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
ROWS: dict[str, type[EpisodeRow] | type[EvalRow]] = {"metrics.csv": EpisodeRow, "evals.csv": EvalRow}
"""The record each row of a run's CSV files parses into."""
BENCHMARK_FILES = ("efficiency.json", "sb3-dqn", "calibration.json", "bc-alone")
"""Files the report reads besides the runs: `experiments efficiency`'s table and SB3's
runs, `calibrate`'s measurements and BC alone's results (`imitation.py`)."""
ARCHIVE_SUFFIX = ".tar.xz"
"""What a run file that lacks a column or field of this version's format is taken for, and the way on."""


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


def _read_csv(path: Path, file: PurePosixPath) -> list[EpisodeRow] | list[EvalRow]:
    """The rows of `path` as its records (`ROWS`); a truncated or garbled file is refused."""
    text = _text(path, file)
    if text and not text.endswith("\n"):
        raise RunFileError(file, "ends in the middle of a line (truncated?)")
    reader = csv.reader(io.StringIO(text))
    try:
        header, *lines = list(reader) or [[]]
    except csv.Error as error:
        raise RunFileError(file, f"line {reader.line_num}: {error}") from None
    record = ROWS[path.name]
    missing = [c for c in record.columns() if c not in header]
    if missing:
        raise RunFileError(file, f"no column(s) {missing} in the header: {OLDER}")
    rows = []
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
        value = json.loads(_text(path, file))
    except json.JSONDecodeError as error:
        raise RunFileError(file, f"not valid JSON ({error})") from None
    if not isinstance(value, kind):
        raise RunFileError(file, f"expected a JSON {'object' if kind is dict else 'array'}")
    return value


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


def _read_run(directory: Path, relative: PurePosixPath, shown: Path) -> FinishedRun:
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
    metrics = _read_csv(directory / "metrics.csv", relative / "metrics.csv")
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
        _read_csv(directory / "evals.csv", relative / "evals.csv"),
        read("eval.json", dict, _final),
        demonstrations,
        read("dynamic_demos.json", list, _updates) if updates.is_file() else [],
        read("provenance.json", dict, Provenance.of),
    )


REPLICATIONS = "replications"
"""A suite directory's subdirectory of reruns at fresh seeds (`experiments replicate --out
SUITE/replications`): read apart from the suite's own runs, whose arms they would join (their
configs are the same), and exported with them."""


def _own(directory: Path, path: Path) -> bool:
    return path.relative_to(directory).parts[0] != REPLICATIONS


def _finishing(run_dir: Path) -> bool:
    """A run started here that has not written COMPLETE yet (its eval.json may be there, its last
    files not): a run unpacked from an archive has no checkpoints/, one finished here has COMPLETE."""
    return (run_dir / "checkpoints").is_dir() and not (run_dir / COMPLETE).is_file()


def _run_dirs(directory: Path) -> list[Path]:
    """Every complete run (a directory with eval.json, not still finishing) below `directory`, in
    path order, its REPLICATIONS left out. A sweep in progress can so be read or exported at any time."""
    return sorted(
        final.parent
        for final in directory.rglob("eval.json")
        if _own(directory, final) and not _finishing(final.parent)
    )


def _unfinished(directory: Path) -> list[Path]:
    """Run directories below `directory` that have started (config.json, checkpoints/) but not finished."""
    return sorted(
        config.parent
        for config in directory.rglob("config.json")
        if _own(directory, config)
        and (config.parent / "checkpoints").is_dir()
        and not ((config.parent / COMPLETE).is_file() and (config.parent / "eval.json").is_file())
    )


def _load(directory: Path, shown: Path, skipped: list[RunFileError] | None) -> list[FinishedRun]:
    runs = []
    if skipped is not None:  # the report names them; an export leaves them out as it always did
        skipped.extend(
            RunFileError(
                PurePosixPath(run_dir.relative_to(directory).as_posix()) / "eval.json",
                "missing: the run has not finished (still running, or cut off: run the suite again to resume it)",
            )
            for run_dir in _unfinished(directory)
        )
    for run_dir in _run_dirs(directory):
        relative = PurePosixPath(run_dir.relative_to(directory).as_posix())
        try:
            runs.append(_read_run(run_dir, relative, shown / relative))
        except RunFileError as error:
            if skipped is None:
                raise ConfigError(f"{shown / error.file}: {error.problem}") from None
            skipped.append(error)
    return runs


@contextlib.contextmanager
def open_suite(source: str | os.PathLike) -> Iterator[Path]:
    """`source` itself if it is a suite directory; an archive of one extracted into a temporary
    directory, removed on exit. Anything else is a ConfigError naming it."""
    source = Path(source)
    if source.is_dir():
        yield source
        return
    if not source.is_file():
        raise ConfigError(f"{source}: no such suite directory or archive")
    with tempfile.TemporaryDirectory(prefix="dqfd-suite-") as tmp:
        _extract(source, Path(tmp))
        yield Path(tmp)


def _extract(archive: Path, root: Path) -> None:
    """The archive's regular files into `root`; a member naming a place outside it is refused."""
    try:
        with tarfile.open(archive, "r:xz") as tar:
            for member in tar:
                name = PurePosixPath(member.name)
                if name.is_absolute() or ".." in name.parts:
                    raise ConfigError(f"{archive}: member {member.name!r} points outside the suite")
                if member.isfile():
                    target = root.joinpath(*name.parts)
                    target.parent.mkdir(parents=True, exist_ok=True)
                    target.write_bytes(tar.extractfile(member).read())
    except (tarfile.TarError, lzma.LZMAError, EOFError) as error:
        problem = f"not a suite directory or a readable {ARCHIVE_SUFFIX} archive ({error})"
        raise ConfigError(f"{archive}: {problem}") from None


def load_runs(source: str | os.PathLike, skipped: list[RunFileError] | None = None) -> list[FinishedRun]:
    """Every complete run of `source` (a suite directory, an archive of one, or a run directory),
    in path order. A run with a missing or unreadable file raises a ConfigError naming the file;
    given a `skipped` list, it is left out and its error appended there instead."""
    with open_suite(source) as directory:
        return _load(directory, Path(source), skipped)


def lab_files(directory: Path) -> list[str]:
    """The files of the suite in `directory` that the report reads, relative and sorted: the
    RUN_FILES of every complete run (its REPLICATIONS' too), every sweep log and the benchmark's files."""
    run_dirs = [*_run_dirs(directory), *_run_dirs(directory / REPLICATIONS)]
    files = {run_dir / name for run_dir in run_dirs for name in RUN_FILES if (run_dir / name).is_file()}
    files |= set(directory.rglob(SWEEP_LOG))
    for name in BENCHMARK_FILES:
        files |= {p for p in [directory / name, *(directory / name).rglob("*")] if p.is_file()}
    return sorted(p.relative_to(directory).as_posix() for p in files)


def export_archive(source: str | os.PathLike, path: str | os.PathLike) -> list[str]:
    """Write the `lab_files` of the suite `source` into one xz-compressed tar at `path`; return
    their names. Every run must be readable (a ConfigError names the first bad file).

    The bytes depend on the files' contents only: members sorted, no directories, mtime 0,
    owner 0 without names, mode 0644. Exporting the same data twice gives the same archive.
    """
    with open_suite(source) as directory:
        if not _load(directory, Path(source), None):
            raise ConfigError(f"{source}: no complete run (a directory with eval.json) to export")
        names = lab_files(directory)
        with atomic_path(path) as tmp, tarfile.open(tmp, "w:xz", format=tarfile.PAX_FORMAT) as tar:
            for name in names:
                data = (directory / name).read_bytes()
                info = tarfile.TarInfo(name)
                info.size, info.mtime, info.mode = len(data), 0, 0o644
                info.uid = info.gid = 0
                info.uname = info.gname = ""
                tar.addfile(info, io.BytesIO(data))
    return names
