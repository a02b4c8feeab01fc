"""The RESULTS.md report of a suite directory: claims table, figures, baselines, sensitivity."""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import numpy as np

from . import figures
from .analysis import (ALPHA, CLAIMS, METRICS, PER_RUN, REGENERATE, Arm, Comparison, setting_name, bayes_ce_pairs,
                       demonstrator_return, group_arms, judge, load_runs, steps_to_threshold)
from .envs import get_task
from .files import write_text
from .stats import Summary


def _cell(comparisons: list[Comparison], part: Callable[[Comparison], str]) -> str:
    return "<br>".join(part(c) for c in comparisons) or "—"


def _flips(verdict: str, reference: str) -> str:
    if verdict == reference:
        return "no"
    return "yes" if {verdict, reference} == {"holds", "does not hold"} else "unclear"


def _claim_rows(arms: list[Arm]) -> tuple[list[str], list[str]]:
    """The claims table's rows (the reference pair of each claim's setting) and the sensitivity
    table's rows (every other bayes arm of that setting, against its ce arm)."""
    claims, sensitivity = [], []
    for claim in CLAIMS:
        for task, timeout in claim.settings:
            pairs = bayes_ce_pairs(arms, task, timeout)
            if not pairs or pairs[0][1] is None:
                claims.append(f"| {claim.id} | {setting_name(task, timeout)} | {claim.statement} | — | — | — "
                              "| not run |")
                continue
            reference = judge(claim, *pairs[0])[0]
            for i, (bayes, ce) in enumerate(pairs):
                verdict, comparisons = judge(claim, bayes, ce)
                per_arm = _cell(comparisons, lambda c: f"{c.metric}: bayes {c.bayes.format(2)} · ce {c.ce.format(2)}")
                if i == 0:
                    diff = _cell(comparisons, lambda c: f"{c.diff[0]:.2f} … {c.diff[1]:.2f}")
                    test = _cell(comparisons, lambda c: f"{c.test} p = {c.p:.3g}")
                    claims.append(f"| {claim.id} | {bayes.setting} (n = {len(bayes.runs)}, {len(ce.runs)}) | "
                                  f"{claim.statement} | {per_arm} | {diff} | {test} | **{verdict}** |")
                else:
                    sensitivity.append(f"| {claim.id} | {bayes.label} | {ce.name if ce else '—'} | {per_arm} | "
                                       f"{verdict} | {_flips(verdict, reference)} |")
    return claims, sensitivity


def _baseline_row(arm: Arm) -> str:
    steps = [steps_to_threshold(r) for r in arm.runs]
    reached = sum(s is not None for s in steps)  # the median is finite once more than half reached it
    median = f"{np.median([np.inf if s is None else s for s in steps]):,.0f}" if 2 * reached > len(steps) else "—"
    final = Summary.of(arm.values("final_eval"))
    source, teacher, beats = "—", "none", "—"
    if arm.config["expert_loss"] != "none":
        demonstrator = np.mean([demonstrator_return(r) for r in arm.runs])
        source = f"{arm.config['demo_episodes']} × {arm.config['expert']}"
        teacher, beats = f"{demonstrator:.1f}", f"{final.mean - demonstrator:+.1f}"
    return (f"| {arm.setting} | {arm.name} | {len(arm.runs)} | {source} | {final.format()} | "
            f"{Summary.of(arm.values('mean_train_return')).format()} | {median} ({reached}/{len(steps)}) | "
            f"{teacher} | {beats} |")


def _figures(arms: list[Arm], figures_dir: Path, markdown_dir: Path) -> list[str]:
    """Per setting: learning curves of every arm; the best, average and worst run of each arm of
    its reference bayes–ce pair (of every arm if it has none). Returns the markdown links."""
    links = []
    for setting in sorted({a.setting for a in arms}):
        members = [a for a in arms if a.setting == setting]
        task, timeout = setting.split("/")
        goals = get_task(task).goal_count
        column, score = ("goals", "goals_all") if goals else ("plain_return", "mean_train_return")
        runs = {a.name: [(f"seed {r.config.seed}", r.column(column), PER_RUN[score](r)) for r in a.runs]
                for a in members}
        pair = next((p for p in bayes_ce_pairs(members, task, timeout) if p[1] is not None), members)
        paths = figures.setting_figures(setting, runs, [a.name for a in pair], score,
                                        "flags reached per episode" if goals else "plain-env return per episode",
                                        figures_dir / setting.replace("/", "-"))
        links += [f"![{setting} {p.stem}]({Path(os.path.relpath(p, markdown_dir)).as_posix()})" for p in paths]
    return links


def report(suite_dir: str | os.PathLike, out_markdown: str | os.PathLike, figures_dir: str | os.PathLike) -> str:
    """Write the RESULTS-style markdown for every complete run under `suite_dir` (and its figures
    into `figures_dir`, linked relative to `out_markdown`); return the markdown."""
    out_markdown, figures_dir = Path(out_markdown), Path(figures_dir)
    arms = group_arms(load_runs(suite_dir))
    claims, sensitivity = _claim_rows(arms)
    wall = sum(r.metrics[-1]["wall_time"] for a in arms for r in a.runs if r.metrics)
    doc = ["# Results: the paper's claims over seeds", "",
           f"{sum(len(a.runs) for a in arms)} complete runs in {len(arms)} arms under `{suite_dir}`; "
           f"total training wall time {wall / 60:.1f} min (sum over runs). Regenerate with:", "",
           f"    {REGENERATE}", "", "## Claims", "",
           "Metrics and rules were fixed before the runs (`dqfd_bc_keras/analysis.py`). Per arm: mean "
           "[95% percentile-bootstrap CI] over seeds; Δ is the 95% CI of the difference of means bayes − ce; "
           f"tests are two-sided at α = {ALPHA}.", ""]
    doc += [f"- `{name}`: {text}." for name, text in METRICS.items()]
    doc += [f"- {c.id} ({', '.join(setting_name(*s) for s in c.settings)}): {c.rule}" for c in CLAIMS]
    doc += ["", "| claim | setting (seeds bayes, ce) | the paper | metric per arm | Δ bayes − ce | test | verdict |",
            "| --- | --- | --- | --- | --- | --- | --- |", *claims, "", "## Figures", "",
            *_figures(arms, figures_dir, out_markdown.parent), "", "## Baselines", "",
            "Final evaluation on the plain env against the mean plain return of the demonstrations the run "
            "started from (for cartpole-200 those are capped at 200 steps, the evaluation at 500).", "",
            "| setting | arm | seeds | demos | final eval | mean training return | steps to threshold "
            "(median, reached) | demonstrator | beats it by |",
            "| --- | --- | --- | --- | --- | --- | --- | --- | --- |", *map(_baseline_row, arms), "",
            "## Sensitivity", "",
            "Each further bayes arm of a claim's setting (σ0², demonstrator, …) judged against its ce arm "
            "with the same rule; *flips*: holds ↔ does not hold against the reference pair's verdict (yes), the "
            "same verdict (no), or a change to or from inconclusive (unclear).", "",
            "| claim | bayes arm | ce arm | metric per arm | verdict | flips |",
            "| --- | --- | --- | --- | --- | --- |",
            *(sensitivity or ["| — | no sensitivity arms | | | | |"]), ""]
    text = "\n".join(doc)
    write_text(out_markdown, text)
    return text
