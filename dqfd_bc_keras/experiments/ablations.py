"""The ablations and the default of dynamic demonstrations, judged over seeds as pre-registered
(docs/PREREGISTRATION.md §2, §6); `sections.py` writes them up. Like claims.py's, every rule is a
constant or docstring here, so RESULTS.md can quote it.
"""

from __future__ import annotations

import numpy as np

from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.experiments.arms import ArmRuns, common_seeds
from dqfd_bc_keras.experiments.claims import GOALS_MARGIN, RETURN_MARGIN, Verdict, _verdict, compare
from dqfd_bc_keras.experiments.lab_settings import lab_settings
from dqfd_bc_keras.experiments.stats import equivalent

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
