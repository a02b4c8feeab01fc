"""The RESULTS.md report of a suite (a directory or its archive): its sections (sections.py and the
modules that own them) assembled under their headings, and per_seed.csv beside it.

The same data give the same bytes: the suite is named by its basename, every time comes from the
data, and the figures are drawn deterministically (figures.py).
"""

from __future__ import annotations

import csv
import io
import os
import sys
from collections.abc import Callable
from pathlib import Path

from dqfd_bc_keras.experiments.arms import ArmRuns, group_arms
from dqfd_bc_keras.experiments.baselines_table import baselines_section, demos_text
from dqfd_bc_keras.experiments.claims import ALPHA, CLAIMS
from dqfd_bc_keras.experiments.data import ARCHIVE_SUFFIX, load_runs, open_suite
from dqfd_bc_keras.experiments.efficiency import efficiency_section
from dqfd_bc_keras.experiments.estimators import estimators_section
from dqfd_bc_keras.experiments.grid import grid_section
from dqfd_bc_keras.experiments.metrics import METRICS, PER_RUN
from dqfd_bc_keras.experiments.plans import PLANNED_SEEDS
from dqfd_bc_keras.experiments.replicate import replication_section
from dqfd_bc_keras.experiments.run_files import RunFileError
from dqfd_bc_keras.experiments.sections import (
    ablations_section,
    claim_rows,
    dynamic_section,
    figure_links,
    provenance_line,
    sweeps_section,
)
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
    suite_name = Path(source).resolve().name
    skipped: list[RunFileError] = []
    with open_suite(source) as directory:
        directory = directory.resolve()
        arms = group_arms(load_runs(directory, skipped))
        read = _read_suite(arms, directory, figures_dir, out_markdown.parent)
        opening = summary(arms, directory)
    for error in skipped:
        warn(f"{Path(source) / error.file}: {error.problem}; run skipped")
    doc = [
        *_head(arms, suite_name, opening),
        *_skipped(skipped),
        *_notes(out_markdown),
        *_body(arms, read, figures_dir, out_markdown.parent),
    ]
    # A section naming the directory it read (the benchmark's "not run" hint) names the suite as above.
    text = "\n".join(doc).replace(str(directory), suite_name)
    write_text(out_markdown.with_name(PER_SEED), _per_seed(arms))
    write_text(out_markdown, text)
    return text


def _read_suite(arms: list[ArmRuns], directory: Path, figures_dir: Path, markdown_dir: Path) -> dict[str, list[str]]:
    """The sections read from the suite directory itself (an archive's exists only while it is
    unpacked), by heading."""
    return {
        "Sample efficiency": efficiency_section(directory),
        "Wall time": sweeps_section(directory),
        "Uncertainty estimators": estimators_section(arms, directory, figures_dir, markdown_dir),
        "Demonstration quality × quantity": grid_section(arms, directory, figures_dir, markdown_dir),
        "Replications": replication_section(arms, directory),
    }


def _head(arms: list[ArmRuns], suite_name: str, opening: list[str]) -> list[str]:
    """The title, the opening, what the report covers, how to regenerate it and the runs' provenance."""
    wall = sum(r.metrics[-1]["wall_time"] for a in arms for r in a.runs)
    return [
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
        provenance_line(arms),
        "",
    ]


def _body(arms: list[ArmRuns], read: dict[str, list[str]], figures_dir: Path, markdown_dir: Path) -> list[str]:
    """Every section under its heading, in the report's order."""
    claims, sensitivity = claim_rows(arms)
    sections = {
        "Claims": _claims(claims),
        "Figures": figure_links(arms, figures_dir, markdown_dir),
        "Baselines": baselines_section(arms),
        "Sensitivity": _sensitivity(sensitivity),
        "Replications": read["Replications"],
        "Dynamic demonstrations: the default": dynamic_section(arms),
        "Ablations": ablations_section(arms),
        "Sample efficiency": read["Sample efficiency"],
        "Uncertainty estimators": read["Uncertainty estimators"],
        "Demonstration quality × quantity": read["Demonstration quality × quantity"],
        "Demonstrations": [demos_text()],
        "Wall time": read["Wall time"],
    }
    return [line for heading, lines in sections.items() for line in (f"## {heading}", "", *lines, "")]


def _claims(rows: list[str]) -> list[str]:
    """The claims section: how they are judged, then the table of their reference pairs."""
    return [
        "Metrics and rules were fixed before the runs (docs/PREREGISTRATION.md, `dqfd_bc_keras/experiments/"
        "claims.py`; their commit is printed above). Per arm: mean "
        "[95% percentile-bootstrap CI] (IQM: the mean of the middle half of the seeds) over seeds; Δ is the "
        f"95% CI of the difference of means bayes − ce; tests are two-sided at α = {ALPHA}.",
        "",
        *(f"- `{name}`: {text}." for name, text in METRICS.items()),
        *(f"- {c.id} ({'; '.join(s.name for s in c.settings)}): {c.rule}" for c in CLAIMS),
        *(
            f"- Seeds planned for {claim} on {setting}: {plan.describe()}."
            for (claim, setting), plan in PLANNED_SEEDS.items()
        ),
        "- Δ: the 95% CI of the difference of means and, in parentheses, the CI whose ends are one-sided "
        f"bounds at α = {ALPHA} (TOST's). *n · sd · power*: seeds per arm, the judged metric's pooled sd over "
        "seeds and the power its rule has at that spread and n when bayes and ce truly do not differ.",
        "",
        "| claim | setting | the paper | metric per arm | Δ bayes − ce | test | n · sd · power | verdict |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
        *rows,
    ]


def _sensitivity(rows: list[str]) -> list[str]:
    """The sensitivity section: every further bayes arm of a claim's setting against its ce arm."""
    return [
        "Each further bayes arm of a claim's setting (σ0², demonstrator, …) judged against its ce arm "
        "with the same rule; *flips*: holds ↔ does not hold against the reference pair's verdict (yes), the "
        "same verdict (no), or a change to or from inconclusive (unclear).",
        "",
        "| claim | bayes arm | ce arm | metric per arm | verdict | flips |",
        "| --- | --- | --- | --- | --- | --- |",
        *(rows or ["| — | no sensitivity arms | | | | |"]),
    ]
