"""Running a suite: the incomplete runs of its job list (jobs.py), each in a worker process of a
local pool or a Ray task. Every sweep gets a line in `OUT/sweeps.jsonl`.

Ctrl-C or SIGTERM stops a local sweep within seconds: no run is started after it, and each
running one gets SIGTERM, which stops it where `train.py` would stop (its last checkpoint kept);
one still running `STOP_GRACE` seconds later is killed, which keeps the same checkpoint.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from multiprocessing import get_context
from multiprocessing.connection import Connection
from multiprocessing.connection import wait as wait_for
from multiprocessing.context import SpawnContext
from multiprocessing.process import BaseProcess
from pathlib import Path
from typing import Any

from dqfd_bc_keras import runtime
from dqfd_bc_keras.commands.cli import Terminated, raise_terminated
from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.experiments.arm_config import Arm
from dqfd_bc_keras.experiments.data import SWEEP_LOG
from dqfd_bc_keras.experiments.jobs import Job, Outcome, locked, run_job, sweep_jobs
from dqfd_bc_keras.experiments.names import BACKENDS, RUNS_PER_WORKER
from dqfd_bc_keras.experiments.suites import suite_arms
from dqfd_bc_keras.files import write_text
from dqfd_bc_keras.runs.provenance import provenance

STOP_GRACE = 20.0
"""Seconds the stopped runs get, together, to reach their safe point (the end of the graph call
under way: one episode at most) before those still running are killed. A kill costs nothing a
stop keeps: a stop writes no checkpoint either, every file of a run is written atomically, and
the next runner takes over the dead one's lock."""


@dataclass
class _Worker:
    """A worker process, the pipes that give it jobs and bring back outcomes, and its runs so far."""

    process: BaseProcess
    jobs: Connection
    outcomes: Connection
    job: Job | None = None
    runs: int = 0

    @classmethod
    def start(cls, context: SpawnContext) -> _Worker:
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
        return end_by(self.process, deadline)


def end_by(process: BaseProcess, deadline: float) -> bool:
    """Wait for `process` until `deadline` (`time.monotonic()`), then kill it; True if it had to be killed."""
    process.join(max(0.0, deadline - time.monotonic()))
    if not process.is_alive():
        return False
    process.kill()
    process.join()
    return True


def stop_processes(processes: Sequence[BaseProcess]) -> list[bool]:
    """SIGTERM each of `processes` (a run stops at its next safe point), wait for them all against
    one deadline, `STOP_GRACE` from now, and kill those still running then; which were killed."""
    for process in processes:
        process.terminate()
    deadline = time.monotonic() + STOP_GRACE
    return [end_by(process, deadline) for process in processes]


def as_worker() -> None:
    """Set up a worker process: its TensorFlow as a command's (`runtime.configure`: one core, one
    run per core); Ctrl-C is the parent's to relay, as SIGTERM, which stops the run as Ctrl-C would."""
    runtime.configure()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, raise_terminated)


def _local(jobs: Sequence[Job], workers: int, runs_per_worker: int = RUNS_PER_WORKER) -> Iterator[Outcome]:
    """Up to `workers` runs at once, in worker processes that take up to `runs_per_worker` runs
    each, one after the other (each run starts from a cleared Keras session and its own seeds, so
    its results are those of a fresh process). If the sweep is stopped (Ctrl-C, SIGTERM, or its
    consumer closing this generator), no run is started after it and each running one is sent
    SIGTERM and awaited."""
    context = get_context("spawn")
    queue, idle, busy = list(jobs), list[_Worker](), dict[int, _Worker]()
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
                    assert worker.job is not None  # a busy worker's
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
    for worker, killed in zip(workers, stop_processes([w.process for w in workers]), strict=True):
        if killed:
            assert worker.job is not None  # a running worker's
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
    as_worker()
    try:
        while (job := jobs.recv()) is not None:
            outcomes.send(run_job(job))
    except (Terminated, EOFError, BrokenPipeError):
        pass  # stopped (nothing to report, the run resumes next time), or the sweep is gone
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


def _ray(jobs: Sequence[Job], workers: int, address: str | None, runs_per_worker: int) -> Iterator[Outcome]:
    """Each run a Ray task on one CPU, a worker taking up to `runs_per_worker` of them (Ray's
    `max_calls`); joins `address` (a running cluster) or starts a local Ray."""
    with ray_session(workers, address) as ray:
        task = ray.remote(num_cpus=1, max_calls=runs_per_worker)(run_job)
        pending = [task.remote(job) for job in jobs]
        while pending:
            finished, pending = ray.wait(pending, num_returns=1)
            yield ray.get(finished[0])


@contextlib.contextmanager
def ray_session(workers: int, address: str | None) -> Iterator[Any]:
    """The `ray` module, joined to `address` (a running cluster) or to a local Ray of `workers` CPUs
    started here (and shut down after), its workers configured as every command is (`runtime`). A local
    Ray's workers run at the caller's priority, as the local pool's do: Ray's default (nice 15) leaves them
    only what other processes on the machine do not take (3 quick trials took 4.5 minutes beside a study)."""
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
            _system_config=None if address else {"worker_niceness": 0},
        )
    try:
        yield ray
    finally:
        if started_here:
            ray.shutdown()


@dataclass(frozen=True)
class SweepOptions:
    """How a sweep runs its jobs, whichever they are."""

    workers: int = 2
    backend: str = "local"
    """One of BACKENDS: local (a process pool) or ray."""
    address: str | None = None
    """The Ray cluster to join (ray backend); None: a local Ray instance."""
    progress: Callable[[str], None] = print
    runs_per_worker: int = RUNS_PER_WORKER
    """Runs a worker process takes in turn (1: a fresh process per run)."""
    finished: Callable[[Outcome], None] | None = None
    """Called with each run's outcome as it comes in (a study exports its archive there, so that a
    lost machine loses only the runs in progress)."""


def run_suite(
    suite: str | Sequence[Arm],
    seeds: int | None,
    out: str | Path,
    options: SweepOptions = SweepOptions(),
    name: str = "arms",
    restart_broken: bool = False,
) -> list[Outcome]:
    """Run every incomplete (arm, seed) of `suite` (a name in SUITES, or arms called `name` in the
    progress lines and the sweep log), seeds 0 … `seeds` − 1, or each arm's own number when
    `seeds` is None; one progress line per run. A run whose checkpoint cannot be resumed fails
    (reported, the sweep goes on) unless `restart_broken`, which starts it over."""
    name, arms = (suite, suite_arms(suite)) if isinstance(suite, str) else (name, list(suite))
    jobs = sweep_jobs(arms, seeds, Path(out), restart_broken)
    return run_jobs(jobs, Path(out), name, seeds or max(arm.seeds for arm in arms), options)


def run_jobs(
    jobs: Sequence[Job], out: Path, name: str, seeds: int | str, options: SweepOptions = SweepOptions()
) -> list[Outcome]:
    """Run the incomplete ones of `jobs`, logged in `out`'s sweep log as `name` with `seeds`."""
    if options.backend not in BACKENDS:
        raise ConfigError(f"unknown backend {options.backend!r}; expected one of {BACKENDS}")
    sweep = _Sweep(name, seeds, [job for job in jobs if not job.complete])
    options.progress(
        f"{name}: {len(jobs)} runs, {len(jobs) - len(sweep.todo)} already complete, {len(sweep.todo)} to run "
        f"on {options.workers} {options.backend} worker(s)"
    )
    interrupted = True
    try:
        for outcome in _stream(sweep.todo, options):
            sweep.outcomes.append(outcome)
            options.progress(
                f"[{len(sweep.outcomes)}/{len(sweep.todo)}] {outcome.job.arm.name} seed{outcome.job.seed}: "
                f"{_status(outcome)} ({outcome.seconds:.0f} s; {sweep.elapsed():.0f} s elapsed)"
            )
            if options.finished is not None:
                options.finished(outcome)
        interrupted = False
    except KeyboardInterrupt:
        options.progress(
            f"{name}: interrupted after {len(sweep.outcomes)} of {len(sweep.todo)} runs; no run was started after "
            f"it, the running ones stopped at their last checkpoint ({sweep.elapsed():.0f} s elapsed): "
            "run the same command again to go on"
        )
        raise
    finally:
        if sweep.outcomes or interrupted:  # every sweep that ran something, and one cut off (as such)
            _log(out, sweep, options, interrupted)
    _check(sweep, options.progress)
    return sweep.outcomes


@dataclass
class _Sweep:
    """A sweep under way: its name and seeds in the log, the runs it has to do and those done."""

    name: str
    seeds: int | str
    todo: list[Job]
    outcomes: list[Outcome] = field(default_factory=list)
    started: float = field(default_factory=time.perf_counter)

    def elapsed(self) -> float:
        return time.perf_counter() - self.started


def _stream(todo: list[Job], options: SweepOptions) -> Iterator[Outcome]:
    """The outcomes of `todo` as they finish, from the chosen backend."""
    if options.backend == "local":
        return _local(todo, options.workers, options.runs_per_worker)
    return _ray(todo, options.workers, options.address, options.runs_per_worker)


def _status(outcome: Outcome) -> str:
    """What became of a run, for its progress line."""
    if outcome.error:
        return f"failed: {outcome.error}"
    if outcome.busy:
        return f"left to the runner that holds it ({outcome.busy})"
    if outcome.done_elsewhere:
        return "skipped: another runner completed it"
    return f"{outcome.episodes} episodes, {outcome.env_steps} steps, eval {outcome.mean_return:.1f}"


def _log(out: Path, sweep: _Sweep, options: SweepOptions, interrupted: bool) -> None:
    """Add the sweep's line to `out`'s SWEEP_LOG: what ran, how, for how long, from which code."""
    log = out / SWEEP_LOG
    entry = {
        "suite": sweep.name,
        "seeds": sweep.seeds,
        "runs": len(sweep.outcomes),
        "workers": options.workers,
        "backend": options.backend,
        "runs_per_worker": options.runs_per_worker,
        "seconds": round(sweep.elapsed(), 1),
        "ended": time.strftime("%Y-%m-%d %H:%M:%S"),
        **({"interrupted": True} if interrupted else {}),
        **provenance(),
    }
    out.mkdir(parents=True, exist_ok=True)
    with locked(out):  # two runners ending together: each line kept, the file rewritten atomically
        write_text(log, (log.read_text() if log.is_file() else "") + json.dumps(entry) + "\n")


def _check(sweep: _Sweep, progress: Callable[[str], None]) -> None:
    """Say which runs were left to another runner; ConfigError naming the first failed run if any failed."""
    busy = [o for o in sweep.outcomes if o.busy]
    if busy:
        progress(
            f"{sweep.name}: {len(busy)} run(s) left to another runner that holds them; run the command again once "
            "it is done to check they are complete"
        )
    failed = [o for o in sweep.outcomes if o.error]
    if failed:
        raise ConfigError(
            f"{len(failed)} of {len(sweep.todo)} runs failed; first: {failed[0].job.directory}: {failed[0].error}"
        )
