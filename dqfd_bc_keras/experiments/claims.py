"""The paper's claims (ALGORITHM.md §7, C1–C4) judged over seeds; `results.py` writes them up.

Every metric, margin and verdict rule is a constant or docstring here, fixed before any result
is looked at, so RESULTS.md can quote them. Runs are read from their files (never from their
directory names) and grouped into arms by config.json: every field except `seed`.
"""

from __future__ import annotations

import functools
import json
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..config import Config
from ..demos import record
from ..envs import get_task
from ..errors import ConfigError
from .data import FinishedRun
from .stats import Summary, bootstrap_diff_ci, equivalent, excludes_zero, fisher_exact, mann_whitney

ALPHA = 0.05
"""Significance level of every two-sided test."""
RETURN_MARGIN = 0.05
"""C1, C3: "no difference" in mean training return: the 95% CI of bayes − ce lies within ±5% of the limit."""
SHARE_MARGIN = 0.2
"""C2: "about equally frequent" unfinished runs means a difference of shares within ±0.2."""
GOALS_MARGIN = 0.25
"""C4: goals per episode within ±0.25 count as no difference."""
EARLY_EPISODES = 30
"""C4's "early in training": the first 30 training episodes."""
BAYES_ONLY = ("sigma0_sq", "mc_passes", "prior_scale", "prior_center", "bc_dropout", "bc_prior_scale")
"""Config fields only the bayes loss reads: a bayes arm pairs with the ce arm equal in every other field."""
PEAK_FRACTION, COLLAPSE_FRACTION = 0.98, 0.5
"""A collapse (the paper's perturbation): plain return < 0.5 × limit after the first episode ≥ 0.98 × limit."""
REGENERATE = ("python -m dqfd_bc_keras.experiments run all --out results && "
              "python benchmarks/bench_sample_efficiency.py --out results && "
              "python -m dqfd_bc_keras.experiments report results")
"""Every run, the benchmark and this report (finished runs are skipped, so it also resumes)."""

METRICS = {
    "episodes_to_solve": "training episodes until the early-stopping rule fired (the last `early_stop_window` "
                         "task returns all ≥ `early_stop_fraction` × limit); a run that never fired counts as "
                         "its episode count + 1 (censored, ranked after every finished run)",
    "unfinished": "1 if the early-stopping rule never fired within the step budget, else 0",
    "mean_train_return": "mean plain-env return over all training episodes",
    "collapses": f"episodes with plain return < {COLLAPSE_FRACTION} × limit after the first episode whose task "
                 f"return ≥ {PEAK_FRACTION} × limit",
    "goals_first30": f"mean flags reached per episode over the first {EARLY_EPISODES} training episodes "
                     "(all, if fewer)",
    "goals_all": "mean flags reached per episode over all training episodes",
    "final_eval": "mean return of the final greedy evaluation (eval.json) on the plain env",
    "steps_to_threshold": "first evaluation env step whose mean return ≥ the plain env's solved threshold",
}


# --- per-run metrics ------------------------------------------------------------------------
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


def collapses(run: FinishedRun) -> int:
    """The paper's perturbations: episodes whose plain return falls below COLLAPSE_FRACTION × limit
    after the first whose task return reached PEAK_FRACTION × limit."""
    peaks = np.flatnonzero(run.column("return") >= PEAK_FRACTION * run.config.limit)
    if peaks.size == 0:
        return 0
    return int(np.sum(run.column("plain_return")[peaks[0] + 1:] < COLLAPSE_FRACTION * run.config.limit))


def first_reaching(evals: Iterable[tuple[float, float]], threshold: float) -> float | None:
    """The first evaluated env step of (env step, mean return) pairs whose mean reaches `threshold`."""
    return next((float(step) for step, mean in evals if mean >= threshold), None)


def steps_to_threshold(run: FinishedRun) -> float | None:
    return first_reaching(((e["env_step"], e["mean_return"]) for e in run.evals),
                          get_task(run.config.task).solved_return)


PER_RUN: dict[str, Callable[[FinishedRun], float]] = {
    "episodes_to_solve": lambda r: len(r.metrics) + 1 if episodes_to_solve(r) is None else episodes_to_solve(r),
    "unfinished": lambda r: float(not finished(r)),
    "mean_train_return": lambda r: float(r.column("plain_return").mean()),
    "collapses": collapses,
    "goals_first30": lambda r: float(r.column("goals")[:EARLY_EPISODES].mean()),
    "goals_all": lambda r: float(r.column("goals").mean()),
    "final_eval": lambda r: float(r.final["mean_return"]),
}
"""Each metric as one number per run, for statistics over seeds (censoring resolved)."""


# --- arms and settings ----------------------------------------------------------------------
@dataclass
class ArmRuns:
    """The runs of one configuration (all fields but the seed)."""

    config: dict
    runs: list[FinishedRun]
    name: str = ""

    @property
    def setting(self) -> str:
        return f"{self.config['task']}/{self.config['timeout']}"

    @property
    def label(self) -> str:
        return f"{self.setting} · {self.name}"

    def values(self, metric: str) -> np.ndarray:
        return np.array([PER_RUN[metric](run) for run in self.runs], dtype=float)


def group_arms(runs: list[FinishedRun]) -> list[ArmRuns]:
    """Runs with equal configs but for `seed` form an arm; each arm is named by its expert loss
    and every field in which the arms of its setting (task, timeout) differ."""
    arms: dict[str, ArmRuns] = {}
    for run in runs:
        fields = {k: v for k, v in run.config.to_dict().items() if k != "seed"}
        arm = arms.setdefault(json.dumps(fields, sort_keys=True), ArmRuns(fields, []))
        if all(r.config.seed != run.config.seed for r in arm.runs):  # a run repeated elsewhere counts once
            arm.runs.append(run)
    for arm in arms.values():
        arm.runs.sort(key=lambda r: r.config.seed)
        peers = [a.config for a in arms.values() if a.setting == arm.setting]
        varying = [k for k in arm.config if k not in ("task", "timeout", "expert_loss")
                   and len({json.dumps(p[k]) for p in peers}) > 1
                   and not (k in BAYES_ONLY and arm.config["expert_loss"] != "bayes")]
        arm.name = " ".join([arm.config["expert_loss"], *(f"{k}={arm.config[k]}" for k in varying)])
    return sorted(arms.values(), key=lambda a: a.label)


def preset_distance(arm: ArmRuns) -> int:
    """How many config fields besides the loss (and the timeout) differ from the task preset:
    0 for the paper's and the baselines' arms, more for a sensitivity or benchmark variant."""
    preset = Config.for_task(arm.config["task"]).to_dict()
    return sum(v != preset[k] for k, v in arm.config.items() if k not in ("expert_loss", "timeout"))


def bayes_ce_pairs(arms: list[ArmRuns], task: str, timeout: str | None) -> list[tuple[ArmRuns, ArmRuns | None]]:
    """Each bayes arm of the setting with its ce arm (equal in every field but the Bayes-only
    ones and the loss), the reference pair first: the one closest to the task preset."""
    def strip(arm: ArmRuns) -> dict:
        return {k: v for k, v in arm.config.items() if k not in ("expert_loss", *BAYES_ONLY)}

    pairs = [(b, next((c for c in arms if c.config["expert_loss"] == "ce" and strip(c) == strip(b)), None))
             for b in arms if b.config["expert_loss"] == "bayes" and b.config["task"] == task
             and timeout in (None, b.config["timeout"])]
    return sorted(pairs, key=lambda p: (p[1] is None, preset_distance(p[0]), -len(p[0].runs), p[0].label))


# --- the claims -----------------------------------------------------------------------------
@dataclass
class Comparison:
    """One metric, bayes against ce: each arm's summary, the CI of the difference of means, a test."""

    metric: str
    bayes: Summary
    ce: Summary
    diff: tuple[float, float]
    test: str
    p: float


def compare(metric: str, bayes: ArmRuns, ce: ArmRuns) -> Comparison:
    """Mann–Whitney U on the per-run values; Fisher's exact test for the 0/1 `unfinished`."""
    x, y = bayes.values(metric), ce.values(metric)
    if metric == "unfinished":
        test, p = "Fisher exact", fisher_exact(int(x.sum()), len(x), int(y.sum()), len(y))[1]
    else:
        test, p = "Mann–Whitney U", mann_whitney(x, y)[1]
    return Comparison(metric, Summary.of(x), Summary.of(y), bootstrap_diff_ci(x, y), test, p)


def _same_return(bayes: ArmRuns, ce: ArmRuns, episodes: bool) -> tuple[str, list[Comparison]]:
    ret = compare("mean_train_return", bayes, ce)
    comparisons = [compare("episodes_to_solve", bayes, ce), ret] if episodes else [ret]
    differ = episodes and comparisons[0].p < ALPHA
    if equivalent(ret.diff, RETURN_MARGIN * bayes.runs[0].config.limit) and not differ:
        return "holds", comparisons
    return ("does not hold" if excludes_zero(ret.diff) or differ else "inconclusive"), comparisons


def judge_c1(bayes: ArmRuns, ce: ArmRuns) -> tuple[str, list[Comparison]]:
    """holds: the CI of the difference of mean training returns lies within ±RETURN_MARGIN × limit
    and Mann–Whitney p ≥ ALPHA on episodes_to_solve; does not hold: that CI excludes 0 or p < ALPHA;
    else inconclusive. Equivalence is checked first: a significant difference of returns inside
    the margin is no difference that matters."""
    return _same_return(bayes, ce, episodes=True)


def judge_c3(bayes: ArmRuns, ce: ArmRuns) -> tuple[str, list[Comparison]]:
    """holds: the CI of the difference of mean training returns lies within ±RETURN_MARGIN × limit;
    does not hold: it excludes 0 (and is not within the margin); else inconclusive."""
    return _same_return(bayes, ce, episodes=False)


def judge_c2(bayes: ArmRuns, ce: ArmRuns) -> tuple[str, list[Comparison]]:
    """holds: both arms show perturbations (an unfinished run or a collapse), Fisher's p ≥ ALPHA
    on unfinished runs and their shares differ by ≤ SHARE_MARGIN; does not hold: Fisher's
    p < ALPHA; else inconclusive. Collapses are compared with Mann–Whitney U (reported)."""
    unfinished, falls = compare("unfinished", bayes, ce), compare("collapses", bayes, ce)
    perturbed = all(arm.values("unfinished").sum() + arm.values("collapses").sum() > 0 for arm in (bayes, ce))
    if perturbed and unfinished.p >= ALPHA and abs(unfinished.bayes.mean - unfinished.ce.mean) <= SHARE_MARGIN:
        return "holds", [unfinished, falls]
    return ("does not hold" if unfinished.p < ALPHA else "inconclusive"), [unfinished, falls]


def judge_c4(bayes: ArmRuns, ce: ArmRuns) -> tuple[str, list[Comparison]]:
    """holds: the CI of bayes − ce in goals_first30 lies above 0 and Mann–Whitney p < ALPHA;
    does not hold: that CI lies at or below 0, or p ≥ ALPHA with the CI within ±GOALS_MARGIN; else
    inconclusive. goals_all is reported beside it."""
    early, whole = compare("goals_first30", bayes, ce), compare("goals_all", bayes, ce)
    if early.diff[0] > 0 and early.p < ALPHA:
        return "holds", [early, whole]
    if early.diff[1] <= 0 or (early.p >= ALPHA and equivalent(early.diff, GOALS_MARGIN)):
        return "does not hold", [early, whole]
    return "inconclusive", [early, whole]


@dataclass(frozen=True)
class Claim:
    id: str
    statement: str
    settings: tuple[tuple[str, str | None], ...]
    """(task, timeout) pairs it is tested on; timeout None: any."""
    judge: Callable[[ArmRuns, ArmRuns], tuple[str, list[Comparison]]]

    @property
    def rule(self) -> str:
        """The verdict rule, from the judge's docstring, with the constants filled in."""
        text = " ".join(self.judge.__doc__.split())
        for name in ("ALPHA", "RETURN_MARGIN", "SHARE_MARGIN", "GOALS_MARGIN"):
            text = text.replace(name, f"{globals()[name]:g}")
        return text


CLAIMS = (
    Claim("C1", "bayes and ce do not differ significantly in best or average case",
          (("cartpole", "naive"), ("cartpole-200", "naive")), judge_c1),
    Claim("C2", "with the 200-step limit both suffer perturbations; unfinished runs about equally frequent",
          (("cartpole-200", "naive"),), judge_c2),
    Claim("C3", "with the time-limit bootstrap fix bayes and ce give the same average reward",
          (("cartpole", "bootstrap"),), judge_c3),
    Claim("C4", "bayes reaches the flag markedly more often per episode than ce, especially early",
          (("mountaincar-goals", None),), judge_c4),
)


def setting_name(task: str, timeout: str | None) -> str:
    return f"{task}/{timeout or '*'}"


def judge(claim: Claim, bayes: ArmRuns, ce: ArmRuns | None) -> tuple[str, list[Comparison]]:
    if ce is None:
        return "not run (no ce arm)", []
    if min(len(bayes.runs), len(ce.runs)) < 2:
        return "inconclusive (n < 2)", []
    return claim.judge(bayes, ce)


# --- the report -----------------------------------------------------------------------------
@functools.cache
def _recorded_plain_return(task: str, expert: str, episodes: int, seed: int, timeout: str,
                           max_steps: int | None) -> float:
    return float(np.mean(record(task, expert, episodes, seed=seed, timeout=timeout,
                                max_steps=max_steps).meta.plain_returns))


def demonstrator_return(run: FinishedRun) -> float | None:
    """The mean plain return of the demonstrations the run started from (None for plain DQN).

    demos.npz holds D_demo at the end, which dynamic demonstrations enlarge with the agent's
    own episodes; it is the demonstrator's only when dynamic_demos.json (the log of such
    updates) is absent. Otherwise the recording is replayed: the scripted experts are
    deterministic and seeded (training.demonstrations), so it is the same data.
    """
    c = run.config
    if not c.uses_demos:
        return None
    if (run.path / "demos.npz").is_file() and not (run.path / "dynamic_demos.json").exists():
        with np.load(run.path / "demos.npz", allow_pickle=False) as data:
            return float(np.mean(json.loads(str(data["meta"]))["plain_returns"]))
    return _recorded_plain_return(c.task, c.expert, c.demo_episodes, c.seed * 1000, c.timeout, c.max_steps)
