"""The paper's claims (ALGORITHM.md §7, C1–C4) judged over seeds; `report.py` writes them up.

Every margin and verdict rule is a constant or docstring here (the metrics they read are in
metrics.py, the arms they compare in arms.py), fixed before any result is looked at, so
RESULTS.md can quote them.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.experiments.arms import ArmRuns, Setting, common_seeds
from dqfd_bc_keras.experiments.lab_settings import lab_settings
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


# --- ablations and the dynamic-demonstration default (docs/PREREGISTRATION.md §2, §6) -------
ABLATED = {"dynamic_demos": "off", "bayes_prior": False, "mc_dropout": False}
"""The part each ablation switches off, and its value when off."""
ABLATION_MARGINS = {"mean_train_return": RETURN_MARGIN, "goals_first30": None}
"""The metrics an ablation can be judged on (a task's `ablation_metric`, lab_settings.py) and each one's
margin: a fraction of the limit, or None for GOALS_MARGIN."""


def ablation_pairs(arms: list[ArmRuns]) -> list[tuple[str, ArmRuns, ArmRuns]]:
    """(switched-off part, ablated arm, full arm): arms equal in every field but one part of ABLATED,
    which the ablated arm switches off and the full arm has as the preset does."""

    def without(arm: ArmRuns, key: str) -> dict:
        return {k: v for k, v in arm.fields.items() if k != key}

    return [
        (key, *common_seeds(ablated, full))
        for key, off in ABLATED.items()
        for ablated in arms
        if ablated.fields[key] == off and lab_settings(ablated.config.task).ablation_metric
        for full in arms
        if full.fields[key] == _preset(full, key) and without(full, key) == without(ablated, key)
    ]


def _preset(arm: ArmRuns, key: str) -> object:
    return Config.for_task(arm.config.task).to_dict()[key]


def judge_ablation(ablated: ArmRuns, full: ArmRuns) -> Verdict:
    """On the task's ABLATION_METRIC (mean training return within ±RETURN_MARGIN × limit; goals over
    the first 30 episodes within ±GOALS_MARGIN), the TOST_LEVEL CI of full − ablated: no measurable
    contribution if it lies within ±margin; contributes if it lies wholly above +margin; hurts if
    wholly below −margin; else inconclusive."""
    if min(len(full.runs), len(ablated.runs)) < 2:
        return Verdict("inconclusive (n < 2)")
    metric = lab_settings(full.config.task).ablation_metric
    assert metric is not None  # ablations are run on the tasks that name their metric
    fraction = ABLATION_MARGINS[metric]
    margin = GOALS_MARGIN if fraction is None else fraction * full.config.limit
    comparison = compare(metric, full, ablated)
    low, high = comparison.judged
    if equivalent(comparison.judged, margin):
        verdict = "no measurable contribution"
    else:
        verdict = "contributes" if low > margin else "hurts" if high < -margin else "inconclusive"
    return _verdict(verdict, [comparison], full, ablated, margin)


DYNAMIC_MODES = ("episodes", "rollouts")
DYNAMIC_TIE = "episodes"
"""At a tie, the reading that costs no interaction (and is the paper's literal wording)."""


def dynamic_default(arms: list[ArmRuns]) -> tuple[str | None, list[tuple[ArmRuns, ArmRuns, str]]]:
    """The default of `Config.dynamic_demos` by the pre-registered rule: per (task, loss) pair of
    arms equal but for the mode, on the seeds both ran, the mode with the lower median interactions_to_threshold (∞ for
    never) wins (a tie wins for neither); the mode winning ≥ 3 of the 4 pairs is the default, else
    DYNAMIC_TIE."""

    # Returns the default (None until all 4 pairs have run) and each pair with its winner.
    def rest(arm: ArmRuns) -> dict:
        return {k: v for k, v in arm.fields.items() if k != "dynamic_demos"}

    pairs = []
    for first in arms:
        if first.config.dynamic_demos != DYNAMIC_MODES[0]:
            continue
        for second in arms:
            if second.config.dynamic_demos == DYNAMIC_MODES[1] and rest(second) == rest(first):
                pair = common_seeds(first, second)
                medians = [np.median(a.values("interactions_to_threshold")) for a in pair]
                winner = "tie" if medians[0] == medians[1] else DYNAMIC_MODES[int(medians[1] < medians[0])]
                pairs.append((*pair, winner))
    if len(pairs) < 4:
        return None, pairs
    wins = {mode: sum(w == mode for *_, w in pairs) for mode in DYNAMIC_MODES}
    return next((m for m, n in wins.items() if n >= 3), DYNAMIC_TIE), pairs
