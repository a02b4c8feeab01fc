"""The job list of a sweep: every (arm, seed) a `Job`, what one run in a worker does (`run_job`)
and the `Outcome` it reports back.

A run is complete when its `complete.json` exists (written last): running a suite again skips
complete runs and resumes one that was cut off from its last checkpoint (if its config is still
the arm's), so a sweep killed halfway picks up where it stopped. A run whose directory another
live runner holds is left to that runner, not counted as failed; one that another runner completed
after the sweep listed it is skipped (`claim`).
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import shutil
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from dqfd_bc_keras.errors import BrokenRunError, DirectoryInUseError, RunDirectoryError
from dqfd_bc_keras.experiments.arm_config import Arm
from dqfd_bc_keras.files import DirectoryLock


@dataclass(frozen=True)
class Job:
    arm: Arm
    seed: int
    out: Path
    restart_broken: bool = False
    """Start a run whose checkpoint cannot be resumed over, instead of reporting it."""

    @property
    def directory(self) -> Path:
        return self.out / self.arm.name / f"seed{self.seed}"

    @property
    def complete(self) -> bool:
        """Finished here (complete.json), or a finished run unpacked from an archive: its eval.json
        without checkpoints/ (`export` keeps none, and a run started here has one until it is
        done). Neither is run again, so resuming a sweep in an unpacked archive trains only what
        it lacks and never replaces an archived run."""
        from dqfd_bc_keras.runs.directory import COMPLETE  # TensorFlow: a worker loads it after runtime.configure()

        d = self.directory
        return (d / COMPLETE).is_file() or ((d / "eval.json").is_file() and not (d / "checkpoints").exists())


@dataclass
class Outcome:
    """What one finished run reports back to the sweep."""

    job: Job
    episodes: int
    env_steps: int
    mean_return: float
    seconds: float
    error: str = ""
    busy: str = ""
    """Why the run was left alone: another live runner holds its directory."""
    done_elsewhere: bool = False
    """Another runner completed the run after this sweep listed it: it was not run here."""
    pid: int = 0
    """The worker process that ran it."""


def run_job(job: Job) -> Outcome:
    """One run (in a worker process): train, resuming a run cut off before, and summarise it. A run
    sets its own seeds when it is built, so it gives what it gives in a fresh process whatever ran
    before it in the worker (tested); the Keras session is cleared first so that the earlier runs'
    graphs and names are let go."""
    import keras

    from dqfd_bc_keras.runs.directory import train
    from dqfd_bc_keras.runs.resume import differences, saved_config

    keras.backend.clear_session()

    started, pid = time.perf_counter(), os.getpid()
    config = job.arm.config(job.seed)
    try:
        with claim(job.directory):
            if job.complete:
                return Outcome(job, 0, 0, float("nan"), time.perf_counter() - started, pid=pid, done_elsewhere=True)
            resume = (job.directory / "checkpoints" / "latest.json").is_file()
            try:
                if resume:  # the run on disk must be this arm's run
                    changed = differences(config.to_dict(), saved_config(job.directory).to_dict())
                    if changed:
                        raise BrokenRunError(
                            f"{job.directory / 'config.json'}: not the arm's config ({'; '.join(changed)})"
                        )
                result = train(config, job.directory, resume=resume, force=not resume, quiet=True)
            except BrokenRunError as error:
                if not job.restart_broken:
                    raise BrokenRunError(f"{error} (or rerun the sweep with --restart-broken)") from None
                result = train(config, job.directory, force=True, quiet=True)
    except DirectoryInUseError as error:  # another runner's: it will finish it
        return Outcome(job, 0, 0, float("nan"), time.perf_counter() - started, busy=str(error), pid=pid)
    except Exception as error:
        return Outcome(
            job, 0, 0, float("nan"), time.perf_counter() - started, f"{type(error).__name__}: {error}", pid=pid
        )
    return Outcome(
        job, result.episodes, result.env_steps, result.evaluation.mean_return, time.perf_counter() - started, pid=pid
    )


@contextlib.contextmanager
def claim(directory: Path) -> Iterator[None]:
    """Hold run `directory` for a runner from before it decides whether the run is to be done until
    the run ends: an exclusive `flock` on the directory itself (`train` takes the `.lock` inside it
    on its own). A sweep lists the runs to do before it starts them, so another runner on the same
    `--out` may finish one in between: holding the claim, `Job.complete` tells, and the run is
    skipped instead of resumed and finished a second time. DirectoryInUseError if another runner
    holds it. A directory made here for a run that left nothing in it (a new run that failed before
    its first checkpoint) is removed, as `train` removes one it made."""
    if directory.exists() and not directory.is_dir():
        raise RunDirectoryError(f"{directory} is a file, not a run directory")
    made = not directory.exists()
    directory.mkdir(parents=True, exist_ok=True)
    with locked(directory, wait=False):
        try:
            yield
        finally:
            if made and all(path.name == DirectoryLock.NAME for path in directory.iterdir()):
                shutil.rmtree(directory)


@contextlib.contextmanager
def locked(directory: Path, wait: bool = True) -> Iterator[None]:
    """Hold an exclusive `flock` on `directory` itself (no file of its own is needed, and the kernel
    drops it if the holder dies); without `wait`, DirectoryInUseError if another process holds it,
    naming the PID its run's `.lock` holds."""
    fd = os.open(directory, os.O_RDONLY)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | (0 if wait else fcntl.LOCK_NB))
        except BlockingIOError:
            lock = directory / DirectoryLock.NAME
            holder = (lock.read_text().strip() if lock.is_file() else "") or "(unknown)"
            raise DirectoryInUseError(
                f"{directory} is in use by process {holder}; wait for it to finish or stop it"
            ) from None
        yield
    finally:
        os.close(fd)


def sweep_jobs(arms: Sequence[Arm], seeds: int | None, out: Path, restart_broken: bool = False) -> list[Job]:
    """Every (arm, seed) of a sweep, seed-major: a sweep cut off partway leaves its arms with
    seed counts that differ by at most one."""
    last = seeds or max(arm.seeds for arm in arms)
    return [Job(arm, seed, out, restart_broken) for seed in range(last) for arm in arms if seed < (seeds or arm.seeds)]
