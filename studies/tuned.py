"""A study's best params against the preset's defaults, on fresh seeds: what `experiments tune` found,
judged on runs it never saw (docs/TUNING.md, whose rule below was committed before these runs).

Two arms, `defaults` (the task preset with the study's fixed fields: its budget, env settings,
demonstrator) and `tuned` (the same and best.json's params), at seeds 0 … N − 1: a study tunes on
seeds from `seeds.TUNE_SEED` (10⁶) up, so none of these. Each run is scored by the study's own metric
(`tuning.objective.score`: the same definition the trials were ranked by), with the final greedy
evaluation and the area under the curve beside it. The rule: the tuned params are **better** (or
**worse**) if a two-sided Mann–Whitney test over the seeds gives p < 0.05 *and* the medians differ by
at least the margin (one evaluation period of interactions for `threshold`; 5% of the episode limit's
return for `final` and `auc`, the lab's return margin); a significant difference inside the margin
is reported as such, never as better; else there is no measurable difference.

    python -m studies.tuned tuning/acrobot/best.json --seeds 20 --out runs/tuned-acrobot
    python -m dqfd_bc_keras.experiments export runs/tuned-acrobot --out docs/data/tuned-acrobot.tar.xz
    python -m studies.tuned tuning/acrobot/best.json --out docs/data/tuned-acrobot.tar.xz --no-run --report FILE.md
    python -m studies.tuned BEST --out /tmp/tuned --quick      # seconds: two seeds on the quick budget

Writes only under --out (the runs, in the lab's format) and, with --report, that one file.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from dqfd_bc_keras.arguments import is_demo_source
from dqfd_bc_keras.commands.cli import ArgumentParser, positive_int, run
from dqfd_bc_keras.core.config import QUICK, Config
from dqfd_bc_keras.core.params import read_params
from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.experiments.claims import ALPHA, RETURN_MARGIN
from dqfd_bc_keras.experiments.data import load_runs
from dqfd_bc_keras.experiments.efficiency import ratio_ci
from dqfd_bc_keras.experiments.run_files import FinishedRun
from dqfd_bc_keras.experiments.stats import bootstrap_ci, mann_whitney
from dqfd_bc_keras.experiments.suites import Arm
from dqfd_bc_keras.experiments.sweep import SweepOptions, run_suite
from dqfd_bc_keras.files import write_text
from dqfd_bc_keras.tuning.objective import METRICS, score

ARMS = ("defaults", "tuned")


def arms(best: Path, seeds: int, quick: bool) -> list[Arm]:
    """The two arms of best.json's study: its fixed fields, then (tuned) its params."""
    found = json.loads(best.read_text())
    tunes = found.get("tunes") if isinstance(found, dict) else None
    if not isinstance(tunes, dict) or "task" not in tunes:
        raise ConfigError(f'{best}: not a best.json of `experiments tune` (no "tunes" record of what it tuned)')
    demos = tunes.get("demos")
    if demos is not None and is_demo_source(demos):
        raise ConfigError(f"{best}: the study learnt from a dataset ({demos}); a sweep records its demonstrations")
    fixed = {**tunes["fixed"], **({"expert": demos} if demos else {}), **(QUICK if quick else {})}
    params = read_params(best, tunes["task"])
    timeout = Config.for_task(tunes["task"], expert_loss=tunes["expert_loss"], **fixed).timeout
    fixed.pop("timeout", None)  # an Arm's own field
    return [
        Arm(tunes["task"], timeout, tunes["expert_loss"], tuple(overrides.items()), label, seeds)
        for label, overrides in (("defaults", fixed), ("tuned", {**fixed, **params}))
    ]


def run_score(run: FinishedRun, metric: str, threshold: float | None) -> float:
    """The run's value by the study's metric, as a trial's run was scored."""
    curve = [(int(e["interactions"]), float(e["mean_return"])) for e in run.evals]
    c = run.config
    return score(metric, curve, run.final.mean_return, c.total_steps, c.eval_every, threshold)


def report(best: Path, source: Path) -> str:
    """The comparison's markdown, from the runs (a suite directory or its archive)."""
    found = json.loads(best.read_text())
    metric, threshold = found["metric"], found["tunes"].get("threshold")
    by_arm: dict[str, list[FinishedRun]] = {label: [] for label in ARMS}
    for one in load_runs(source):
        label = one.path.parent.name.rsplit("-", 1)[-1]
        if label in by_arm:
            by_arm[label].append(one)
    if min(len(runs) for runs in by_arm.values()) < 2:
        raise ConfigError(
            f"{source}: each arm needs two complete runs at least, has {[len(r) for r in by_arm.values()]}"
        )
    values = {label: np.array([run_score(r, metric, threshold) for r in runs]) for label, runs in by_arm.items()}
    config = by_arm["defaults"][0].config
    lines = [
        f"# {found['study']}'s best params on fresh seeds ({config.task}, {config.expert_loss})",
        "",
        f"Generated by `python -m studies.tuned {best} --out {source} --no-run`. Metric: {metric} "
        f"({METRICS[metric].doc}{f', threshold {threshold:g}' if threshold is not None else ''}); seeds "
        f"{min(r.config.seed for r in by_arm['tuned'])}–{max(r.config.seed for r in by_arm['tuned'])}, "
        f"{config.total_steps:,} steps per run. Median [95% bootstrap CI] over seeds"
        + (
            f"; a run that never reaches the threshold counts as {config.total_steps + config.eval_every:,}."
            if metric == "threshold"
            else "."
        ),
        "",
        f"| arm | seeds | {metric} | final greedy return | mean return under the curve |",
        "| --- | --- | --- | --- | --- |",
    ]
    for label, runs in by_arm.items():
        final = np.array([r.final.mean_return for r in runs])
        auc = np.array([run_score(r, "auc", None) for r in runs])
        reached = (
            f" (reached by {int(np.sum(values[label] <= config.total_steps))}/{len(runs)})"
            if metric == "threshold"
            else ""
        )
        lines.append(
            f"| {label} | {len(runs)} | {_median(values[label])}{reached} | {_median(final)} | {_median(auc)} |"
        )
    lines += ["", *verdict(values, metric, config)]
    return "\n".join(lines) + "\n"


def verdict(values: dict[str, np.ndarray], metric: str, config: Config) -> list[str]:
    """The rule of the module's docstring, applied, with the test and the medians it read."""
    margin = config.eval_every if metric == "threshold" else RETURN_MARGIN * config.limit
    p, gain, said = compare(values["tuned"], values["defaults"], METRICS[metric].direction, margin)
    lines = [f"Tuned against defaults: Mann–Whitney p = {p:.3g}; the medians differ by {gain:+,.1f} in the tuned "
             f"params' favour (margin {margin:,.1f}): {said}."]  # fmt: skip
    if metric == "threshold":
        point, low, high = ratio_ci(values["defaults"], values["tuned"])
        lines.append(f"Defaults ÷ tuned, the medians' ratio: {point:.2f} [{low:.2f}, {high:.2f}] (95% bootstrap CI).")
    return lines


def compare(tuned: np.ndarray, defaults: np.ndarray, direction: str, margin: float) -> tuple[float, float, str]:
    """The rule: (two-sided Mann–Whitney p, the medians' difference in the tuned side's favour, the verdict)."""
    p = mann_whitney(tuned, defaults)[1]
    gain = float(np.median(tuned) - np.median(defaults))
    gain = -gain if direction == "minimize" else gain
    if p >= ALPHA:
        said = "no measurable difference"
    elif abs(gain) < margin:
        said = f"a significant difference inside the margin ({margin:g}): not a better or worse setting"
    else:
        said = "**better**" if gain > 0 else "**worse**"
    return p, gain, said


def _median(values: np.ndarray) -> str:
    low, high = bootstrap_ci(values, np.median)
    return f"{np.median(values):,.1f} [{low:,.1f}, {high:,.1f}]"


def main(argv: Sequence[str] | None = None) -> int:
    parser = ArgumentParser(prog="python -m studies.tuned", description=__doc__.split("\n\n")[0])
    parser.add_argument("best", type=Path, help="best.json of `experiments tune`")
    parser.add_argument(
        "--out", type=Path, required=True, help="suite directory of the runs (or, with --no-run, its archive)"
    )
    parser.add_argument("--seeds", type=positive_int, default=20, help="fresh seeds 0 … N − 1 per arm (default 20)")
    parser.add_argument("--workers", type=positive_int, default=2)
    parser.add_argument("--no-run", action="store_true", help="report the runs under --out, run nothing")
    parser.add_argument("--report", type=Path, help="write the markdown here too (default: print it only)")
    parser.add_argument("--quick", action="store_true", help="two seeds on the quick budget (a test)")
    args = parser.parse_args(argv)
    seeds = 2 if args.quick else args.seeds
    if not args.no_run:
        run_suite(arms(args.best, seeds, args.quick), seeds, args.out, SweepOptions(args.workers), name="tuned")
    text = report(args.best, args.out)
    print(text)
    if args.report is not None:
        write_text(args.report, text)
    return 0


if __name__ == "__main__":
    sys.exit(run(main))
