"""The opening of RESULTS.md: what holds, what does not, what is unknown and what has not run,
each with its number, computed from the same runs and files as the tables below it, so it
regenerates with them and can say nothing they do not show.
"""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

from dqfd_bc_keras.experiments.ablations import ablation_pairs, dynamic_default, judge_ablation
from dqfd_bc_keras.experiments.arms import ArmRuns, find_arm
from dqfd_bc_keras.experiments.claims import (
    CLAIMS,
    GOALS_MARGIN,
    RETURN_MARGIN,
    SHARE_MARGIN,
    flips,
    judge,
    too_few,
)
from dqfd_bc_keras.experiments.efficiency import EFFICIENCY_FILE, SB3_METHOD, load, ratio_ci
from dqfd_bc_keras.experiments.estimators import CALIBRATION_FILE, meets_goal
from dqfd_bc_keras.experiments.grid import BC_ALONE, DQN, collect, effect
from dqfd_bc_keras.experiments.replicate import replicated
from dqfd_bc_keras.experiments.stats import Summary
from dqfd_bc_keras.experiments.suites import (
    ALL,
    GRID_SEEDS,
    GRID_TASKS,
    SUITES,
    efficiency_arm,
    efficiency_tasks,
)

UNKNOWN = ("inconclusive", "not reproduced")


def _claims(arms: list[ArmRuns]) -> dict[str, list[str]]:
    """Each claim setting's reference verdict in one line, filed under holds / does not hold / unknown."""
    filed: dict[str, list[str]] = {"holds": [], "does not hold": [], "unknown": [], "not run": []}
    for claim in CLAIMS:
        for setting in claim.settings:
            where = f"{claim.id} on {setting.name}" + (f" ({setting.reading.split(':')[0]})" if setting.reading else "")
            pairs = setting.pairs(arms)
            ce = pairs[0][1] if pairs else None
            if ce is None:
                filed["not run"].append(where)
                continue
            bayes = pairs[0][0]
            result = judge(claim, bayes, ce)
            if not result.comparisons:  # a sweep under way or cut off, or `run quick --seeds 1`
                filed["unknown"].append(f"{where}: **inconclusive**: {too_few(bayes, ce)}.")
                continue
            c = result.comparisons[0]
            margin = (
                f"±{RETURN_MARGIN * bayes.runs[0].config.limit:g}"
                if claim.id in ("C1", "C3")
                else f"±{SHARE_MARGIN:g}"
                if claim.id == "C2"
                else f"+{GOALS_MARGIN:g}"
            )
            assert isinstance(c.bayes, Summary) and isinstance(c.ce, Summary)  # a judged metric is uncensored
            interval = "—" if c.tost is None else f"{c.tost[0]:.2f} … {c.tost[1]:.2f}"
            power = "" if result.power is None else f", power {result.power:.2f}"
            line = (
                f"{where}: **{result.verdict}**: `{c.metric}` bayes {c.bayes.mean:.4g} · ce {c.ce.mean:.4g}, "
                f"90% CI of bayes − ce {interval} against {margin} ({len(bayes.runs)} and {len(ce.runs)} seeds"
                f"{power})."
            )
            filed["unknown" if result.verdict.startswith(UNKNOWN) else result.verdict].append(line)
    return filed


def _sensitivity(arms: list[ArmRuns]) -> list[str]:
    """How often a further bayes arm of a claim's setting (σ0², demonstrator, estimator, …) judged
    against its ce arm changes the setting's reference verdict (the sensitivity table's *flips*)."""
    moves = []
    for claim in CLAIMS:
        for setting in claim.settings:
            pairs = setting.pairs(arms)
            if not pairs or pairs[0][1] is None:
                continue
            reference = judge(claim, *pairs[0]).verdict
            moves += [flips(judge(claim, bayes, ce).verdict, reference) for bayes, ce in pairs[1:] if ce is not None]
    if not moves:
        return []
    return [
        f"Sensitivity (each further bayes arm of a claim's setting against its ce arm): the verdict flips "
        f"between holds and does not hold in {moves.count('yes')} of {len(moves)}, moves to or from "
        f"inconclusive in {moves.count('unclear')}, stays in {moves.count('no')}."
    ]


def _ablations(arms: list[ArmRuns]) -> list[str]:
    verdicts = Counter(judge_ablation(ablated, full).verdict for _, ablated, full in ablation_pairs(arms))
    if not verdicts:
        return []
    counts = ", ".join(f"{verdict} in {n}" for verdict, n in sorted(verdicts.items()))
    return [
        f"Ablations (one part of the Bayesian machinery off, against the full arm): {counts}, "
        f"of {sum(verdicts.values())}."
    ]


def _efficiency(arms: list[ArmRuns], directory: Path) -> list[str]:
    """SB3's median ÷ bayes's per task (the efficiency table) and, where the archive holds more
    seeds of the same bayes arm, the same ratio over all of them."""
    loaded = load(directory / EFFICIENCY_FILE)
    if loaded is None:
        return []
    _, steps = loaded
    sb3 = {a.task: a.steps for a in steps if a.method == SB3_METHOD}
    lines = []
    for a in steps:
        if a.method != "bayes" or a.task not in sb3:
            continue
        point, low, high = ratio_ci(sb3[a.task], a.steps)
        text = (
            f"{a.task}: SB3 ÷ bayes {point:.1f}× [{low:.1f}×, {high:.1f}×] over {a.steps.size} seeds, the "
            f"{a.target:g}× goal {'met' if point >= a.target else 'not met'}"
        )
        run = find_arm(arms, efficiency_arm(a.task, "bayes", efficiency_tasks()[a.task]).config(0))
        if run is not None and len(run.runs) > a.steps.size:
            more = ratio_ci(sb3[a.task], run.values("interactions_to_threshold"))
            text += (
                f"; over all {len(run.runs)} archived seeds of the same arm {more[0]:.1f}× [{more[1]:.1f}×, "
                f"{more[2]:.1f}×], goal {'met' if more[0] >= a.target else 'not met'}"
            )
        lines.append(text + ".")
    return lines


def _estimators(directory: Path) -> list[str]:
    path = directory / CALIBRATION_FILE
    if not path.is_file():
        return []
    summary = json.loads(path.read_text())
    estimators = sorted({u for entries in summary["tasks"].values() for u in entries})
    met = [u for u in estimators if all(meets_goal(entries[u]) for entries in summary["tasks"].values())]
    return [
        f"σ² estimators that meet the calibration goal (≥ {summary['goal_ratio']:g}× the on-demo σ² − σ0² off "
        f"the demonstrations, on every task): {len(met)} of {len(estimators)}, {', '.join(met) or 'none'}."
    ]


def _grid(arms: list[ArmRuns], directory: Path) -> list[str]:
    lines = []
    for task in GRID_TASKS:
        cells, table = collect(arms, directory, task)
        dqn = table.get(DQN, {})
        pairs = [
            (entries[c], dqn[c])
            for method, entries in table.items()
            if method not in (DQN, BC_ALONE)
            for c in cells
            if c in entries and c in dqn
        ]
        if not pairs:
            continue
        verdicts = [effect(entry, baseline) for entry, baseline in pairs]
        seeds = sorted({len(entry.steps) for entry, _ in pairs})
        partial = (
            ""
            if seeds[0] >= GRID_SEEDS
            else (
                f" So far from {seeds[0]}{'' if len(seeds) == 1 else f'–{seeds[-1]}'} of the {GRID_SEEDS} planned "
                f"seeds per pair: read these as provisional."
            )
        )
        lines.append(
            f"Demonstration quality × quantity ({task}): a method with demonstrations is faster than DQN "
            f"in {verdicts.count('helps')} of {len(verdicts)} (cell, method) pairs, slower in "
            f"{verdicts.count('hurts')}, unclear in {verdicts.count('unclear')}.{partial}"
        )
    return lines


def _replications(arms: list[ArmRuns], directory: Path) -> list[str]:
    found = replicated(arms, directory)
    if not found:
        return []
    tests = [c for *_, comparisons in found for c in comparisons]
    differ = [
        f"{archived.label}: {c.metric} (p = {c.p:.2g})"
        for archived, _, comparisons in found
        for c in comparisons
        if c.p < 0.05
    ]
    return [
        f"Replications at fresh seeds: {len(found)} arms, {len(tests)} rank tests, "
        f"{len(differ)} with p < 0.05 (uncorrected; {0.05 * len(tests):.1f} expected by chance if none differ)"
        f"{': ' + '; '.join(differ) if differ else ''}."
    ]


def _not_run(arms: list[ArmRuns]) -> list[str]:
    """Per suite of `run all`: how many of its arms have no run here, and how many seeds are missing."""
    lines = []
    for name in ALL:
        missing, seeds = 0, 0
        for a in SUITES[name]:
            found = find_arm(arms, a.config(0))
            have = 0 if found is None else sum(r.config.seed < a.seeds for r in found.runs)
            missing += have == 0
            seeds += a.seeds - have
        if seeds:
            lines.append(f"`{name}`: {missing} of {len(SUITES[name])} arms not run, {seeds} planned runs missing.")
    return lines


def summary(arms: list[ArmRuns], directory: Path) -> list[str]:
    """The summary's lines (markdown), computed from `arms` and the suite `directory`'s files."""
    claims = _claims(arms)
    choice, _ = dynamic_default(arms)
    found = [
        *_sensitivity(arms),
        *_ablations(arms),
        *_efficiency(arms, directory),
        *_estimators(directory),
        *_grid(arms, directory),
        *_replications(arms, directory),
        *([f"Dynamic demonstrations: the pre-registered rule picks `{choice}` as the default."] if choice else []),
    ]
    lines = [
        "## Summary",
        "",
        "Computed from the tables below (it regenerates with them); the numbers are the "
        "judged metric's means, the TOST interval (90% CI) and the margin of each claim's rule.",
        "",
    ]
    for title, key in (("Holds", "holds"), ("Does not hold", "does not hold"), ("Unknown", "unknown")):
        lines += [f"**{title}**", "", *(f"- {line}" for line in claims[key] or ["none"]), ""]
    lines += [
        "**Measured beside the claims**",
        "",
        *(f"- {line}" for line in found or ["nothing"]),
        "- Studies with their own archives and reports: the Bayesian loss with σ0² below the variance cap "
        "([SIGMA0.md](SIGMA0.md)), MinAtar Breakout on frames ([PIXELS.md](PIXELS.md)) and all five MinAtar "
        "games against DQN and SB3 ([MINATAR.md](MINATAR.md)).",
        "",
    ]
    gaps = [*(f"claim {where}" for where in claims["not run"]), *_not_run(arms)]
    lines += ["**Not run yet**", "", *(f"- {line}" for line in gaps or ["nothing: every planned run is here"]), ""]
    return lines
