"""The RESULTS.md report of a suite directory: claims table, figures, baselines, sensitivity."""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path

import numpy as np

from . import figures
from .claims import (ALPHA, CLAIMS, METRICS, PER_RUN, REGENERATE, ArmRuns, Comparison, setting_name, bayes_ce_pairs,
                       demonstrator_return, group_arms, judge, preset_distance, steps_to_threshold)
from ..envs import get_task
from ..files import write_text
from .data import load_runs
from .stats import Summary


SB3_LABEL = "SB3 DQN (rl-zoo3)"
"""The method name of the benchmark's Stable-Baselines3 rows."""
EFFICIENCY_FILE = "efficiency.json"
"""Written into the suite directory by benchmarks/bench_sample_efficiency.py; quoted by the report."""
DEMOS = (
    "Which demonstrations the paper's experiments get is not stated in the paper. Every arm that uses "
    "them starts from the same choice: **5 episodes of the imperfect scripted expert on CartPole** (push "
    "with the pole's angular velocity, ignoring its angle: 198 ± 37 over 100 episodes of CartPole-v1, against "
    "500 for the strong expert) and **10 episodes of the imperfect expert on MountainCar** (follows the velocity, "
    "always starting rightwards: −120.0 ± 3.3 against −106.4). Why: an imperfect teacher is the case the paper's Bayesian loss is built for (an uncertain "
    "π_bc should weigh less), a handful of episodes is the paper's \"few demonstrations\" regime, and a "
    "weak teacher leaves room to show that a method beats its demonstrator. Seed k of every arm records "
    "the same episodes (reset seed 1000 k), so bayes and ce differ in the loss only and the spread over "
    "seeds includes the draw of the demonstrations. The sensitivity suite swaps in the strong experts.")


SMOOTH_ABOVE, SMOOTH_WINDOW = 150, 10
"""Settings whose runs are longer than 150 episodes (MountainCar's 500–1,000) are drawn as trailing
means of 10 episodes: a flag count of 0–2 per episode is unreadable raw."""


def _cell(comparisons: list[Comparison], part: Callable[[Comparison], str]) -> str:
    return "<br>".join(part(c) for c in comparisons) or "—"


def _flips(verdict: str, reference: str) -> str:
    if verdict == reference:
        return "no"
    return "yes" if {verdict, reference} == {"holds", "does not hold"} else "unclear"


def _claim_rows(arms: list[ArmRuns]) -> tuple[list[str], list[str]]:
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


def _baseline_row(arm: ArmRuns) -> str:
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


def _figures(arms: list[ArmRuns], figures_dir: Path, markdown_dir: Path) -> list[str]:
    """Per setting: learning curves of the preset arms (the paper's and the baselines'); the best,
    average and worst run of each arm of its reference bayes–ce pair (of every arm if it has
    none); and, where a setting has variants (sensitivity), their curves beside the reference
    pair. Returns the markdown links."""
    links = []
    for setting in sorted({a.setting for a in arms}):
        members = [a for a in arms if a.setting == setting]
        task, timeout = setting.split("/")
        goals = get_task(task).goal_count
        column, score = ("goals", "goals_all") if goals else ("plain_return", "mean_train_return")
        ylabel = "flags reached per episode" if goals else "plain-env return per episode"
        window = SMOOTH_WINDOW if max(len(r.metrics) for a in members for r in a.runs) > SMOOTH_ABOVE else 1
        if window > 1:
            ylabel += f"\n(trailing mean of {window} episodes)"
        runs = {a.name: [(f"seed {r.config.seed}", figures.trailing_mean(r.column(column), window), PER_RUN[score](r))
                         for r in a.runs] for a in members}
        pair = next((p for p in bayes_ce_pairs(members, task, timeout) if p[1] is not None), members)
        main = [a.name for a in members if preset_distance(a) == 0] or list(runs)
        stem = figures_dir / setting.replace("/", "-")
        paths = figures.setting_figures(setting, {n: runs[n] for n in main}, [a.name for a in pair], score,
                                        ylabel, stem)
        variants = [a.name for a in members if a.name not in main]
        if variants:
            path = stem.with_name(f"{stem.name}-variants.png")
            shown = [a.name for a in pair if a.name in main] + variants
            figures.learning_curves(f"{setting}, variants",
                                    {n: [curve for _, curve, _ in runs[n]] for n in shown}, ylabel, path)
            paths.append(path)
        links += [f"![{setting} {p.stem}]({Path(os.path.relpath(p, markdown_dir)).as_posix()})" for p in paths]
    return links


def efficiency_table(rows: list[dict]) -> list[str]:
    """The sample-efficiency rows (bench_sample_efficiency.py, arms named "<task> <method>") as a
    markdown table, with how many times fewer steps than SB3's median each median is."""
    def steps(value: float | None, missing: str) -> str:
        return missing if value is None else f"{value:,.0f}"

    sb3 = {row["arm"].removesuffix(f" {SB3_LABEL}"): row["median_steps"] for row in rows
           if row["arm"].endswith(SB3_LABEL)}
    lines = ["| arm | median env steps to threshold | 95% CI | seeds that reached it | above it at the end "
             "| SB3's median ÷ this median |", "| --- | --- | --- | --- | --- | --- |"]
    for row in rows:
        ci = f"[{steps(row['ci'][0], '∞')}, {steps(row['ci'][1], '∞')}]"
        theirs, ours = sb3.get(row["arm"].split()[0]), row["median_steps"]
        ratio = f"{theirs / ours:.1f}×" if theirs and ours else "—"
        lines.append(f"| {row['arm']} | {steps(ours, 'not reached')} | {ci} | {row['reached']}/{row['seeds']} | "
                     f"{row['above_at_end']}/{row['seeds']} | {ratio} |")
    return lines


def _efficiency(suite_dir: Path) -> list[str]:
    path = suite_dir / EFFICIENCY_FILE
    if not path.is_file():
        return [f"Not run: `python benchmarks/bench_sample_efficiency.py --out {suite_dir}` writes {EFFICIENCY_FILE}."]
    return ["Env steps until the mean of a 10-episode greedy evaluation on the plain env (fixed seeds, every "
            "1,000 steps) first reaches the threshold (CartPole-v1 475, MountainCar-v0 −110); median and 95% "
            "bootstrap CI over seeds, a seed that never reaches it counted as ∞. *Above it at the end*: the "
            "final evaluation (ours: 20 episodes after the run; SB3: the last 10-episode evaluation).", "",
            *efficiency_table(json.loads(path.read_text()))]


def _sweeps(suite_dir: Path) -> list[str]:
    """The sweeps that produced the runs (experiments.SWEEP_LOG): suite, runs, workers, wall time."""
    entries = [json.loads(line) for log in sorted(suite_dir.rglob("sweeps.jsonl"))
               for line in log.read_text().splitlines() if line.strip()]
    if not entries:
        return ["No sweep log (sweeps.jsonl) under the suite directory."]
    rows = [f"| {e['suite']} | {e['seeds']} | {e['runs']} | {e['workers']} × {e['backend']} | "
            f"{e['seconds'] / 60:.1f} min | {e['ended']} |" for e in entries]
    return ["Each sweep as logged by the runner (runs it ran, not those it found complete).", "",
            "| suite | seeds | runs | workers | wall time | ended |", "| --- | --- | --- | --- | --- | --- |", *rows,
            "", f"Sum: {sum(e['seconds'] for e in entries) / 60:.1f} min of wall time on this 2-core machine."]


NOTES = ("<!-- notes: hand-written, kept when the report is regenerated -->", "<!-- /notes -->")


def _notes(out_markdown: Path) -> list[str]:
    """The hand-written block (between the NOTES markers) of the file being replaced, if any."""
    text = out_markdown.read_text() if out_markdown.is_file() else ""
    start, end = text.find(NOTES[0]), text.find(NOTES[1])
    return [text[start:end + len(NOTES[1])], ""] if 0 <= start < end else []


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
           f"    {REGENERATE}", "", *_notes(out_markdown), "## Claims", "",
           "Metrics and rules were fixed before the runs (`dqfd_bc_keras/analysis.py`). Per arm: mean "
           "[95% percentile-bootstrap CI] (IQM: the mean of the middle half of the seeds) over seeds; Δ is the "
           f"95% CI of the difference of means bayes − ce; tests are two-sided at α = {ALPHA}.", ""]
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
    doc += ["## Sample efficiency", "", *_efficiency(Path(suite_dir)), "", "## Demonstrations", "", DEMOS, "",
            "## Wall time", "", *_sweeps(Path(suite_dir)), ""]
    text = "\n".join(doc)
    write_text(out_markdown, text)
    return text
