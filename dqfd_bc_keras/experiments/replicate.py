"""Replicate an archived arm on the reader's machine: rerun it at fresh seeds and compare the
distributions of its metrics with the archive's, so a table of RESULTS.md can be checked
without trusting the machine it came from.

    python -m dqfd_bc_keras.experiments replicate cartpole-bootstrap-bayes --seeds 100-107 --out replica

Into a suite directory's `replications/` (`--out results/replications`), the reruns travel with
the suite: `export` archives them, and the report compares them with the suite's own runs
(`replication_section`), which they do not join.

The reruns train with the config of the arm's archived runs, only the seed changed, into
`OUT/<arm>/seed<N>/` (a sweep like any other: cut off, it resumes). Reruns are bit-identical
only on the same code, seed and machine kind (`provenance.py`); on another machine, or at other
seeds, only the distributions should agree, which is what this compares: the medians, and a
two-sided Mann–Whitney rank test per metric. A small p says the two samples differ; a large one
does not prove they agree (with 8 seeds a side only large shifts are seen).
"""

from __future__ import annotations

import dataclasses
import difflib
import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.experiments.arm_config import arm
from dqfd_bc_keras.experiments.arms import ArmRuns, find_arm, group_arms
from dqfd_bc_keras.experiments.claims import CLAIMS, judge
from dqfd_bc_keras.experiments.data import REPLICATIONS, load_runs
from dqfd_bc_keras.experiments.jobs import Job
from dqfd_bc_keras.experiments.metrics import PER_RUN, interactions_to_threshold
from dqfd_bc_keras.experiments.run_files import FinishedRun
from dqfd_bc_keras.experiments.stats import mann_whitney
from dqfd_bc_keras.experiments.sweep import SweepOptions, run_jobs
from dqfd_bc_keras.files import write_text

DEFAULT_ARCHIVE = "docs/data/results.tar.xz"
METRICS: dict[str, Callable[[FinishedRun], float]] = {
    "interactions to the threshold": interactions_to_threshold,
    "final return": lambda run: run.final.mean_return,
    "mean training return": lambda run: float(np.mean(run.column("plain_return"))),
}
"""What is compared for every arm; a run that never reached the threshold counts as ∞ (ranked last)."""
SAME_AS_METRICS = {"mean_train_return"}
"""Claim metrics that METRICS already compares under another name."""


def claim_metrics(arms: list[ArmRuns], archived: ArmRuns) -> dict[str, Callable[[FinishedRun], float]]:
    """Beside METRICS, what the claims judge `archived` by: the metrics each claim's judge compares
    where `archived` is one side of the pair the claim's verdict reads (C1's episodes to solve, C2's
    unfinished runs or collapses, C4's flags)."""
    found: dict[str, Callable[[FinishedRun], float]] = {}
    for claim in CLAIMS:
        for setting in claim.settings:
            pairs = setting.pairs(arms)
            if pairs and pairs[0][1] is not None and any(archived is side for side in pairs[0]):
                found |= {
                    c.metric: PER_RUN[c.metric]
                    for c in judge(claim, *pairs[0]).comparisons
                    if c.metric not in SAME_AS_METRICS
                }
    return found


def compare(archived: ArmRuns, fresh: list[FinishedRun], arms: list[ArmRuns]) -> list[Comparison]:
    """Each metric of METRICS and of `archived`'s claim, archived runs against fresh ones."""
    metrics = {**METRICS, **claim_metrics(arms, archived)}
    return [Comparison(metric, [f(r) for r in archived.runs], [f(r) for r in fresh]) for metric, f in metrics.items()]


@dataclass(frozen=True)
class Comparison:
    metric: str
    archived: list[float]
    fresh: list[float]

    @property
    def p(self) -> float:
        return mann_whitney(self.archived, self.fresh)[1]

    def row(self) -> str:
        def median(values: list[float]) -> str:
            value = float(np.median(values))
            return "∞" if np.isinf(value) else f"{value:g}"

        return (
            f"| {self.metric} | {len(self.archived)} | {median(self.archived)} | {len(self.fresh)} | "
            f"{median(self.fresh)} | {self.p:.2f} |"
        )


def parse_seeds(text: str) -> range:
    """`A-B` (inclusive) or a single seed `A`."""
    first, _, last = text.partition("-")
    try:
        seeds = range(int(first), int(last or first) + 1)
    except ValueError:
        raise ConfigError(f"--seeds {text!r}: expected A-B, e.g. 100-107") from None
    if not seeds or seeds.start < 0:
        raise ConfigError(f"--seeds {text!r}: expected A-B with 0 ≤ A ≤ B")
    return seeds


def archived_runs(archive: str | Path, name: str) -> tuple[list[FinishedRun], list[FinishedRun]]:
    """The runs of the arm called `name` (its directory) in `archive`, one config but for the seed,
    and all the archive's runs."""
    runs = load_runs(archive)
    found = [run for run in runs if run.path.parent.name == name]
    if not found:
        names = sorted({run.path.parent.name for run in runs})
        near = difflib.get_close_matches(name, names, n=1)
        raise ConfigError(
            f"{archive} has no arm {name!r}"
            + (f"; did you mean {near[0]!r}?" if near else f" ({len(names)} arms, e.g. {names[0]!r})")
        )
    configs = {
        json.dumps({k: v for k, v in run.config.to_dict().items() if k != "seed"}, sort_keys=True) for run in found
    }
    if len(configs) > 1:
        raise ConfigError(f"{archive}: the runs of {name!r} do not share one config")
    return found, runs


def replicate(
    name: str,
    seeds: range,
    out: str | Path,
    archive: str | Path = DEFAULT_ARCHIVE,
    workers: int = 2,
    progress: Callable[[str], None] = print,
) -> list[Comparison]:
    """Rerun arm `name` of `archive` at `seeds` (none of them archived) into `out`; compare."""
    runs, everything = archived_runs(archive, name)
    taken = sorted(set(seeds) & {run.config.seed for run in runs})
    if taken:
        raise ConfigError(
            f"--seeds: the archive already has seed(s) {taken} of {name!r}; fresh seeds are ones it has not"
        )
    config = runs[0].config.to_dict()
    fields = {k: v for k, v in config.items() if k not in ("task", "timeout", "expert_loss", "seed")}
    rerun = arm(config["task"], config["timeout"], config["expert_loss"], len(seeds), **fields)
    prefix = rerun.name.removesuffix(rerun.label)
    if name.startswith(prefix):  # the archive's own name for the same config (its labels may be in another order)
        rerun = dataclasses.replace(rerun, label=name.removeprefix(prefix))
    out = Path(out)
    jobs = [Job(rerun, seed, out) for seed in seeds]
    run_jobs(
        jobs, out, f"replicate {name}", f"{seeds.start}-{seeds.stop - 1}", SweepOptions(workers, progress=progress)
    )
    fresh = [run for run in load_runs(out / rerun.name) if run.config.seed in seeds]
    arms = group_arms(everything)
    comparisons = compare(next(a for a in arms if a.runs[0].path.parent.name == name), fresh, arms)
    table = "\n".join(
        [
            f"# Replication of {name}",
            "",
            f"Archive: {archive} ({len(runs)} runs, seeds {min(r.config.seed for r in runs)}–"
            f"{max(r.config.seed for r in runs)}). Fresh: seeds {seeds.start}–{seeds.stop - 1} on this machine.",
            "",
            "| metric | archived runs | archived median | fresh runs | fresh median | rank test p |",
            "| --- | ---: | ---: | ---: | ---: | ---: |",
            *(c.row() for c in comparisons),
            "",
        ]
    )
    write_text(out / "REPLICATE.md", table)
    progress(table)
    return comparisons


def replicated(arms: list[ArmRuns], directory: Path) -> list[tuple[ArmRuns, ArmRuns, list[Comparison]]]:
    """(archived arm, its rerun, the comparisons) for each arm rerun under the suite's REPLICATIONS."""
    fresh = group_arms(load_runs(directory / REPLICATIONS)) if (directory / REPLICATIONS).is_dir() else []
    found = []
    for rerun in fresh:
        archived = find_arm(arms, rerun.runs[0].config)
        if archived is not None:
            found.append((archived, rerun, compare(archived, rerun.runs, arms)))
    return found


def replication_section(arms: list[ArmRuns], directory: Path) -> list[str]:
    """Each arm rerun under the suite's REPLICATIONS against the suite's runs of the same config."""
    rows = [
        f"| {archived.label} | seeds {rerun.runs[0].config.seed}–{rerun.runs[-1].config.seed} {c.row()}"
        for archived, rerun, comparisons in replicated(arms, directory)
        for c in comparisons
    ]
    if not rows:
        return [
            f"Not run: `python -m dqfd_bc_keras.experiments replicate ARM --seeds 100-107 --out "
            f"SUITE/{REPLICATIONS}` reruns an arm at fresh seeds."
        ]
    return [
        "Arms rerun at fresh seeds (`experiments replicate`), against the archive's runs of the same config: "
        "medians, and a two-sided Mann–Whitney test per metric (a small p says the two samples differ; a "
        "large one does not prove they agree). The reruns are of newer code than most archived runs "
        "(*Provenance*), so they check the distributions, not the bits.",
        "",
        "| arm | fresh | metric | archived runs | archived median | fresh runs | fresh median | rank test p |",
        "| --- | --- | --- | ---: | ---: | ---: | ---: | ---: |",
        *rows,
    ]
