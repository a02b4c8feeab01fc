"""Running a suite: every (arm, seed) a fresh process on a local pool or a Ray task.

A run is complete when its `eval.json` exists: running a suite again skips complete runs and
resumes a run that was cut off from its last checkpoint, so a sweep killed halfway picks up
where it stopped. Every finished run gets a `provenance.json` (the code and rules commits it ran
under), and every sweep a line in `OUT/sweeps.jsonl`.
"""

from __future__ import annotations

import json
import os
import subprocess
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass
from multiprocessing import get_context
from pathlib import Path

from ..errors import BrokenRunError, ConfigError
from ..files import write_text
from .data import SWEEP_LOG
from .suites import Arm, suite_arms

BACKENDS = ("local", "ray")


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
        return (self.directory / "eval.json").is_file()


@dataclass
class Outcome:
    """What one finished run reports back to the sweep."""

    job: Job
    episodes: int
    env_steps: int
    mean_return: float
    seconds: float
    error: str = ""


RULES = ("dqfd_bc_keras/experiments/claims.py", "docs/PREREGISTRATION.md")
"""Where the verdict rules live: `rules_commit` is the last commit that changed either."""


def _git(*args: str) -> str | None:
    root = Path(__file__).resolve().parents[2]
    try:
        done = subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout.strip() if done.returncode == 0 else None


def provenance() -> dict:
    """The code a run ran and the rules that will judge it: commits (None outside a git checkout),
    whether tracked files differed from the commit, and the library versions."""
    import gymnasium
    import keras
    import numpy
    import tensorflow

    status = _git("status", "--porcelain", "--untracked-files=no")
    return {"code_commit": _git("rev-parse", "HEAD"), "rules_commit": _git("log", "-1", "--format=%H", "--", *RULES),
            "dirty": bool(status) if status is not None else None,
            "versions": {m.__name__: m.__version__ for m in (tensorflow, keras, gymnasium, numpy)}}


def run_job(job: Job) -> Outcome:
    """One run (in a worker process): train, resuming a run cut off before, and summarise it."""
    from ..runs import train

    started = time.perf_counter()
    resume = (job.directory / "checkpoints" / "latest.json").is_file()
    config = job.arm.config(job.seed)
    try:
        try:
            result = train(config, job.directory, resume=resume, force=not resume, quiet=True)
        except BrokenRunError as error:
            if not job.restart_broken:
                raise BrokenRunError(f"{error} (or rerun the sweep with --restart-broken)") from None
            result = train(config, job.directory, force=True, quiet=True)
        write_text(job.directory / "provenance.json", json.dumps(provenance(), indent=1))
    except Exception as error:  # noqa: BLE001  (a failed run is reported, the sweep goes on)
        return Outcome(job, 0, 0, float("nan"), time.perf_counter() - started, f"{type(error).__name__}: {error}")
    return Outcome(job, result.episodes, result.env_steps, result.evaluation.mean_return,
                   time.perf_counter() - started)


def _local(jobs: Sequence[Job], workers: int) -> Iterator[Outcome]:
    """A pool of fresh processes (one run each: no TensorFlow state carried between runs).

    Not several runs per process: it would save TensorFlow's import (~5 s per run), but Python
    3.11's `ProcessPoolExecutor` stopped starting new workers once two had retired after their
    `max_tasks_per_child` > 1 (a 72-run sweep hung after its 20th run)."""
    with ProcessPoolExecutor(max_workers=workers, mp_context=get_context("spawn"), max_tasks_per_child=1) as pool:
        pending = {pool.submit(run_job, job) for job in jobs}
        try:
            while pending:
                finished, pending = wait(pending, return_when=FIRST_COMPLETED)
                for future in finished:
                    yield future.result()
        except BaseException:  # Ctrl-C, SIGTERM: the queued runs are dropped, the running ones end
            pool.shutdown(wait=True, cancel_futures=True)
            raise


def _ray(jobs: Sequence[Job], workers: int, address: str | None) -> Iterator[Outcome]:
    """Each run a Ray task on one CPU; joins `address` (a running cluster) or starts a local Ray."""
    try:
        import ray
    except ImportError:
        raise ConfigError("the ray backend needs Ray: pip install -r requirements-ray.txt") from None
    started_here = not ray.is_initialized()
    if started_here:
        ray.init(address=address, num_cpus=None if address else workers, include_dashboard=False,
                 log_to_driver=False, runtime_env={"env_vars": {"PYTHONPATH": str(Path(__file__).parents[2])}})
    try:
        task = ray.remote(num_cpus=1, max_calls=1)(run_job)
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
    suite: str | Sequence[Arm], seeds: int | None, out: str | Path, workers: int = 2, backend: str = "local",
    address: str | None = None, progress: Callable[[str], None] = print, name: str = "arms",
    restart_broken: bool = False,
) -> list[Outcome]:
    """Run every incomplete (arm, seed) of `suite` (a name in SUITES, or arms called `name` in the
    progress lines and the sweep log), seeds 0 … `seeds` − 1, or each arm's own number when
    `seeds` is None; one progress line per run. A run whose checkpoint cannot be resumed fails
    (reported, the sweep goes on) unless `restart_broken`, which starts it over."""
    if backend not in BACKENDS:
        raise ConfigError(f"unknown backend {backend!r}; expected one of {BACKENDS}")
    name, arms = (suite, suite_arms(suite)) if isinstance(suite, str) else (name, list(suite))
    out = Path(out)
    jobs = sweep_jobs(arms, seeds, out, restart_broken)
    todo = [job for job in jobs if not job.complete]
    progress(f"{name}: {len(jobs)} runs, {len(jobs) - len(todo)} already complete, {len(todo)} to run "
             f"on {workers} {backend} worker(s)")
    os.environ.setdefault("DQFD_TF_THREADS", "1")  # one core per run
    outcomes, started, interrupted = [], time.perf_counter(), True
    stream = _local(todo, workers) if backend == "local" else _ray(todo, workers, address)
    try:
        for outcome in stream:
            outcomes.append(outcome)
            job = outcome.job
            status = (f"failed: {outcome.error}" if outcome.error else
                      f"{outcome.episodes} episodes, {outcome.env_steps} steps, eval {outcome.mean_return:.1f}")
            progress(f"[{len(outcomes)}/{len(todo)}] {job.arm.name} seed{job.seed}: {status} "
                     f"({outcome.seconds:.0f} s; {time.perf_counter() - started:.0f} s elapsed)")
        interrupted = False
    finally:
        if outcomes:  # every sweep that ran something, one cut off too (as such)
            log = out / SWEEP_LOG
            entry = {"suite": name, "seeds": seeds or max(arm.seeds for arm in arms), "runs": len(outcomes),
                     "workers": workers, "backend": backend, "seconds": round(time.perf_counter() - started, 1),
                     "ended": time.strftime("%Y-%m-%d %H:%M:%S"), **({"interrupted": True} if interrupted else {}),
                     **provenance()}
            write_text(log, (log.read_text() if log.is_file() else "") + json.dumps(entry) + "\n")
    failed = [o for o in outcomes if o.error]
    if failed:
        raise ConfigError(f"{len(failed)} of {len(todo)} runs failed; first: {failed[0].job.directory}: {failed[0].error}")
    return outcomes
