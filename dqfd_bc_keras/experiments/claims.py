"""The paper's claims (ALGORITHM.md §7, C1–C4) judged over seeds; `report.py` writes them up.

Every margin and verdict rule is a constant or docstring here (the metrics they read are in
metrics.py, the arms they compare in arms.py), fixed before any result is looked at, so
RESULTS.md can quote them.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass, field

from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.experiments.arms import ArmRuns, Setting
from dqfd_bc_keras.experiments.metrics import CENSORED, SHARES
from dqfd_bc_keras.experiments.power import bound_power, equivalence_power, pooled_sd
from dqfd_bc_keras.experiments.stats import (
    CensoredSummary,
    Summary,
    beyond,
    bootstrap_diff_ci,
    equivalent,
    fisher_exact,
    mann_whitney,
    tost_ci,
)

ALPHA = 0.05
"""Significance level of every test: two-sided tests at ALPHA, and TOST at ALPHA."""
TOST_LEVEL = 1.0 - 2.0 * ALPHA
"""The CI whose two ends are one-sided bounds at ALPHA: every margin rule reads it (TOST at 0.05: the 90% CI)."""
RETURN_MARGIN = 0.05
"""C1, C3: "no difference" in mean training return means |bayes − ce| within 5% of the episode limit."""
SHARE_MARGIN = 0.2
"""C2: "about equally frequent" means shares of runs within ±0.2 of each other."""
GOALS_MARGIN = 0.25
"""C4: flags per episode within ±0.25 are no difference; "markedly more" has to clear +0.25."""
PAPER_READING_STEPS = 60_000
"""C2's paper reading runs without early stop for this budget: ≥ 300 episodes of at most 200 steps."""


# --- the claims -----------------------------------------------------------------------------
@dataclass
class Comparison:
    """One metric, bayes against ce: each arm's summary, the 95% and the TOST (1 − 2α) bootstrap CI
    of the difference of means (None for a censored metric), and a two-sided test."""

    metric: str
    bayes: Summary | CensoredSummary
    ce: Summary | CensoredSummary
    diff: tuple[float, float] | None
    tost: tuple[float, float] | None
    test: str
    p: float

    @property
    def judged(self) -> tuple[float, float]:
        """The TOST interval a rule judges by: a censored metric has none, so no rule judges one."""
        if self.tost is None:
            raise ValueError(f"{self.metric} is censored: no interval of a difference of means judges it")
        return self.tost

    def interval(self, digits: int = 2) -> str:
        """`low … high (90%: low … high)` for a table cell; — when a mean is undefined."""
        if self.diff is None or self.tost is None:
            return "—"
        return (
            f"{self.diff[0]:.{digits}f} … {self.diff[1]:.{digits}f} "
            f"({TOST_LEVEL:.0%}: {self.tost[0]:.{digits}f} … {self.tost[1]:.{digits}f})"
        )


def compare(metric: str, bayes: ArmRuns, ce: ArmRuns) -> Comparison:
    """Fisher's exact test for a share, Mann–Whitney U otherwise (inf ranks last); a censored
    metric gets medians and no interval of a difference of means."""
    x, y = bayes.values(metric), ce.values(metric)
    if metric in SHARES:
        test, p = "Fisher exact", fisher_exact(int(x.sum()), len(x), int(y.sum()), len(y))[1]
    else:
        test, p = "Mann–Whitney U", mann_whitney(x, y)[1]
    if metric in CENSORED:
        return Comparison(metric, CensoredSummary.of(x), CensoredSummary.of(y), None, None, test, p)
    return Comparison(metric, Summary.of(x), Summary.of(y), bootstrap_diff_ci(x, y), tost_ci(x, y, ALPHA), test, p)


def rule_power(sd: float, margin: float, n: int, one_sided: bool = False) -> float:
    """The power of a margin rule with n seeds per arm and spread sd when bayes and ce truly do not
    differ: TOST at ALPHA inside ±margin, or (`one_sided`, C4) the upper bound below +margin.
    With a planned sd it plans the seeds; with the observed sd it is the power the runs achieved."""
    return bound_power(sd, margin, n, ALPHA) if one_sided else equivalence_power(sd, margin, n, ALPHA)


@dataclass
class Verdict:
    """A claim judged on one bayes–ce pair: the verdict, the comparisons (the judged metric first),
    and that metric's pooled sd over seeds with the power it gives the rule (`rule_power`)."""

    verdict: str
    comparisons: list[Comparison] = field(default_factory=list)
    sd: float | None = None
    power: float | None = None


def _verdict(
    verdict: str, comparisons: list[Comparison], bayes: ArmRuns, ce: ArmRuns, margin: float, one_sided: bool = False
) -> Verdict:
    metric = comparisons[0].metric
    sd = pooled_sd(bayes.values(metric), ce.values(metric))
    return Verdict(verdict, comparisons, sd, rule_power(sd, margin, min(len(bayes.runs), len(ce.runs)), one_sided))


def _equivalence(comparison: Comparison, margin: float) -> str:
    """TOST by the interval: holds inside ±margin, does not hold wholly outside it."""
    if equivalent(comparison.judged, margin):
        return "holds"
    return "does not hold" if beyond(comparison.judged, margin) else "inconclusive"


def judge_c1(bayes: ArmRuns, ce: ArmRuns) -> Verdict:
    """holds: TOST at ALPHA on mean_train_return, i.e. the TOST_LEVEL CI of bayes − ce lies within
    ±RETURN_MARGIN × limit; does not hold: that CI lies wholly outside ±RETURN_MARGIN × limit; else
    inconclusive. A significant difference inside the margin holds (it is none that matters); a
    large p never does. episodes_to_solve is reported, not judged (medians, runs that never solved
    ranked last, Mann–Whitney U): an episode count has no scale on which a margin could be fixed in
    advance, and its censored runs leave a difference of means undefined."""
    margin = RETURN_MARGIN * bayes.config.limit
    returns = compare("mean_train_return", bayes, ce)
    return _verdict(
        _equivalence(returns, margin), [returns, compare("episodes_to_solve", bayes, ce)], bayes, ce, margin
    )


def judge_c2(bayes: ArmRuns, ce: ArmRuns) -> Verdict:
    """Judged on a share of runs: unfinished runs under today's reading (training stops once the
    early-stopping rule fires), runs with a collapse under the paper's (no early stop: every run is
    unfinished by construction). not reproduced: no run of either arm collapses (the claim's
    perturbations never occur); holds: both arms have a run that collapses and TOST at ALPHA finds
    the shares equal, i.e. the TOST_LEVEL CI of bayes − ce lies within ±SHARE_MARGIN; does not hold:
    that CI lies wholly outside ±SHARE_MARGIN; else inconclusive. Fisher's exact test on the share
    and collapses per run (Mann–Whitney U) are reported beside it."""
    share = compare("unfinished" if bayes.config.early_stop_window else "collapsed", bayes, ce)
    comparisons = [share, compare("collapses", bayes, ce)]
    struck = [bool(arm.values("collapsed").any()) for arm in (bayes, ce)]
    if not any(struck):
        verdict = "not reproduced"
    elif equivalent(share.judged, SHARE_MARGIN):
        verdict = "holds" if all(struck) else "inconclusive"
    else:
        verdict = "does not hold" if beyond(share.judged, SHARE_MARGIN) else "inconclusive"
    return _verdict(verdict, comparisons, bayes, ce, SHARE_MARGIN)


def judge_c3(bayes: ArmRuns, ce: ArmRuns) -> Verdict:
    """holds: TOST at ALPHA on mean_train_return, i.e. the TOST_LEVEL CI of bayes − ce lies within
    ±RETURN_MARGIN × limit; does not hold: that CI lies wholly outside ±RETURN_MARGIN × limit; else
    inconclusive."""
    margin = RETURN_MARGIN * bayes.config.limit
    returns = compare("mean_train_return", bayes, ce)
    return _verdict(_equivalence(returns, margin), [returns], bayes, ce, margin)


def judge_c4(bayes: ArmRuns, ce: ArmRuns) -> Verdict:
    """A claim of "markedly more" has to clear the no-difference margin, not just 0. holds: the lower end of the
    TOST_LEVEL CI of bayes − ce in goals_first30 (its one-sided bound at ALPHA) lies above
    +GOALS_MARGIN and Mann–Whitney p < ALPHA; does not hold: the upper end lies below +GOALS_MARGIN
    (a gain shown smaller than the margin, a significant one included); else inconclusive. goals_all
    is reported beside it."""
    early, whole = compare("goals_first30", bayes, ce), compare("goals_all", bayes, ce)
    low, high = early.judged
    if low > GOALS_MARGIN and early.p < ALPHA:
        verdict = "holds"
    else:
        verdict = "does not hold" if high < GOALS_MARGIN else "inconclusive"
    return _verdict(verdict, [early, whole], bayes, ce, GOALS_MARGIN, one_sided=True)


RULE_CONSTANTS = {
    "ALPHA": f"{ALPHA:g}",
    "TOST_LEVEL": f"{TOST_LEVEL:.0%}",
    "RETURN_MARGIN": f"{RETURN_MARGIN:g}",
    "SHARE_MARGIN": f"{SHARE_MARGIN:g}",
    "GOALS_MARGIN": f"{GOALS_MARGIN:g}",
    "ABLATION_METRIC": "metric",
    "DYNAMIC_TIE": "`episodes`",
}
"""How each constant named in a rule's docstring reads in RESULTS.md."""


@dataclass(frozen=True)
class Claim:
    """A claim of the paper (ALGORITHM.md §7): where it is tested and the rule that judges it."""

    id: str
    statement: str
    settings: tuple[Setting, ...]
    judge: Callable[[ArmRuns, ArmRuns], Verdict]

    @property
    def rule(self) -> str:
        return rule_text(self.judge)


def rule_text(judge: Callable) -> str:
    """A verdict rule as RESULTS.md prints it: the judge's docstring with the constants filled in."""
    assert judge.__doc__ is not None  # every judge states its rule
    text = " ".join(judge.__doc__.split())
    return re.sub(r"\b[A-Z][A-Z_]+\b", lambda m: RULE_CONSTANTS.get(m.group(), m.group()), text)


_WINDOW = Config.for_task("cartpole-200").early_stop_window
TODAY = Setting(
    "cartpole-200",
    "naive",
    (("early_stop_window", _WINDOW),),
    "today's reading: training stops once the early-stopping rule fires",
)
PAPER = Setting(
    "cartpole-200",
    "naive",
    (("early_stop_window", 0), ("total_steps", PAPER_READING_STEPS)),
    "the paper's reading: its rule (average ≥ 490, 10 times in a row), kept with 200-step episodes, "
    "never fires: no early stop, a fixed budget",
)
CLAIMS = (
    Claim(
        "C1",
        "bayes and ce do not differ significantly in best or average case",
        (Setting("cartpole", "naive"), Setting("cartpole-200", "naive")),
        judge_c1,
    ),
    Claim(
        "C2",
        "with the 200-step limit both suffer perturbations; unfinished runs about equally frequent",
        (TODAY, PAPER),
        judge_c2,
    ),
    Claim(
        "C3",
        "with the time-limit bootstrap fix bayes and ce give the same average reward",
        (Setting("cartpole", "bootstrap"),),
        judge_c3,
    ),
    Claim(
        "C4",
        "bayes reaches the flag markedly more often per episode than ce, especially early",
        (Setting("mountaincar-goals", None),),
        judge_c4,
    ),
)


def judge(claim: Claim, bayes: ArmRuns, ce: ArmRuns | None) -> Verdict:
    if ce is None:
        return Verdict("not run (no ce arm)")
    if min(len(bayes.runs), len(ce.runs)) < 2:
        return Verdict("inconclusive (n < 2)")
    return claim.judge(bayes, ce)


def too_few(*arms: ArmRuns) -> str:
    """What a table or summary line says in place of a comparison one of `arms` has too few seeds for."""
    return f"n = {min(len(arm.runs) for arm in arms)}: too few seeds for a comparison"


def flips(verdict: str, reference: str) -> str:
    """A sensitivity arm's verdict against its setting's reference verdict: "yes" if it turns holds
    into does not hold (or back), "unclear" if it moves to or from inconclusive, "no" if the same."""
    if verdict == reference:
        return "no"
    return "yes" if {verdict, reference} == {"holds", "does not hold"} else "unclear"
