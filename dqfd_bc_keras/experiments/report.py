"""The RESULTS.md report of a suite (a directory or its archive): claims table, figures, baselines,
sensitivity, and per_seed.csv beside it.

The same data give the same bytes: the suite is named by its basename, every time comes from the
data, and the figures are drawn deterministically (figures.py).
"""

from __future__ import annotations

import csv
import io
import json
import os
import sys
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import numpy as np

from dqfd_bc_keras.envs.make import get_task
from dqfd_bc_keras.experiments import figures
from dqfd_bc_keras.experiments.arms import ArmRuns, bayes_ce_pairs, group_arms, preset_distance
from dqfd_bc_keras.experiments.baselines_table import baselines_section, demos_text
from dqfd_bc_keras.experiments.claims import (
    ALPHA,
    CLAIMS,
    Comparison,
    ablation_pairs,
    dynamic_default,
    flips,
    judge,
    judge_ablation,
    rule_text,
    too_few,
)
from dqfd_bc_keras.experiments.data import ARCHIVE_SUFFIX, load_runs, open_suite
from dqfd_bc_keras.experiments.efficiency import efficiency_section
from dqfd_bc_keras.experiments.estimators import estimators_section
from dqfd_bc_keras.experiments.grid import grid_only, grid_section
from dqfd_bc_keras.experiments.metrics import EARLY_EPISODES, METRICS, PER_RUN, finished
from dqfd_bc_keras.experiments.plans import PLANNED_SEEDS
from dqfd_bc_keras.experiments.replicate import replication_section
from dqfd_bc_keras.experiments.run_files import RunFileError
from dqfd_bc_keras.experiments.stats import CensoredSummary, Summary
from dqfd_bc_keras.experiments.summary import summary
from dqfd_bc_keras.files import write_text

ARCHIVE = "docs/data/results.tar.xz"
"""Where the per-run data behind docs/RESULTS.md are committed."""
REGENERATE = (
    f"python -m dqfd_bc_keras.experiments report {ARCHIVE} --docs",
    "python -m dqfd_bc_keras.experiments run all --out results && "
    "python -m dqfd_bc_keras.experiments calibrate --out results/calibration.json && "
    "python -m dqfd_bc_keras.experiments grid --out results && "
    "python -m dqfd_bc_keras.experiments efficiency --out results && "
    f"python -m dqfd_bc_keras.experiments export results --out {ARCHIVE}",
)
"""This report from the committed per-run data (no training), and every run, the benchmark and the
archive behind it (finished runs are skipped, so the second also resumes a cut-off sweep)."""


PER_SEED = "per_seed.csv"
"""Written beside RESULTS.md: one row per run with every per-run metric."""


SMOOTH_ABOVE, SMOOTH_WINDOW = 150, 10
"""The mean curves of settings whose runs are longer than 150 episodes (MountainCar's hundreds) are
drawn as trailing means of 10 episodes, said on the axis: a few flags per episode, over hundreds of
episodes, are unreadable raw. Single runs and the early-episode zoom are drawn raw."""


def _cell(comparisons: list[Comparison], part: Callable[[Comparison], str]) -> str:
    return "<br>".join(part(c) for c in comparisons) or "—"


def _claim_rows(arms: list[ArmRuns]) -> tuple[list[str], list[str]]:
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


def _per_seed(arms: list[ArmRuns]) -> str:
    """PER_SEED's text: per run its arm, setting and seed, every metric of claims.PER_RUN (inf: never),
    the demonstration transitions it started from and its dynamic updates."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["arm", "setting", "seed", *PER_RUN, "demo_transitions", "dynamic_demo_updates"])
    for arm in arms:
        for run in arm.runs:
            writer.writerow(
                [
                    arm.name,
                    arm.setting,
                    run.config.seed,
                    *(f"{PER_RUN[m](run):.10g}" for m in PER_RUN),
                    run.demo_transitions,
                    len(run.dynamic_demos),
                ]
            )
    return buffer.getvalue()


def _figures(arms: list[ArmRuns], figures_dir: Path, markdown_dir: Path) -> list[str]:
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
        cases = [a.name for a in pair if a.name in main] or main
        paths = figures.setting_figures(setting, {n: runs[n] for n in main}, cases, score, ylabel, stem, window, zoom)
        variants = [a.name for a in members if a.name not in main and not grid_only(a.config)]
        if variants:
            path = stem.with_name(f"{stem.name}-variants.png")
            shown = [a.name for a in pair if a.name in main] + variants
            figures.learning_curves(f"{setting}, variants", {n: runs[n] for n in shown}, ylabel, path, window, zoom)
            paths.append(path)
        links += [f"![{setting} {p.stem}]({Path(os.path.relpath(p, markdown_dir)).as_posix()})" for p in paths]
    return links


def _commit(commit: str | None, dirty: bool = False) -> str:
    return ("unknown" if commit is None else f"`{commit[:12]}`") + (" (dirty)" if dirty else "")


def _sweeps(suite_dir: Path) -> list[str]:
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


def _provenance(arms: list[ArmRuns]) -> str:
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


def _skipped(errors: list[RunFileError]) -> list[str]:
    if not errors:
        return []
    return [
        f"**{len(errors)} run(s) skipped**, a file missing or unreadable:",
        "",
        *(f"- `{e.file}`: {e.problem}" for e in errors),
        "",
    ]


NOTES = ("<!-- notes: hand-written, kept when the report is regenerated -->", "<!-- /notes -->")


def _notes(out_markdown: Path) -> list[str]:
    """The hand-written block (between the NOTES markers) of the file being replaced, if any."""
    text = out_markdown.read_text() if out_markdown.is_file() else ""
    start, end = text.find(NOTES[0]), text.find(NOTES[1])
    return [text[start : end + len(NOTES[1])], ""] if 0 <= start < end else []


def default_location(source: str | os.PathLike) -> Path:
    """Where `report SOURCE` writes unless told otherwise: into a suite directory itself; for an
    archive, into `<its name without .tar.xz>-report/` beside it. Never into the project's docs/."""
    source = Path(source)
    return source if source.is_dir() else source.with_name(f"{source.name.removesuffix(ARCHIVE_SUFFIX)}-report")


def warn(line: str) -> None:
    print(f"warning: {line}", file=sys.stderr)


def _dynamic(arms: list[ArmRuns]) -> list[str]:
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


def _ablations(arms: list[ArmRuns]) -> list[str]:
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


def report(
    source: str | os.PathLike,
    out_markdown: str | os.PathLike,
    figures_dir: str | os.PathLike,
    warn: Callable[[str], None] = warn,
) -> str:
    """Write the RESULTS-style markdown for every complete run of `source` (a suite directory or
    an archive of one), its figures into `figures_dir` (linked relative to `out_markdown`) and
    PER_SEED beside it; return the markdown. A run with a missing or unreadable file is skipped:
    `warn` gets one line naming the file, and the markdown lists it."""
    out_markdown, figures_dir = Path(out_markdown), Path(figures_dir)
    suite_name, skipped = Path(source).resolve().name, []
    with open_suite(source) as directory:
        directory = directory.resolve()
        arms = group_arms(load_runs(directory, skipped))
        efficiency, sweeps = efficiency_section(directory), _sweeps(directory)
        estimators = estimators_section(arms, directory, figures_dir, out_markdown.parent)
        grid = grid_section(arms, directory, figures_dir, out_markdown.parent)
        opening = summary(arms, directory)
        replications = replication_section(arms, directory)
    for error in skipped:
        warn(f"{Path(source) / error.file}: {error.problem}; run skipped")
    claims, sensitivity = _claim_rows(arms)
    wall = sum(r.metrics[-1]["wall_time"] for a in arms for r in a.runs)
    doc = [
        "# Results: the paper's claims over seeds",
        "",
        *opening,
        f"{sum(len(a.runs) for a in arms)} complete runs in {len(arms)} arms of `{suite_name}`; total training "
        f"wall time {wall / 60:.1f} min (sum over runs); every run's metrics in [{PER_SEED}]({PER_SEED}). "
        "Regenerate it from the committed per-run data, without training:",
        "",
        f"    {REGENERATE[0]}",
        "",
        "and the data themselves (then the line above):",
        "",
        f"    {REGENERATE[1]}",
        "",
        _provenance(arms),
        "",
        *_skipped(skipped),
        *_notes(out_markdown),
        "## Claims",
        "",
        "Metrics and rules were fixed before the runs (docs/PREREGISTRATION.md, `dqfd_bc_keras/experiments/"
        "claims.py`; their commit is printed above). Per arm: mean "
        "[95% percentile-bootstrap CI] (IQM: the mean of the middle half of the seeds) over seeds; Δ is the "
        f"95% CI of the difference of means bayes − ce; tests are two-sided at α = {ALPHA}.",
        "",
    ]
    doc += [f"- `{name}`: {text}." for name, text in METRICS.items()]
    doc += [f"- {c.id} ({'; '.join(s.name for s in c.settings)}): {c.rule}" for c in CLAIMS]
    doc += [
        f"- Seeds planned for {claim} on {setting}: {plan.describe()}."
        for (claim, setting), plan in PLANNED_SEEDS.items()
    ]
    doc += [
        "- Δ: the 95% CI of the difference of means and, in parentheses, the CI whose ends are one-sided "
        f"bounds at α = {ALPHA} (TOST's). *n · sd · power*: seeds per arm, the judged metric's pooled sd over "
        "seeds and the power its rule has at that spread and n when bayes and ce truly do not differ.",
        "",
        "| claim | setting | the paper | metric per arm | Δ bayes − ce | test | n · sd · power | verdict |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
        *claims,
        "",
        "## Figures",
        "",
        *_figures(arms, figures_dir, out_markdown.parent),
        "",
        "## Baselines",
        "",
        *baselines_section(arms),
        "",
        "## Sensitivity",
        "",
        "Each further bayes arm of a claim's setting (σ0², demonstrator, …) judged against its ce arm "
        "with the same rule; *flips*: holds ↔ does not hold against the reference pair's verdict (yes), the "
        "same verdict (no), or a change to or from inconclusive (unclear).",
        "",
        "| claim | bayes arm | ce arm | metric per arm | verdict | flips |",
        "| --- | --- | --- | --- | --- | --- |",
        *(sensitivity or ["| — | no sensitivity arms | | | | |"]),
        "",
    ]
    doc += [
        "## Replications",
        "",
        *replications,
        "",
        "## Dynamic demonstrations: the default",
        "",
        *_dynamic(arms),
        "",
        "## Ablations",
        "",
        *_ablations(arms),
        "",
    ]
    doc += [
        "## Sample efficiency",
        "",
        *efficiency,
        "",
        "## Uncertainty estimators",
        "",
        *estimators,
        "",
        "## Demonstration quality × quantity",
        "",
        *grid,
        "",
        "## Demonstrations",
        "",
        demos_text(),
        "",
        "## Wall time",
        "",
        *sweeps,
        "",
    ]
    # A section naming the directory it read (the benchmark's "not run" hint) names the suite as above.
    text = "\n".join(doc).replace(str(directory), suite_name)
    write_text(out_markdown.with_name(PER_SEED), _per_seed(arms))
    write_text(out_markdown, text)
    return text
