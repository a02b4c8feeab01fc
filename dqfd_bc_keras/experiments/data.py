"""Suites as the lab reads them: each complete run parsed into a `FinishedRun` (run_files.py), and
the suite as one archive of exactly the files the report reads, so results can be re-derived elsewhere.

A source is a suite directory or such an archive (`export_archive`); `open_suite` gives either
as a directory, so every reader of the lab reads files from one place.
"""

from __future__ import annotations

import contextlib
import io
import lzma
import os
import tarfile
import tempfile
from collections.abc import Iterator
from pathlib import Path, PurePosixPath

from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.experiments.run_files import RUN_FILES, FinishedRun, RunFileError, read_run
from dqfd_bc_keras.files import atomic_path
from dqfd_bc_keras.runs.writers import COMPLETE

SWEEP_LOG = "sweeps.jsonl"
"""One line per sweep in the suite directory: what ran, on how many workers, in how many seconds, from
which commits."""

BENCHMARK_FILES = ("efficiency.json", "sb3-dqn", "calibration.json", "bc-alone")
"""Files the report reads besides the runs: `experiments efficiency`'s table and SB3's
runs, `calibrate`'s measurements and BC alone's results (`imitation.py`)."""
ARCHIVE_SUFFIX = ".tar.xz"
"""The archive `export_archive` writes and `open_suite` reads: an xz-compressed tar."""


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
            runs.append(read_run(run_dir, relative, shown / relative))
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
                    data = tar.extractfile(member)
                    assert data is not None  # a regular file's contents
                    target = root.joinpath(*name.parts)
                    target.parent.mkdir(parents=True, exist_ok=True)
                    target.write_bytes(data.read())
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
    """Write the `lab_files` of the suite `source` into one xz-compressed tar at `path` (`write_archive`);
    return their names. Every run must be readable (a ConfigError names the first bad file)."""
    with open_suite(source) as directory:
        if not _load(directory, Path(source), None):
            raise ConfigError(f"{source}: no complete run (a directory with eval.json) to export")
        names = lab_files(directory)
        write_archive({name: directory / name for name in names}, path)
    return names


def write_archive(files: dict[str, Path], path: str | os.PathLike) -> None:
    """The `files` (member name: the file holding its bytes) as one xz-compressed tar at `path`, atomically.

    The bytes depend on the files' contents only: members sorted, no directories, mtime 0,
    owner 0 without names, mode 0644. Writing the same data twice gives the same archive.
    """
    with atomic_path(path) as tmp, tarfile.open(tmp, "w:xz", format=tarfile.PAX_FORMAT) as tar:
        for name in sorted(files):
            data = files[name].read_bytes()
            info = tarfile.TarInfo(name)
            info.size, info.mtime, info.mode = len(data), 0, 0o644
            info.uid = info.gid = 0
            info.uname = info.gname = ""
            tar.addfile(info, io.BytesIO(data))
