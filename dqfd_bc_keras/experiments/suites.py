"""Suites of training runs: declared arms × seeds, run on a local process pool or Ray.

    python -m dqfd_bc_keras.experiments run paper --out results          # each arm its planned seeds
    python -m dqfd_bc_keras.experiments run all --out results            # every suite of RESULTS.md
    python -m dqfd_bc_keras.experiments run quick --seeds 2 --backend ray --out /tmp/quick

A suite is a list of `Arm`s (task, time-limit mode, expert loss, any other Config field, and
how many seeds it gets); each (arm, seed) is one `train.py`-equivalent run in
`OUT/<arm>/seed<N>/`. A run is complete when its `eval.json` exists: running a suite again
skips complete runs and resumes a run that was cut off from its last checkpoint, so a sweep
killed halfway picks up where it stopped. Every finished run gets a `provenance.json` (the
code and rules commits it ran under), and every sweep a line in `OUT/sweeps.jsonl`.
"""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass
from multiprocessing import get_context
from pathlib import Path

from ..config import QUICK, Config
from ..envs import task_slug
from ..errors import BrokenRunError, ConfigError
from ..files import write_text
from .claims import CLAIMS, PAPER_READING_STEPS
from .plans import planned_seeds
from .data import SWEEP_LOG

BACKENDS = ("local", "ray")


@dataclass(frozen=True)
class Arm:
    """One configuration of a suite; its seeds 0 … seeds − 1 are the runs."""

    task: str
    timeout: str
    expert_loss: str
    overrides: tuple[tuple[str, object], ...] = ()
    """Further Config fields, only those that differ from the task preset."""
    label: str = ""
    """Suffix of the arm's name that says what the overrides change."""
    seeds: int = 10

    @property
    def name(self) -> str:
        return "-".join(filter(None, (task_slug(self.task), self.timeout, self.expert_loss, self.label)))

    def config(self, seed: int) -> Config:
        return Config.for_task(self.task, timeout=self.timeout, expert_loss=self.expert_loss, seed=seed,
                               **dict(self.overrides))


_SHORT = {"sigma0_sq": "sigma", "expert": "", "eval_every": "eval", "dynamic_demos": "dyn",
          "early_stop_window": "stopwindow", "total_steps": "steps", "bayes_prior": "prior",
          "mc_dropout": "mcdropout", "uncertainty": "", "expert_epsilon": "eps", "demo_episodes": "demos"}


def arm(task: str, timeout: str, expert_loss: str, seeds: int = 10, **overrides: object) -> Arm:
    """An arm that keeps only the overrides differing from the task preset, labelled by them:
    arms equal in config get one name, so suites sharing an `--out` share their runs."""
    preset = Config.for_task(task).to_dict()
    changed = {k: v for k, v in overrides.items() if preset[k] != v}
    label = "-".join(f"{_SHORT.get(k, k)}{v:g}" if isinstance(v, float) else f"{_SHORT.get(k, k)}{v}"
                     for k, v in changed.items())
    return Arm(task, timeout, expert_loss, tuple(changed.items()), task_slug(label), seeds)


def on_task(arms: Sequence[Arm], task: str | None, assignments: Sequence[str] = ()) -> list[Arm]:
    """`arms` moved to `task` (a preset or any Gymnasium env id; None: their own) with the Config
    `key=value` `assignments` added (e.g. `expert=module:function`); arms that become equal run once."""
    keys = [text.partition("=")[0].strip().replace("-", "_") for text in assignments]
    for key in set(keys) & {"timeout", "expert_loss", "seed"}:
        raise ConfigError(f"--set {key}: {key} is an arm's own (seeds: --seeds)")
    moved = []
    for a in arms:
        target = a.task if task is None else task
        parsed = Config.for_task(target, **dict(a.overrides)).with_overrides(list(assignments)).to_dict()
        moved.append(arm(target, a.timeout, a.expert_loss, a.seeds, **{**dict(a.overrides),
                                                                       **{k: parsed[k] for k in keys}}))
    return list(dict.fromkeys(moved))


PAPER_SETTINGS = (("C1", "cartpole", "naive"), ("C1", "cartpole-200", "naive"), ("C3", "cartpole", "bootstrap"),
                  ("C4", "mountaincar-goals", "bootstrap"))
"""The paper's settings (ALGORITHM.md §7) and the claim whose power plan sets each one's seeds."""
C2_PAPER_READING_SEEDS = 10
"""C2's plan asks for 69–108 seeds per arm (docs/PREREGISTRATION.md §5), beyond any session's budget:
the paper's reading gets 10, today's reading shares C1's cartpole-200 arms, and the report states
the power that gives."""


def claim_seeds(claim_id: str, task: str) -> int:
    """The planned seeds per arm of `claim_id` on its setting of `task` (plans.PLANNED_SEEDS)."""
    setting = next(s for c in CLAIMS if c.id == claim_id for s in c.settings if s.task == task)
    return planned_seeds(claim_id, setting)


PROTOCOL = {"eval_every": 1_000, "eval_episodes": 10}
"""The sample-efficiency protocol, ours and SB3's alike: 10 greedy episodes on the plain env with
fixed seeds (`seeds.eval_seed`) at exactly every 1,000 interactions."""
EFFICIENCY_TASKS = {"cartpole": 5, "mountaincar": 10, "acrobot": 10, "lunarlander": 10}
"""Sample-efficiency tasks → demonstration episodes of the imperfect expert (the presets')."""
PAPER_TASKS = ("cartpole", "mountaincar")
"""The paper's two envs: the dynamic-demonstration readings and every expert loss run on them."""
C2_PAPER_READING = {"early_stop_window": 0, "total_steps": PAPER_READING_STEPS}
"""C2 as the paper runs it: "average ≥ 490, 10 times in a row" with 200-step episodes can never
fire, so no early stop, and a budget of at least 300 episodes (300 × 200 steps)."""


def _paper() -> list[Arm]:
    """C1–C4 (ALGORITHM.md §7): ce vs bayes in the paper's settings, each with its planned seeds,
    and C2 also under the paper's own reading."""
    arms = [arm(t, m, loss, claim_seeds(claim, t)) for claim, t, m in PAPER_SETTINGS for loss in ("ce", "bayes")]
    return arms + [arm("cartpole-200", "naive", loss, C2_PAPER_READING_SEEDS, **C2_PAPER_READING)
                   for loss in ("ce", "bayes")]


def _dynamic() -> list[Arm]:
    """The two readings of dynamic demonstrations, measured with every interaction counted; the
    rule that picks `Config.dynamic_demos`'s default from them is in docs/PREREGISTRATION.md."""
    return [arm(task, "bootstrap", loss, 10, dynamic_demos=mode, **PROTOCOL)
            for task in PAPER_TASKS for loss in ("bayes", "ce") for mode in ("episodes", "rollouts")]


def _efficiency() -> list[Arm]:
    """Interactions to the plain env's threshold, against SB3's DQN (benchmarks/bench_sample_efficiency.py):
    bayes, ce, DQfD's margin and DQN on the paper's envs; the default (bayes) alone on the others."""
    return [arm(task, "bootstrap", loss, 10, demo_episodes=episodes, **PROTOCOL)
            for task, episodes in EFFICIENCY_TASKS.items()
            for loss in (("bayes", "ce", "margin", "none") if task in PAPER_TASKS else ("bayes",))]


def _ablations() -> list[Arm]:
    """What the Bayesian machinery contributes, on C3's and C4's settings: dynamic demonstrations
    off (bayes and ce), the prior term off, σ² fixed at σ0² (no MC dropout)."""
    arms = []
    for task in ("cartpole", "mountaincar-goals"):
        arms += [arm(task, "bootstrap", loss, 10, dynamic_demos="off") for loss in ("bayes", "ce")]
        arms += [arm(task, "bootstrap", "bayes", 10, bayes_prior=False), arm(task, "bootstrap", "bayes", 10, mc_dropout=False)]
    return arms


def _sensitivity() -> list[Arm]:
    """σ0² of the Bayesian loss and the demonstrator's quality, where the paper fixes neither."""
    arms = []
    for task, timeout in (("cartpole", "bootstrap"), ("mountaincar-goals", "bootstrap")):
        for expert in ("imperfect", "strong"):
            arms += [arm(task, timeout, "bayes", 5, expert=expert, sigma0_sq=s) for s in (0.05, 0.5, 2.0)]
            arms.append(arm(task, timeout, "ce", 5, expert=expert))
    return arms


BEST_OTHER_ESTIMATOR = "distance"
"""`calibration.best_other` of docs/data/calibration.json (PREREGISTRATION §8), picked before any run with it."""
OTHER_ESTIMATORS = (BEST_OTHER_ESTIMATOR, "ensemble")
GRID_TASK = "cartpole"
GRID_TEACHERS = (("strong", 0.0), ("imperfect", 0.0), ("strong", 0.2), ("strong", 0.5))
"""(expert, ε): the strong and imperfect scripted experts, and the strong one acting at random w.p. ε."""
GRID_EPISODES = (1, 5, 20)
GRID_SEEDS = 5
GRID_METHODS = (("margin", ()), ("ce", ()), ("bayes", ()), ("bayes", (("uncertainty", BEST_OTHER_ESTIMATOR),)),
                ("sqil", ()))
"""(expert loss, further Config fields) of the grid's learners with demonstrations."""


QUICK_GRID = ((("strong", 0.5),), (1,))
"""`--quick`: one cell (a bad teacher, one episode), one seed, the QUICK budget (the tests' grid)."""


def grid_cells(quick: bool = False) -> list[dict[str, object]]:
    """The Config fields of each cell: teacher × demonstrated episodes."""
    teachers, episodes = QUICK_GRID if quick else (GRID_TEACHERS, GRID_EPISODES)
    return [{"expert": expert, "expert_epsilon": epsilon, "demo_episodes": n} for expert, epsilon in teachers
            for n in episodes]


def quick(a: Arm) -> Arm:
    """Arm `a` on the QUICK budget (its own fields kept), one seed, labelled `quick`."""
    fields = dict(a.overrides)
    return dataclasses.replace(a, overrides=(*a.overrides, *((k, v) for k, v in QUICK.items() if k not in fields)),
                               label="-".join(filter(None, (a.label, "quick"))), seeds=1)


def grid_arms(quick_budget: bool = False) -> list[Arm]:
    """When demonstrations help or hurt (PREREGISTRATION §8): every method on every cell, and plain
    DQN once; BC alone is `imitation.py`'s, without RL."""
    arms = [arm(GRID_TASK, "bootstrap", "none", GRID_SEEDS, **PROTOCOL)]
    arms += [arm(GRID_TASK, "bootstrap", loss, GRID_SEEDS, **cell, **dict(extra), **PROTOCOL)
             for cell in grid_cells(quick_budget) for loss, extra in GRID_METHODS]
    return [quick(a) for a in arms] if quick_budget else arms


def _estimators() -> list[Arm]:
    """bayes with the other estimators on the verdicts' settings (C3, C4, MountainCar's efficiency),
    in the pre-registered order: the best one first."""
    return [a for u in OTHER_ESTIMATORS for a in (
        arm("cartpole", "bootstrap", "bayes", claim_seeds("C3", "cartpole"), uncertainty=u),
        arm("mountaincar-goals", "bootstrap", "bayes", claim_seeds("C4", "mountaincar-goals"), uncertainty=u),
        arm("mountaincar", "bootstrap", "bayes", 10, uncertainty=u, demo_episodes=EFFICIENCY_TASKS["mountaincar"],
            **PROTOCOL))]


SUITES: dict[str, list[Arm]] = {
    "dynamic": _dynamic(),
    "efficiency": _efficiency(),
    "paper": _paper(),
    "ablations": _ablations(),
    "baselines": [arm(t, m, loss) for _, t, m in PAPER_SETTINGS for loss in ("none", "margin", "bc_margin")],
    "sensitivity": _sensitivity(),
    "demos": grid_arms(),
    "estimators": _estimators(),
    "quick": [Arm("cartpole", "bootstrap", loss, tuple(QUICK.items()), "quick", 2) for loss in ("bayes", "ce")],
}
ALL = ("dynamic", "efficiency", "paper", "ablations", "baselines", "sensitivity", "estimators", "demos")
"""`run all`: every suite of RESULTS.md, in this order, into one directory (shared arms run once)."""


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


def suite_arms(suite: str) -> list[Arm]:
    if suite not in SUITES:
        raise ConfigError(f"unknown suite {suite!r}; expected one of {sorted(SUITES)}")
    return SUITES[suite]


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
