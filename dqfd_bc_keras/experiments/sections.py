"""RESULTS.md's sections: the claims and sensitivity rows, the figures, the dynamic default and the
ablations from the grouped arms; the provenance and wall time of the runs. report.py assembles them
(and the studies reuse the provenance and wall-time parts).
"""

from __future__ import annotations

import json
import os
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import numpy as np

from dqfd_bc_keras.envs.make import get_task
from dqfd_bc_keras.experiments import figures
from dqfd_bc_keras.experiments.ablations import ablation_pairs, dynamic_default, judge_ablation
from dqfd_bc_keras.experiments.arms import ArmRuns, bayes_ce_pairs, preset_distance
from dqfd_bc_keras.experiments.claims import (
    CLAIMS,
    Comparison,
    flips,
    judge,
    rule_text,
    too_few,
)
from dqfd_bc_keras.experiments.grid import grid_only
from dqfd_bc_keras.experiments.metrics import EARLY_EPISODES, PER_RUN, finished
from dqfd_bc_keras.experiments.stats import CensoredSummary, Summary

SMOOTH_ABOVE, SMOOTH_WINDOW = 150, 10
"""The mean curves of settings whose runs are longer than 150 episodes (MountainCar's hundreds) are
drawn as trailing means of 10 episodes, said on the axis: a few flags per episode, over hundreds of
episodes, are unreadable raw. Single runs and the early-episode zoom are drawn raw."""


def _cell(comparisons: list[Comparison], part: Callable[[Comparison], str]) -> str:
    return "<br>".join(part(c) for c in comparisons) or "—"


def claim_rows(arms: list[ArmRuns]) -> tuple[list[str], list[str]]:
    """The claims table's rows (the reference pair of each claim's setting) and the sensitivity
    table's rows (every other bayes arm of that setting, against its ce arm)."""
    claims, sensitivity = [], []
    for claim in CLAIMS:
        for setting in claim.settings:
            where = f"{setting.name}<br>{setting.reading}" if setting.reading else setting.name
            pairs = setting.pairs(arms)
            if not pairs or pairs[0][1] is None:
                claims.append(f"| {claim.id} | {where} | {claim.statement} | — | — | — | — | not run |")
                continue
            reference = judge(claim, *pairs[0]).verdict
            for i, (bayes, ce) in enumerate(pairs):
                result = judge(claim, bayes, ce)
                per_arm = (
                    too_few(bayes, ce)
                    if ce is not None and not result.comparisons
                    else _cell(
                        result.comparisons, lambda c: f"{c.metric}: bayes {c.bayes.format(2)} · ce {c.ce.format(2)}"
                    )
                )
                if i == 0:
                    assert ce is not None  # the reference pair has its ce arm (checked above)
                    diff = _cell(result.comparisons, lambda c: c.interval())
                    test = _cell(result.comparisons, lambda c: f"{c.test} p = {c.p:.3g}")
                    power = "—" if result.power is None else f"sd {result.sd:.3g} · power {result.power:.2f}"
                    claims.append(
                        f"| {claim.id} | {where} | {claim.statement} | {per_arm} | {diff} | {test} | "
                        f"{len(bayes.runs)}, {len(ce.runs)} · {power} | **{result.verdict}** |"
                    )
                else:
                    sensitivity.append(
                        f"| {claim.id} | {bayes.label} | {ce.name if ce else '—'} | {per_arm} | "
                        f"{result.verdict} | {flips(result.verdict, reference)} |"
                    )
    return claims, sensitivity


def figure_links(arms: list[ArmRuns], figures_dir: Path, markdown_dir: Path) -> list[str]:
    """Per setting: learning curves of the preset arms (the paper's and the baselines'); the best,
    average and worst run of each arm of its reference bayes–ce pair (of every arm if it has
    none); and, where a setting has variants (sensitivity, estimators), their curves beside the
    reference pair (the grid's own arms are its heatmaps). A goal-count setting adds the first
    EARLY_EPISODES episodes (C4's "early") zoomed in. Returns the markdown links."""
    links = []
    for setting in sorted({a.setting for a in arms}):
        members = [a for a in arms if a.setting == setting]
        task, timeout = setting.split("/")
        goals = get_task(task).goal_count
        column, score = ("goals", "goals_all") if goals else ("plain_return", "mean_train_return")
        ylabel = "flags reached per episode" if goals else "plain-env return per episode"
        window = SMOOTH_WINDOW if max(len(r.metrics) for a in members for r in a.runs) > SMOOTH_ABOVE else 1
        zoom = EARLY_EPISODES if goals else None
        runs = {
            a.name: [
                figures.Trace(f"seed {r.config.seed}", r.column(column), PER_RUN[score](r), finished(r)) for r in a.runs
            ]
            for a in members
        }
        pair = next((p for p in bayes_ce_pairs(members, task, timeout) if p[1] is not None), members)
        main = [a.name for a in members if preset_distance(a) == 0] or list(runs)
        stem = figures_dir / setting.replace("/", "-")
        cases = [a.name for a in pair if a is not None and a.name in main] or main
        paths = figures.setting_figures(setting, {n: runs[n] for n in main}, cases, score, ylabel, stem, window, zoom)
        variants = [a.name for a in members if a.name not in main and not grid_only(a.config)]
        if variants:
            path = stem.with_name(f"{stem.name}-variants.png")
            shown = [a.name for a in pair if a is not None and a.name in main] + variants
            figures.learning_curves(f"{setting}, variants", {n: runs[n] for n in shown}, ylabel, path, window, zoom)
            paths.append(path)
        links += [f"![{setting} {p.stem}]({Path(os.path.relpath(p, markdown_dir)).as_posix()})" for p in paths]
    return links


def _commit(commit: str | None, dirty: bool = False) -> str:
    return ("unknown" if commit is None else f"`{commit[:12]}`") + (" (dirty)" if dirty else "")


def sweeps_section(suite_dir: Path) -> list[str]:
    """The sweeps that produced the runs (experiments.SWEEP_LOG): suite, runs, workers, wall time, code."""
    entries = [
        json.loads(line)
        for log in sorted(suite_dir.rglob("sweeps.jsonl"))
        for line in log.read_text().splitlines()
        if line.strip()
    ]
    if not entries:
        return ["No sweep log (sweeps.jsonl) under the suite directory."]
    rows = [
        f"| {e['suite']}{' (interrupted)' if e.get('interrupted') else ''} | {e['seeds']} | {e['runs']} | "
        f"{e['workers']} × {e['backend']} | "
        f"{e['seconds'] / 60:.1f} min | {e['ended']} | {_commit(e.get('code_commit'), e.get('dirty', False))} |"
        for e in entries
    ]
    return [
        "Each sweep as logged by the runner (runs it ran, not those it found complete).",
        "",
        "| suite | seeds | runs | workers | wall time | ended | code commit |",
        "| --- | --- | --- | --- | --- | --- | --- |",
        *rows,
        "",
        f"Sum: {sum(e['seconds'] for e in entries) / 60:.1f} min of wall time.",
    ]


def provenance_line(arms: list[ArmRuns]) -> str:
    """Which commits of the code and of the claims rules the runs came from (provenance.json);
    runs trained from uncommitted changes are named: their commit does not reproduce them."""
    runs = [r for a in arms for r in a.runs]
    if not runs:
        return "Provenance: no runs."

    def commits(key: str) -> str:
        counts = Counter(getattr(r.provenance, key) for r in runs)
        return ", ".join(
            f"{_commit(c)} ({n} run{'s' * (n > 1)})"
            for c, n in sorted(counts.items(), key=lambda item: (item[0] is None, item[0] or ""))
        )

    dirty = [f"{a.label} seed {r.config.seed}" for a in arms for r in a.runs if r.provenance.dirty]
    flag = (
        f" **{len(dirty)} run(s) trained from uncommitted changes** (their commit does not reproduce them): "
        f"{', '.join(dirty)}."
        if dirty
        else ""
    )
    return (
        f"Provenance (provenance.json of each run): code {commits('code_commit')}; claims rules "
        f"{commits('rules_commit')}.{flag}"
    )


def dynamic_section(arms: list[ArmRuns]) -> list[str]:
    """The two readings of dynamic demonstrations side by side, and the default the rule picks."""
    choice, pairs = dynamic_default(arms)
    if not pairs:
        return ["Not run: `python -m dqfd_bc_keras.experiments run dynamic` measures both readings."]
    rows = []
    for episodes, rollouts, winner in pairs:
        cells = []
        for arm in (episodes, rollouts):
            steps = CensoredSummary.of(arm.values("interactions_to_threshold"))
            extra = (
                np.mean([sum(u.new_transitions or 0 for u in r.dynamic_demos) for r in arm.runs])
                if arm.config.dynamic_demos == "rollouts"
                else 0.0
            )
            cells.append(f"{steps.format(0)} · {extra:,.0f} · {Summary.of(arm.values('final_eval')).format()}")
        rows.append(
            f"| {episodes.setting} {episodes.config.expert_loss} | {len(episodes.runs)}, "
            f"{len(rollouts.runs)} | {cells[0]} | {cells[1]} | {winner} |"
        )
    verdict = f"**default: `{choice}`**" if choice else f"not decided yet: {len(pairs)} of the rule's 4 pairs have run"
    return [
        f"Rule (docs/PREREGISTRATION.md §2): {rule_text(dynamic_default)}",
        "",
        "Per mode: interactions to threshold (median [95% CI], ∞ = never) · mean roll-out interactions per "
        "run · final evaluation.",
        "",
        "| setting, loss | seeds (episodes, rollouts) | `episodes` | `rollouts` | lower median |",
        "| --- | --- | --- | --- | --- |",
        *rows,
        "",
        f"Verdict: {verdict}.",
    ]


def ablations_section(arms: list[ArmRuns]) -> list[str]:
    """Each ablation (one part of the Bayesian machinery off) against the full arm."""
    pairs = ablation_pairs(arms)
    if not pairs:
        return ["Not run: `python -m dqfd_bc_keras.experiments run ablations`."]
    rows = []
    for key, ablated, full in pairs:
        result = judge_ablation(ablated, full)
        if not result.comparisons:
            rows.append(
                f"| {full.setting} {full.config.expert_loss} | {key} = {ablated.fields[key]} | "
                f"{len(full.runs)}, {len(ablated.runs)} | {too_few(full, ablated)} | — | — | — | "
                f"**{result.verdict}** |"
            )
            continue
        [c] = result.comparisons
        rows.append(
            f"| {full.setting} {full.config.expert_loss} | {key} = {ablated.fields[key]} | "
            f"{len(full.runs)}, {len(ablated.runs)} | {c.metric}: full {c.bayes.format(2)} · ablated "
            f"{c.ce.format(2)} | {c.interval()} | {c.test} p = {c.p:.3g} | {result.power:.2f} | "
            f"**{result.verdict}** |"
        )
    return [
        f"Rule (docs/PREREGISTRATION.md §6): {rule_text(judge_ablation)}",
        "",
        "| setting, loss | switched off | seeds (full, ablated) | metric per arm | Δ full − ablated | test "
        "| power | verdict |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
        *rows,
    ]
