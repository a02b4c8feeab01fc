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
import json
import os
import re
import sys
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from dqfd_bc_keras.errors import ConfigError, DirectoryInUseError, OutputExistsError, RunDirectoryError


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

    The temporary's name is unmistakably the program's (`TEMPORARY`) and ends in `path`'s name, so
    writers that check the suffix (Keras wants `.keras`, numpy appends `.npz` otherwise) work
    unchanged. On error the temporary file is removed and `path` is left as it was. `durable`:
    fsync the file before the rename and the directory after it.
    """
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(errno.EISDIR, "is a directory, not a file", str(path))
    if not overwrite and path.exists():
        raise OutputExistsError(f"{path} exists; pass --force to overwrite it")
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, name = _temporary(path, path.parent)
    os.close(fd)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(name, 0o666 & ~umask)  # mkstemp makes 0600; a result should be as readable as any file
    tmp = Path(name)
    try:
        with naming(path, tmp):
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
    fd, name = _temporary(path, folder)
    os.close(fd)
    os.unlink(name)


def _temporary(path: Path, folder: Path) -> tuple[int, str]:
    """A new empty file in `folder` named as the program's temporaries are (`TEMPORARY`), for
    `path`: (its descriptor, its name); an OSError names `path`."""
    with naming(path):
        return tempfile.mkstemp(prefix=f"{TEMPORARY_PREFIX}{os.getpid()}-", suffix=f"-{path.name}", dir=folder)


@contextlib.contextmanager
def naming(path: Path, tmp: Path | None = None) -> Iterator[None]:
    """An OSError writing `path` names `path`: the user's file, not the temporary one beside it (a
    read-only directory) nor none at all (a full disk in `write`, which names no file)."""
    try:
        yield
    except OSError as error:
        if not error.errno or tmp is not None and error.filename is not None and Path(error.filename) != tmp:
            raise  # not about this file
        raise OSError(error.errno, error.strerror, str(path)) from None


TEMPORARY_PREFIX = ".dqfd-tmp-"
TEMPORARY = re.compile(r"\.dqfd-tmp-\d+-[a-z0-9_]{8}-(.+)")
"""The name `atomic_path` gives its temporary file: `.dqfd-tmp-{pid}-{8 random characters}-{name}`.
Only a name of exactly this form is ever taken for a temporary (and deleted): until 2026-12-06 it
was `.{stem}.{8 characters}{suffix}`, which a user's `.thesis.20261206.tex` matched too."""


def temporary_of(name: str) -> str | None:
    """The file whose temporary `name` is (`TEMPORARY`), else None."""
    match = TEMPORARY.fullmatch(name)
    return None if match is None else match[1]


def remove_temporaries(directory: Path) -> list[Path]:
    """Delete the temporaries `atomic_path` left in `directory` and its subdirectories (a writer
    killed before its rename); returns them. Only regular files named `TEMPORARY` go: nothing else
    is touched, and no directory is deleted."""
    found = [
        path
        for path in Path(directory).rglob(f"{TEMPORARY_PREFIX}*")
        if TEMPORARY.fullmatch(path.name) and path.is_file() and not path.is_symlink()
    ]
    for path in found:
        path.unlink()
    return found


def write_text(path: str | os.PathLike, text: str, durable: bool = False) -> None:
    """Atomically write a text file."""
    with atomic_path(path, durable=durable) as tmp:
        tmp.write_text(text)


class DirectoryLock:
    """One writer per directory: an exclusive `flock` on DIR/.lock, which holds the writer's PID.

    The kernel drops the lock when its process dies, so a lock file that still names a PID but
    can be locked was left by a writer that died: it is taken over with a warning. Only the
    program's own lock file is ever written: one this lock makes (O_EXCL), or one holding what a
    lock writes (a PID, or nothing once released); any other `.lock` is refused, untouched.
    `check`, called holding the lock before anything is written, may refuse the directory (its
    result is `checked`): a refusal writes nothing, and a lock file or directory this lock made
    for it is removed. On release the file is emptied, never deleted while other files are beside
    it; one this lock made and left alone goes, with the directories made for it.
    """

    NAME = ".lock"
    OWN = re.compile(r"(\d+\n)?")
    """What the program's lock file holds: its writer's PID while held, nothing once released."""

    def __init__(self, directory: Path, check: Callable[[], object] | None = None) -> None:
        self.directory, self.check = Path(directory), check
        self.checked: object = None
        self.fd: int | None = None
        self.created = self.written = False
        """Whether this lock made its file, and has written it (a refusal writes nothing)."""
        self.made: list[Path] = []
        """The directories this lock made, deepest first."""

    def __enter__(self) -> DirectoryLock:
        if self.directory.exists() and not self.directory.is_dir():
            raise RunDirectoryError(f"{self.directory} is a file, not a run directory")
        try:
            self._acquire()
        except BaseException:
            self._release()
            raise
        return self

    def _acquire(self) -> None:
        path = self.directory / self.NAME
        while self.fd is None:  # again if the file was deleted by the writer that held it
            self.made += [p for p in (self.directory, *self.directory.parents) if not p.exists()]
            self.directory.mkdir(parents=True, exist_ok=True)
            fd = self._open(path)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = os.pread(fd, 64, 0).decode(errors="replace").strip()
                os.close(fd)
                raise DirectoryInUseError(
                    f"{self.directory} is in use by process {holder or '(unknown)'}; wait for it to finish or stop it"
                ) from None
            if _same_file(fd, path):
                self.fd = fd
            else:
                os.close(fd)
        held = os.pread(self.fd, 64, 0).decode(errors="replace")
        if self.check is not None:
            self.checked = self.check()
        if os.fstat(self.fd).st_size > 64 or not self.OWN.fullmatch(held):
            raise RunDirectoryError(
                f"{path} is not this program's lock file (it holds other text), and a file the program did "
                "not write is never written; move it away, or choose another directory"
            )
        if held:  # a clean release leaves it empty
            print(
                f"warning: {self.directory}: taking over the lock left by process {held.strip()}, "
                "which is no longer running",
                file=sys.stderr,
            )
        self.written = True
        with naming(path):  # a full disk: the lock file named
            os.ftruncate(self.fd, 0)
            os.pwrite(self.fd, f"{os.getpid()}\n".encode(), 0)

    def _open(self, path: Path) -> int:
        """The lock file, made (O_EXCL: `created`) or opened as it is: never created over, truncated,
        nor followed (a symbolic link, a directory: refused)."""
        flags = os.O_RDWR | os.O_NOFOLLOW | os.O_CLOEXEC
        try:
            fd = os.open(path, flags | os.O_CREAT | os.O_EXCL, 0o644)
            self.created = True
            return fd
        except FileExistsError:
            self.created = False
            if path.is_symlink() or not path.is_file():
                raise RunDirectoryError(
                    f"{path} is not this program's lock file (not a regular file); move it away, or choose "
                    "another directory"
                ) from None
            return os.open(path, flags)

    def __exit__(self, *exc: object) -> None:
        self._release()

    def _release(self) -> None:
        """Unlock, having emptied the lock file if it was written. A file this lock made is
        deleted when it was never written (a refusal) or is alone in its directory (before the
        unlock: whoever opened it finds it gone, `_same_file`), and with it the directories made
        for it, if empty."""
        if self.fd is not None:
            if self.created and (not self.written or os.listdir(self.directory) == [self.NAME]):
                (self.directory / self.NAME).unlink()
            elif self.written:
                os.ftruncate(self.fd, 0)
            os.close(self.fd)  # closing releases the flock
            self.fd = None
        for directory in self.made:
            with contextlib.suppress(OSError):  # not empty: something else was put there
                directory.rmdir()
        self.made = []


def _same_file(fd: int, path: Path) -> bool:
    """Whether `path` is still the file `fd` opened (a releasing writer may have deleted it)."""
    try:
        return os.path.samestat(os.fstat(fd), os.stat(path, follow_symlinks=False))
    except FileNotFoundError:
        return False


def read_json(path: str | os.PathLike, what: str) -> Any:
    """The JSON value a user's file holds; a file missing, unreadable or not JSON is a one-line
    ConfigError naming it as `what` (`--space FILE.json`, `params file`)."""
    try:
        return json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such {what}") from None
    except (OSError, UnicodeDecodeError, ValueError) as error:
        raise ConfigError(f"{path}: not a JSON {what} ({str(error).splitlines()[0]})") from None
