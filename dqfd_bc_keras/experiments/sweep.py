"""Running a suite: every (arm, seed) a run in a worker process of a local pool, or a Ray task.

A run is complete when its `complete.json` exists (written last): running a suite again skips
complete runs and resumes one that was cut off from its last checkpoint (if its config is still
the arm's), so a sweep killed halfway picks up where it stopped. Every sweep gets a line in
`OUT/sweeps.jsonl`.

Ctrl-C or SIGTERM stops a local sweep within seconds: no run is started after it, and each
running one gets SIGTERM, which stops it where `train.py` would stop (its last checkpoint kept);
one still running `STOP_GRACE` seconds later is killed, which keeps the same checkpoint.
A run whose directory another live runner holds is left to that runner, not counted as failed;
one that another runner completed after this sweep listed it is skipped (`claim`).
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import shutil
import signal
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from multiprocessing import get_context
from multiprocessing.connection import wait as wait_for
from pathlib import Path

from dqfd_bc_keras import runtime
from dqfd_bc_keras.commands.cli import Terminated
from dqfd_bc_keras.errors import BrokenRunError, ConfigError, DirectoryInUseError, RunDirectoryError
from dqfd_bc_keras.experiments.data import SWEEP_LOG
from dqfd_bc_keras.experiments.names import BACKENDS, RUNS_PER_WORKER
from dqfd_bc_keras.experiments.suites import Arm, suite_arms
from dqfd_bc_keras.files import DirectoryLock, write_text
from dqfd_bc_keras.runs.provenance import provenance


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


STOP_GRACE = 20.0
"""Seconds the stopped runs get, together, to reach their safe point (the end of the graph call
under way: one episode at most) before those still running are killed. A kill costs nothing a
stop keeps: a stop writes no checkpoint either, every file of a run is written atomically, and
the next runner takes over the dead one's lock."""


@dataclass
class _Worker:
    """A worker process, the pipes that give it jobs and bring back outcomes, and its runs so far."""

    process: object
    jobs: object
    outcomes: object
    job: Job | None = None
    runs: int = 0

    @classmethod
    def start(cls, context) -> _Worker:
        take, give = context.Pipe(duplex=False)
        receive, send = context.Pipe(duplex=False)
        process = context.Process(target=_serve, args=(take, send), daemon=True)
        process.start()
        take.close()
        send.close()
        return cls(process, give, receive)

    def give(self, job: Job) -> None:
        self.job = job
        self.jobs.send(job)

    def retire(self) -> None:
        """Tell an idle worker to exit, and wait for it."""
        with contextlib.suppress(OSError):  # it is gone already
            self.jobs.send(None)
        self.end_by(time.monotonic() + STOP_GRACE)

    def end_by(self, deadline: float) -> bool:
        """Wait for the process until `deadline` (`time.monotonic()`), then kill it; True if it
        had to be killed."""
        self.process.join(max(0.0, deadline - time.monotonic()))
        if not self.process.is_alive():
            return False
        self.process.kill()
        self.process.join()
        return True


def _local(jobs: Sequence[Job], workers: int, runs_per_worker: int = RUNS_PER_WORKER) -> Iterator[Outcome]:
    """Up to `workers` runs at once, in worker processes that take up to `runs_per_worker` runs
    each, one after the other (each run starts from a cleared Keras session and its own seeds, so
    its results are those of a fresh process). If the sweep is stopped (Ctrl-C, SIGTERM, or its
    consumer closing this generator), no run is started after it and each running one is sent
    SIGTERM and awaited."""
    context = get_context("spawn")
    queue, idle, busy = list(jobs), [], {}
    try:
        while queue or busy:
            while queue and len(busy) < workers:
                worker = idle.pop() if idle else _Worker.start(context)
                worker.give(queue.pop(0))
                busy[worker.process.sentinel] = worker
            ready = set(wait_for([*busy, *(w.outcomes for w in busy.values())]))
            for sentinel, worker in list(busy.items()):
                if sentinel not in ready and worker.outcomes not in ready:
                    continue
                del busy[sentinel]
                try:
                    outcome = worker.outcomes.recv() if worker.outcomes.poll() else None
                except EOFError:  # its end of the pipe closed without an outcome
                    outcome = None
                if outcome is None:  # it died during the run
                    worker.process.join()
                    yield Outcome(
                        worker.job, 0, 0, float("nan"), 0.0, f"its process died (exit code {worker.process.exitcode})"
                    )
                    continue
                worker.runs += 1
                if worker.runs >= runs_per_worker or not queue:
                    worker.retire()
                else:
                    idle.append(worker)
                yield outcome
    except BaseException:
        _stop_all(list(busy.values()))
        raise
    finally:
        for worker in idle:
            worker.retire()


def _stop_all(workers: list[_Worker]) -> None:
    """SIGTERM each running worker (its run stops at its next safe point), wait for them all
    against one deadline, `STOP_GRACE` from now, and kill those still running then."""
    for worker in workers:
        worker.process.terminate()
    deadline = time.monotonic() + STOP_GRACE
    for worker in workers:
        if worker.end_by(deadline):
            print(
                f"warning: {worker.job.directory}: the run had not stopped {STOP_GRACE:g} s after SIGTERM; "
                "killed (its last checkpoint is kept, and the next sweep resumes from it)",
                file=sys.stderr,
            )


def _serve(jobs, outcomes) -> None:
    """A worker: run the jobs it is given until it is given None. Ctrl-C is the sweep's to relay
    (as SIGTERM), not the run's. It leaves through `os._exit`: what a run keeps is on disk
    already, and skipping the interpreter's teardown spares a stopping worker the seconds (and
    the hangs TensorFlow's teardown is known for) that it would add to the sweep's stop. Its
    TensorFlow runs as a command's does, on one core (`DQFD_TF_THREADS` or 1: one run per core)."""
    runtime.configure()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _stop)
    try:
        while (job := jobs.recv()) is not None:
            outcomes.send(run_job(job))
    except (Terminated, EOFError, BrokenPipeError):
        pass  # stopped (nothing to report, the run resumes next time), or the sweep is gone
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


def _stop(signum: int, frame: object) -> None:
    raise Terminated


def _ray(jobs: Sequence[Job], workers: int, address: str | None, runs_per_worker: int) -> Iterator[Outcome]:
    """Each run a Ray task on one CPU, a worker taking up to `runs_per_worker` of them (Ray's
    `max_calls`); joins `address` (a running cluster) or starts a local Ray."""
    try:
        import ray
    except ImportError:
        raise ConfigError("the ray backend needs Ray: pip install -r requirements-ray.txt") from None
    started_here = not ray.is_initialized()
    if started_here:
        ray.init(
            address=address,
            num_cpus=None if address else workers,
            include_dashboard=False,
            log_to_driver=False,
            runtime_env={"env_vars": {"PYTHONPATH": str(Path(__file__).parents[2]), **runtime.environment()}},
        )
    try:
        task = ray.remote(num_cpus=1, max_calls=runs_per_worker)(run_job)
        pending = [task.remote(job) for job in jobs]
        while pending:
            finished, pending = ray.wait(pending, num_returns=1)
            yield ray.get(finished[0])
    finally:
        if started_here:
            ray.shutdown()


def sweep_jobs(arms: Sequence[Arm], seeds: int | None, out: Path, restart_broken: bool = False) -> list[Job]:
    """Every (arm, seed) of a sweep, seed-major: a sweep cut off partway leaves its arms with
    seed counts that differ by at most one."""
    last = seeds or max(arm.seeds for arm in arms)
    return [Job(arm, seed, out, restart_broken) for seed in range(last) for arm in arms if seed < (seeds or arm.seeds)]


def run_suite(
    suite: str | Sequence[Arm],
    seeds: int | None,
    out: str | Path,
    workers: int = 2,
    backend: str = "local",
    address: str | None = None,
    progress: Callable[[str], None] = print,
    name: str = "arms",
    restart_broken: bool = False,
    runs_per_worker: int = RUNS_PER_WORKER,
) -> list[Outcome]:
    """Run every incomplete (arm, seed) of `suite` (a name in SUITES, or arms called `name` in the
    progress lines and the sweep log), seeds 0 … `seeds` − 1, or each arm's own number when
    `seeds` is None; one progress line per run. A run whose checkpoint cannot be resumed fails
    (reported, the sweep goes on) unless `restart_broken`, which starts it over."""
    name, arms = (suite, suite_arms(suite)) if isinstance(suite, str) else (name, list(suite))
    jobs = sweep_jobs(arms, seeds, Path(out), restart_broken)
    return run_jobs(
        jobs,
        Path(out),
        name,
        seeds or max(arm.seeds for arm in arms),
        workers,
        backend,
        address,
        progress,
        runs_per_worker,
    )


def run_jobs(
    jobs: Sequence[Job],
    out: Path,
    name: str,
    seeds: int | str,
    workers: int = 2,
    backend: str = "local",
    address: str | None = None,
    progress: Callable[[str], None] = print,
    runs_per_worker: int = RUNS_PER_WORKER,
    finished: Callable[[Outcome], None] | None = None,
) -> list[Outcome]:
    """Run the incomplete ones of `jobs`, logged in `out`'s sweep log as `name` with `seeds`; a
    worker process takes up to `runs_per_worker` runs in turn (1: a fresh process per run).
    `finished` is called with each run's outcome as it comes in (a study exports its archive there,
    so that a lost machine loses only the runs in progress)."""
    if backend not in BACKENDS:
        raise ConfigError(f"unknown backend {backend!r}; expected one of {BACKENDS}")
    todo = [job for job in jobs if not job.complete]
    progress(
        f"{name}: {len(jobs)} runs, {len(jobs) - len(todo)} already complete, {len(todo)} to run "
        f"on {workers} {backend} worker(s)"
    )
    outcomes, started, interrupted = [], time.perf_counter(), True
    stream = (
        _local(todo, workers, runs_per_worker) if backend == "local" else _ray(todo, workers, address, runs_per_worker)
    )
    try:
        for outcome in stream:
            outcomes.append(outcome)
            job = outcome.job
            status = (
                f"failed: {outcome.error}"
                if outcome.error
                else f"left to the runner that holds it ({outcome.busy})"
                if outcome.busy
                else "skipped: another runner completed it"
                if outcome.done_elsewhere
                else f"{outcome.episodes} episodes, {outcome.env_steps} steps, eval {outcome.mean_return:.1f}"
            )
            progress(
                f"[{len(outcomes)}/{len(todo)}] {job.arm.name} seed{job.seed}: {status} "
                f"({outcome.seconds:.0f} s; {time.perf_counter() - started:.0f} s elapsed)"
            )
            if finished is not None:
                finished(outcome)
        interrupted = False
    except KeyboardInterrupt:
        progress(
            f"{name}: interrupted after {len(outcomes)} of {len(todo)} runs; no run was started after it, the "
            f"running ones stopped at their last checkpoint ({time.perf_counter() - started:.0f} s elapsed): "
            "run the same command again to go on"
        )
        raise
    finally:
        if outcomes or interrupted:  # every sweep that ran something, and one cut off (as such)
            log = out / SWEEP_LOG
            entry = {
                "suite": name,
                "seeds": seeds,
                "runs": len(outcomes),
                "workers": workers,
                "backend": backend,
                "runs_per_worker": runs_per_worker,
                "seconds": round(time.perf_counter() - started, 1),
                "ended": time.strftime("%Y-%m-%d %H:%M:%S"),
                **({"interrupted": True} if interrupted else {}),
                **provenance(),
            }
            out.mkdir(parents=True, exist_ok=True)
            with locked(out):  # two runners ending together: each line kept, the file rewritten atomically
                write_text(log, (log.read_text() if log.is_file() else "") + json.dumps(entry) + "\n")
    busy = [o for o in outcomes if o.busy]
    if busy:
        progress(
            f"{name}: {len(busy)} run(s) left to another runner that holds them; run the command again once "
            "it is done to check they are complete"
        )
    failed = [o for o in outcomes if o.error]
    if failed:
        raise ConfigError(
            f"{len(failed)} of {len(todo)} runs failed; first: {failed[0].job.directory}: {failed[0].error}"
        )
    return outcomes
