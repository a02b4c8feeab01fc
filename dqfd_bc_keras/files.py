"""Files that survive kills, full disks and a second writer.

Everything the package writes (demos, models, checkpoints, metrics, reports) goes through
`atomic_path`: write to a temporary name in the same directory, then `os.replace`, which is
atomic on POSIX filesystems, so a reader (or a killed run) never sees half a file. What must
also survive a power cut (checkpoints and the pointer to them) is written `durable`: fsynced
before the switch. `DirectoryLock` keeps a run directory to one writer.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import re
import shutil
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

from dqfd_bc_keras.errors import DirectoryInUseError, OutputExistsError, RunDirectoryError


def _sync(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def sync_tree(root: Path) -> None:
    """fsync every file and directory under `root`, then `root` itself."""
    for directory, _, names in os.walk(root, topdown=False):
        for name in names:
            _sync(Path(directory) / name)
        _sync(Path(directory))


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, *, overwrite: bool = True, durable: bool = False) -> Iterator[Path]:
    """Yield a temporary path beside `path`; on success it is renamed to `path`.

    The temporary name keeps `path`'s suffix, so writers that check it (Keras wants
    `.keras`, numpy appends `.npz` otherwise) work unchanged. On error the temporary file is
    removed and `path` is left as it was. `durable`: fsync the file before the rename and the
    directory after it.
    """
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(errno.EISDIR, "is a directory, not a file", str(path))
    if not overwrite and path.exists():
        raise OutputExistsError(f"{path} exists; pass --force to overwrite it")
    path.parent.mkdir(parents=True, exist_ok=True)
    with _naming(path, None):
        fd, name = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(name, 0o666 & ~umask)  # mkstemp makes 0600; a result should be as readable as any file
    tmp = Path(name)
    try:
        with _naming(path, tmp):
            yield tmp
            if durable:
                _sync(tmp)
            os.replace(tmp, path)
            if durable:
                _sync(path.parent)
    finally:
        tmp.unlink(missing_ok=True)


def check_writable(path: str | os.PathLike) -> None:
    """An `OSError` naming `path`, before work that would be lost, if `atomic_path` could not write
    it: a directory in its place, a file where a folder of its path belongs, a folder without write
    permission or on a read-only filesystem. Nothing it tries stays behind."""
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(errno.EISDIR, "is a directory, not a file", str(path))
    folder = next(p for p in (path.parent, *path.parent.parents) if p.exists())  # atomic_path makes the rest
    if not folder.is_dir():
        raise NotADirectoryError(errno.ENOTDIR, f"{folder} is a file, not a folder", str(path))
    with _naming(path, None):
        fd, name = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=folder)
    os.close(fd)
    os.unlink(name)


@contextlib.contextmanager
def _naming(path: Path, tmp: Path | None) -> Iterator[None]:
    """An OSError writing `path` names `path`: the user's file, not the temporary one beside it (a
    read-only directory) nor none at all (a full disk in `write`, which names no file)."""
    try:
        yield
    except OSError as error:
        if not error.errno or tmp is not None and error.filename is not None and Path(error.filename) != tmp:
            raise  # not about this file
        raise OSError(error.errno, error.strerror, str(path)) from None


TEMPORARY = re.compile(r"\.(.+)\.[a-z0-9_]{8}(\.[^.]+)?")
"""The name `atomic_path` gives its temporary file: `.{stem}.{8 random characters}{suffix}`."""


def temporary_of(name: str) -> str | None:
    """The file whose temporary `name` is (`TEMPORARY`), else None."""
    match = TEMPORARY.fullmatch(name)
    return None if match is None else f"{match[1]}{match[2] or ''}"


def remove_temporaries(directory: Path) -> list[Path]:
    """Delete the temporaries `atomic_path` left in `directory` and its subdirectories (a writer
    killed before its rename); returns them."""
    found = [path for path in Path(directory).rglob(".*") if TEMPORARY.fullmatch(path.name)]
    for path in found:
        shutil.rmtree(path) if path.is_dir() else path.unlink()
    return found


def write_text(path: str | os.PathLike, text: str, durable: bool = False) -> None:
    """Atomically write a text file."""
    with atomic_path(path, durable=durable) as tmp:
        tmp.write_text(text)


class DirectoryLock:
    """One writer per directory: an exclusive `flock` on DIR/.lock, which holds the writer's PID.

    The kernel drops the lock when its process dies, so a lock file that still names a PID but
    can be locked was left by a writer that died: it is taken over with a warning. The file is
    emptied on release, never deleted (deleting it would let two writers lock two different
    files of the same name).
    """

    NAME = ".lock"

    def __init__(self, directory: Path) -> None:
        self.directory = directory
        self.fd: int | None = None

    def __enter__(self) -> DirectoryLock:
        if self.directory.exists() and not self.directory.is_dir():
            raise RunDirectoryError(f"{self.directory} is a file, not a run directory")
        self.directory.mkdir(parents=True, exist_ok=True)
        fd = os.open(self.directory / self.NAME, os.O_RDWR | os.O_CREAT, 0o644)
        holder = os.pread(fd, 64, 0).decode(errors="replace").strip()
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise DirectoryInUseError(
                f"{self.directory} is in use by process {holder or '(unknown)'}; wait for it to finish or stop it"
            ) from None
        stale = os.pread(fd, 64, 0).decode(errors="replace").strip()  # a clean release leaves it empty
        if stale:
            print(
                f"warning: {self.directory}: taking over the lock left by process {stale}, which is no longer running",
                file=sys.stderr,
            )
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        self.fd = fd
        return self

    def __exit__(self, *exc: object) -> None:
        if self.fd is not None:
            os.ftruncate(self.fd, 0)
            os.close(self.fd)  # closing releases the flock
            self.fd = None
