"""Suites of training runs (issue D): declared arms × seeds, run on a local process pool or Ray.

    python -m dqfd_bc_keras.experiments run paper --seeds 10 --workers 2 --out results
    python -m dqfd_bc_keras.experiments run all --out results     # paper, baselines, sensitivity
    python -m dqfd_bc_keras.experiments run quick --seeds 2 --backend ray --out /tmp/quick
    python -m dqfd_bc_keras.experiments report results

A suite is a list of `Arm`s (task, time-limit mode, expert loss and any other Config field);
each (arm, seed) is one `train.py`-equivalent run in `OUT/<arm>/seed<N>/`. A run is complete
when its `eval.json` exists: running a suite again skips complete runs and resumes a run that
was cut off from its last checkpoint, so a sweep killed halfway picks up where it stopped.
"""

from __future__ import annotations

import json
import os
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass
from multiprocessing import get_context
from pathlib import Path

from ..cli import ArgumentParser, positive_int, run
from ..config import QUICK, Config
from ..errors import ConfigError
from ..files import write_text

BACKENDS = ("local", "ray")
SWEEP_LOG = "sweeps.jsonl"
"""One line per sweep in the suite directory: what ran, on how many workers, in how many seconds."""


@dataclass(frozen=True)
class Arm:
    """One configuration of a suite; its seeds are the runs."""

    task: str
    timeout: str
    expert_loss: str
    overrides: tuple[tuple[str, object], ...] = ()
    """Further Config fields (sensitivity: sigma0_sq, expert; quick: a tiny budget)."""
    label: str = ""
    """Suffix of the arm's name that says what the overrides change."""

    @property
    def name(self) -> str:
        return "-".join(filter(None, (self.task, self.timeout, self.expert_loss, self.label)))

    def config(self, seed: int) -> Config:
        return Config.for_task(self.task, timeout=self.timeout, expert_loss=self.expert_loss, seed=seed,
                               **dict(self.overrides))


# The paper's four settings (ALGORITHM.md §7): C1 on cartpole and cartpole-200 with the naive
# time limit (the paper's Figs. 3–6), C3 with the bootstrap fix (Fig. 7), C4 on the goal count.
PAPER_SETTINGS = (("cartpole", "naive"), ("cartpole-200", "naive"), ("cartpole", "bootstrap"),
                  ("mountaincar-goals", "bootstrap"))


_SHORT = {"sigma0_sq": "sigma", "expert": "", "eval_every": "eval"}


def arm(task: str, timeout: str, expert_loss: str, **overrides: object) -> Arm:
    """An arm that keeps only the overrides differing from the task preset, labelled by them:
    arms equal in config get one name, so suites sharing an `--out` share their runs."""
    preset = Config.for_task(task).to_dict()
    changed = {k: v for k, v in overrides.items() if preset[k] != v}
    label = "-".join(f"{_SHORT.get(k, k)}{v:g}" if isinstance(v, float) else f"{_SHORT.get(k, k)}{v}"
                     for k, v in changed.items())
    return Arm(task, timeout, expert_loss, tuple(changed.items()), label)


def _sensitivity() -> list[Arm]:
    """σ0² of the Bayesian loss and the demonstrator's quality, where the paper fixes neither."""
    arms = []
    for task, timeout in (("cartpole", "bootstrap"), ("mountaincar-goals", "bootstrap")):
        for expert in ("imperfect", "strong"):
            arms += [arm(task, timeout, "bayes", expert=expert, sigma0_sq=s) for s in (0.05, 0.5, 2.0)]
            arms.append(arm(task, timeout, "ce", expert=expert))
    return arms


SUITES: dict[str, list[Arm]] = {
    "paper": [Arm(t, m, loss) for t, m in PAPER_SETTINGS for loss in ("ce", "bayes")],
    "baselines": [Arm(t, m, loss) for t, m in PAPER_SETTINGS for loss in ("none", "margin", "bc_margin")],
    "sensitivity": _sensitivity(),
    "quick": [Arm("cartpole", "bootstrap", loss, tuple(QUICK.items()), "quick") for loss in ("bayes", "ce")],
}
SEEDS = {"paper": 10, "baselines": 10, "sensitivity": 5, "quick": 2}
"""Seeds per arm when `--seeds` is not given (sensitivity: the issue's minimum of 5 per cell)."""
ALL = ("paper", "baselines", "sensitivity")
"""`run all`: every suite of RESULTS.md, in this order, into one directory (shared arms run once)."""


@dataclass(frozen=True)
class Job:
    arm: Arm
    seed: int
    out: Path

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


def run_job(job: Job) -> Outcome:
    """One run (in a worker process): train, resuming a run cut off before, and summarise it."""
    from ..runs import train

    started = time.perf_counter()
    resume = (job.directory / "checkpoints" / "latest.json").is_file()
    try:
        result = train(job.arm.config(job.seed), job.directory, resume=resume, force=not resume, quiet=True)
    except Exception as error:  # noqa: BLE001  (a failed run is reported, the sweep goes on)
        return Outcome(job, 0, 0, float("nan"), time.perf_counter() - started, f"{type(error).__name__}: {error}")
    return Outcome(job, result.episodes, result.env_steps, result.evaluation["mean_return"],
                   time.perf_counter() - started)


def suite_arms(suite: str) -> list[Arm]:
    if suite not in SUITES:
        raise ConfigError(f"unknown suite {suite!r}; expected one of {sorted(SUITES)}")
    return SUITES[suite]


def _local(jobs: Sequence[Job], workers: int) -> Iterator[Outcome]:
    """A pool of fresh processes (one run each: no TensorFlow state carried between runs)."""
    with ProcessPoolExecutor(max_workers=workers, mp_context=get_context("spawn"), max_tasks_per_child=1) as pool:
        pending = {pool.submit(run_job, job) for job in jobs}
        while pending:
            finished, pending = wait(pending, return_when=FIRST_COMPLETED)
            for future in finished:
                yield future.result()


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


def run_suite(
    suite: str | Sequence[Arm], seeds: int, out: str | Path, workers: int = 2, backend: str = "local",
    address: str | None = None, progress: Callable[[str], None] = print, name: str = "arms",
) -> list[Outcome]:
    """Run every incomplete (arm, seed) of `suite` (a name in SUITES, or arms called `name` in the
    progress lines and the sweep log); one progress line per run."""
    if backend not in BACKENDS:
        raise ConfigError(f"unknown backend {backend!r}; expected one of {BACKENDS}")
    name, arms = (suite, suite_arms(suite)) if isinstance(suite, str) else (name, list(suite))
    out = Path(out)
    jobs = [Job(arm, seed, out) for arm in arms for seed in range(seeds)]
    todo = [job for job in jobs if not job.complete]
    progress(f"{name}: {len(jobs)} runs, {len(jobs) - len(todo)} already complete, {len(todo)} to run "
             f"on {workers} {backend} worker(s)")
    os.environ.setdefault("DQFD_TF_THREADS", "1")  # one core per run
    outcomes, started = [], time.perf_counter()
    stream = _local(todo, workers) if backend == "local" else _ray(todo, workers, address)
    for outcome in stream:
        outcomes.append(outcome)
        job = outcome.job
        status = (f"failed: {outcome.error}" if outcome.error else
                  f"{outcome.episodes} episodes, {outcome.env_steps} steps, eval {outcome.mean_return:.1f}")
        progress(f"[{len(outcomes)}/{len(todo)}] {job.arm.name} seed{job.seed}: {status} "
                 f"({outcome.seconds:.0f} s; {time.perf_counter() - started:.0f} s elapsed)")
    if todo:
        log = out / SWEEP_LOG
        entry = {"suite": name, "seeds": seeds, "runs": len(todo), "workers": workers, "backend": backend,
                 "seconds": round(time.perf_counter() - started, 1), "ended": time.strftime("%Y-%m-%d %H:%M:%S")}
        write_text(log, (log.read_text() if log.is_file() else "") + json.dumps(entry) + "\n")
    failed = [o for o in outcomes if o.error]
    if failed:
        raise ConfigError(f"{len(failed)} of {len(todo)} runs failed; first: {failed[0].job.directory}: {failed[0].error}")
    return outcomes
