"""Per-run metrics: each run of the lab as one number per metric, for statistics over seeds.

Part of the pre-registered rules (docs/PREREGISTRATION.md): every metric is defined here, in
words (`METRICS`, quoted by RESULTS.md) and in code (`PER_RUN`), before any result is looked at.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

import numpy as np

from dqfd_bc_keras.envs.make import get_task
from dqfd_bc_keras.experiments.run_files import FinishedRun

EARLY_EPISODES = 30
"""C4's "early in training": the first 30 training episodes."""
PEAK_FRACTION, COLLAPSE_FRACTION = 0.98, 0.5
"""A collapse (the paper's perturbation): plain return < 0.5 × limit after the first episode ≥ 0.98 × limit."""
METRICS = {
    "episodes_to_solve": "training episodes until the early-stopping rule fired (the last `early_stop_window` "
    "task returns all ≥ `early_stop_fraction` × limit); a run in which it never fired is "
    "censored as ∞, so it ranks after every finished run (medians and rank tests, never a mean)",
    "unfinished": "1 if the early-stopping rule never fired within the step budget, else 0",
    "mean_train_return": "mean plain-env return over all training episodes",
    "collapses": f"episodes with plain return < {COLLAPSE_FRACTION} × limit after the first episode whose task "
    f"return ≥ {PEAK_FRACTION} × limit",
    "collapsed": "1 if the run has at least one collapse, else 0",
    "goals_first30": f"mean flags reached per episode over the first {EARLY_EPISODES} training episodes "
    "(all, if fewer)",
    "goals_all": "mean flags reached per episode over all training episodes",
    "final_eval": "mean return of the final greedy evaluation (eval.json) on the plain env",
    "interactions_to_threshold": "interactions (every env step the learner's data came from, roll-outs included) "
    "at the first grid evaluation whose mean return ≥ the plain env's solved "
    "threshold; ∞ if none did (medians and rank tests)",
}


def episodes_to_solve(run: FinishedRun) -> int | None:
    """The episode at which the task's early-stopping rule fired; None if it never did."""
    c = run.config
    if c.early_stop_window == 0:
        return None
    streak = 0
    for episode, good in enumerate(run.column("return") >= c.early_stop_fraction * c.limit, start=1):
        streak = streak + 1 if good else 0
        if streak >= c.early_stop_window:
            return episode
    return None


def finished(run: FinishedRun) -> bool:
    return episodes_to_solve(run) is not None


def censored_episodes_to_solve(run: FinishedRun) -> float:
    """`episodes_to_solve`, inf for a run that never solved: it ranks after every finished run by
    construction (its own episode count + 1 would rank before a slower run that did finish)."""
    solved = episodes_to_solve(run)
    return np.inf if solved is None else float(solved)


def collapses(run: FinishedRun) -> int:
    """The paper's perturbations: episodes whose plain return falls below COLLAPSE_FRACTION × limit
    after the first whose task return reached PEAK_FRACTION × limit."""
    peaks = np.flatnonzero(run.column("return") >= PEAK_FRACTION * run.config.limit)
    if peaks.size == 0:
        return 0
    return int(np.sum(run.column("plain_return")[peaks[0] + 1 :] < COLLAPSE_FRACTION * run.config.limit))


def solved_return(task: str) -> float:
    """The mean return that solves `task`, which the interactions to the threshold are counted to."""
    threshold = get_task(task).solved_return
    if threshold is None:
        raise ValueError(f"{task} sets no solved_return: no interactions to a threshold are counted on it")
    return threshold


def first_reaching(evals: Iterable[tuple[float, float]], threshold: float) -> float | None:
    """The first evaluated step of (step, mean return) pairs whose mean reaches `threshold`."""
    return next((float(step) for step, mean in evals if mean >= threshold), None)


def interactions_to_threshold(run: FinishedRun) -> float:
    """Counted interactions at the first evaluation that reaches the plain env's threshold; inf if
    none did."""
    step = first_reaching(((e["interactions"], e["mean_return"]) for e in run.evals), solved_return(run.config.task))
    return np.inf if step is None else step


PER_RUN: dict[str, Callable[[FinishedRun], float]] = {
    "episodes_to_solve": censored_episodes_to_solve,
    "unfinished": lambda r: float(not finished(r)),
    "mean_train_return": lambda r: float(r.column("plain_return").mean()),
    "collapses": collapses,
    "collapsed": lambda r: float(collapses(r) > 0),
    "goals_first30": lambda r: float(r.column("goals")[:EARLY_EPISODES].mean()),
    "goals_all": lambda r: float(r.column("goals").mean()),
    "final_eval": lambda r: r.final.mean_return,
    "interactions_to_threshold": interactions_to_threshold,
}
"""Each metric as one number per run, for statistics over seeds."""
CENSORED = ("episodes_to_solve", "interactions_to_threshold")
"""Metrics with inf for "never": summarised by medians, compared by ranks only."""
SHARES = ("unfinished", "collapsed")
"""0/1 metrics: their mean is a share of runs, compared with Fisher's exact test."""
