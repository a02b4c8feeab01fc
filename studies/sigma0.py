"""The Bayesian loss where it can act (docs/PREREGISTRATION.md §10): σ0² below the variance cap,
against ce at the same seeds, and the weight 1/(2σ²) it put on and off the demonstrations.

    python -m dqfd_bc_keras.experiments run sigma0 --out runs/sigma0      # its runs, ce's included
    python -m dqfd_bc_keras.experiments export runs/sigma0 --out docs/data/sigma0.tar.xz
    python -m studies.sigma0 docs/data/sigma0.tar.xz --report docs/SIGMA0.md

With σ² = σ0² + u(s) and u ≤ (1 − 1/A)/A, the weight can vary between states by a factor
(σ0² + v)/σ0² at most: 1.5 at the default σ0² = 0.5. The study lowers σ0² to where the factor is
3.5 and 13.5, judges each (setting, estimator, σ0²) against ce with one family of Holm-adjusted
rank tests, and shows the weights the runs logged (`imitation_weight_demo`, `_agent`).
"""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dqfd_bc_keras.commands.cli import ArgumentParser, run
from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.experiments.arms import ArmRuns, common_seeds, find_arm, group_arms
from dqfd_bc_keras.experiments.claims import ALPHA, RETURN_MARGIN, compare
from dqfd_bc_keras.experiments.data import load_runs, open_suite
from dqfd_bc_keras.experiments.efficiency import ratio_ci
from dqfd_bc_keras.experiments.stats import beyond, equivalent, holm, mann_whitney
from dqfd_bc_keras.experiments.suites import SIGMA0_ESTIMATORS, SIGMA0_VALUES, sigma0_settings
from dqfd_bc_keras.files import write_text

FAMILY = len(SIGMA0_ESTIMATORS) * len(SIGMA0_VALUES) * len(sigma0_settings())
"""The pre-registered comparisons (32): Holm adjusts over all of them, those not run as p = 1."""
ACTS = 1.5
"""The mechanism acts in an arm if its weight on D_demo ÷ on D_replay reaches 1.5, the most any σ²
can give at the default σ0² = 0.5 (on CartPole)."""
WEIGHTS = ("imitation_weight_demo", "imitation_weight_agent")


@dataclass
class Result:
    """One (setting, estimator, σ0²): the bayes arm and its ce arm on their common seeds, the
    judged metric, the rank test and, once the family is complete, the Holm-adjusted p."""

    setting: str
    uncertainty: str
    sigma0_sq: float
    bayes: ArmRuns
    ce: ArmRuns
    metric: str
    p: float
    p_holm: float = 1.0

    @property
    def higher_is_better(self) -> bool:
        return self.metric == "mean_train_return"

    @property
    def verdict(self) -> str:
        """better / worse (Holm-adjusted p < ALPHA, by the medians' order), else no measurable difference."""
        if self.p_holm >= ALPHA:
            return "no measurable difference"
        b, c = (float(np.median(arm.values(self.metric))) for arm in (self.bayes, self.ce))
        return "better" if (b > c) == self.higher_is_better else "worse"

    def margin_rule(self) -> str:
        """C3's own rule (§4) on C3's setting; ce's median ÷ bayes's [95% CI] elsewhere."""
        if self.higher_is_better:
            comparison = compare(self.metric, self.bayes, self.ce)
            margin = RETURN_MARGIN * self.bayes.runs[0].config.limit
            assert comparison.tost is not None  # `compare` always gives the TOST interval
            low, high = comparison.tost
            verdict = (
                "equivalent"
                if equivalent(comparison.tost, margin)
                else ("markedly better" if low > 0 else "markedly worse")
                if beyond(comparison.tost, margin)
                else "inconclusive"
            )
            return f"Δ {comparison.interval(1)}: {verdict}"
        point, low, high = ratio_ci(self.ce.values(self.metric), self.bayes.values(self.metric))
        if np.isnan(point):
            return "ce ÷ bayes undefined (both medians 0 or ∞)"
        interval = "CI undefined" if np.isnan(low) else f"{_times(low)}, {_times(high)}"
        return f"ce ÷ bayes {_times(point)} [{interval}]"


def _times(value: float) -> str:
    return "∞" if np.isinf(value) else f"{value:.2f}"


def _seeds(arm: ArmRuns, n: int) -> ArmRuns:
    """The arm's runs at seeds 0 … n − 1 (the grid's imperfect × 5 cell is C3's arms, at 5 seeds)."""
    return ArmRuns(arm.config, [r for r in arm.runs if r.config.seed < n], arm.name)


def results(arms: list[ArmRuns]) -> list[Result]:
    """Every comparison of the study whose bayes and ce arms have run, Holm-adjusted over FAMILY."""
    found = []
    for setting, task, seeds, fields in sigma0_settings():
        metric = "mean_train_return" if setting == "C3" else "interactions_to_threshold"
        ce = find_arm(arms, Config.for_task(task, timeout="bootstrap", expert_loss="ce", **fields))
        for uncertainty in SIGMA0_ESTIMATORS:
            for sigma0_sq in SIGMA0_VALUES:
                bayes = find_arm(
                    arms,
                    Config.for_task(
                        task,
                        timeout="bootstrap",
                        expert_loss="bayes",
                        uncertainty=uncertainty,
                        sigma0_sq=sigma0_sq,
                        **fields,
                    ),
                )
                if bayes is None or ce is None:
                    continue
                pair = common_seeds(_seeds(bayes, seeds), _seeds(ce, seeds))
                if min(len(a.runs) for a in pair) < 2:
                    continue
                p = mann_whitney(*(a.values(metric) for a in pair))[1]
                found.append(Result(setting, uncertainty, sigma0_sq, *pair, metric, p))
    for result, adjusted in zip(found, holm([r.p for r in found], FAMILY), strict=True):
        result.p_holm = adjusted
    return found


def weights(arm: ArmRuns) -> tuple[float, float] | None:
    """The median over seeds of each run's mean weight on D_demo and on D_replay; None if the
    runs predate the logging."""
    per_run = np.array(
        [
            [np.nanmean(run.column(w)) if np.isfinite(run.column(w)).any() else np.nan for w in WEIGHTS]
            for run in arm.runs
        ]
    )
    if np.isnan(per_run).any():
        return None
    on, off = np.median(per_run, axis=0)
    return float(on), float(off)


def _median(arm: ArmRuns, metric: str) -> str:
    value = float(np.median(arm.values(metric)))
    return "∞" if np.isinf(value) else f"{value:,.0f}" if metric != "mean_train_return" else f"{value:.1f}"


def sigma0_section(arms: list[ArmRuns]) -> list[str]:
    """The study's table, its answer, and what has not run."""
    found = results(arms)
    if not found:
        return ["Not run: `python -m dqfd_bc_keras.experiments run sigma0 --out SUITE` (docs/PREREGISTRATION.md §10)."]
    rows = []
    for r in found:
        w = weights(r.bayes)
        mechanism = (
            "—"
            if w is None
            else (f"{w[0]:.2f} · {w[1]:.2f} · ×{w[0] / w[1]:.2f}{' (acts)' if w[0] / w[1] >= ACTS else ''}")
        )
        rows.append(
            f"| {r.setting} | {r.uncertainty} | {r.sigma0_sq:g} | {len(r.bayes.runs)} | "
            f"{_median(r.bayes, r.metric)} · {_median(r.ce, r.metric)} | {r.margin_rule()} | "
            f"{r.p:.3g} · {r.p_holm:.3g} | **{r.verdict}** | {mechanism} |"
        )
    acts = {
        u: [r for r in found if r.uncertainty == u and (w := weights(r.bayes)) and w[0] / w[1] >= ACTS]
        for u in SIGMA0_ESTIMATORS
    }
    mechanism = "; ".join(f"{u} {len(acts[u])} of {sum(r.uncertainty == u for r in found)}" for u in SIGMA0_ESTIMATORS)
    better = [r for r in found if r.verdict == "better"]
    worse = [r for r in found if r.verdict == "worse"]
    answer = "yes" if better and not worse else "no"
    return [
        "bayes with σ0² below the variance cap, against ce at the same seeds (docs/PREREGISTRATION.md §10). Metric: "
        "mean plain training return on C3's setting, counted interactions to the threshold elsewhere (∞ = never); "
        f"medians over seeds. p: two-sided Mann–Whitney; Holm: adjusted over the study's {FAMILY} pre-registered "
        "comparisons (those not run count as p = 1). Weights: the median over seeds of each run's mean 1/(2σ²) on "
        f"D_demo · on D_replay · their ratio; *acts*: ratio ≥ {ACTS:g}, the most any σ² allows at σ0² = 0.5. A lower "
        "σ0² also raises the weight on every state: the study cannot separate a stronger imitation from a more "
        "selective one.",
        "",
        "| setting | estimator | σ0² | seeds | bayes · ce | margin rule | p · Holm | verdict "
        "| weight on · off · ratio |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
        *rows,
        "",
        f"**Is the Bayesian loss measurably better than ce in any setting? {answer}**: {len(better)} of {len(found)} "
        f"comparisons run are *better*, {len(worse)} *worse* ({FAMILY - len(found)} of {FAMILY} not run yet). "
        f"The weight's ratio on ÷ off the demonstrations reaches {ACTS:g} (*acts*) in: {mechanism} arms.",
    ]


ARCHIVE = "docs/data/sigma0.tar.xz"


def study_report(source: str | os.PathLike) -> str:
    """docs/SIGMA0.md from the study's runs (a suite directory or its archive): provenance, the
    study's table and answer, the sweeps' wall time. The same data give the same bytes."""
    from dqfd_bc_keras.experiments.report import _skipped
    from dqfd_bc_keras.experiments.sections import provenance_line, sweeps_section

    skipped: list = []
    with open_suite(source) as directory:
        arms = group_arms(load_runs(directory, skipped))
        sweeps = sweeps_section(directory)
    runs = sum(len(a.runs) for a in arms)
    return "\n".join(
        [
            "# The Bayesian loss where it can act: σ0² below the variance cap",
            "",
            f"Generated by `python -m studies.sigma0 {ARCHIVE} --report docs/SIGMA0.md` from the "
            f"{runs} runs in {ARCHIVE} (rules: docs/PREREGISTRATION.md §10). Its runs, ce's included, are of one code "
            "version, apart from docs/data/results.tar.xz (whose runs the current code does not reproduce seed for "
            "seed).",
            "",
            provenance_line(arms),
            "",
            *_skipped(skipped),
            *sigma0_section(arms),
            "",
            "## Wall time",
            "",
            *sweeps,
            "",
        ]
    )


def main(argv: Sequence[str] | None = None) -> int:
    parser = ArgumentParser(prog="python -m studies.sigma0", description=__doc__.split("\n\n")[0])
    parser.add_argument("source", help="the study's suite directory, or its archive")
    parser.add_argument("--report", type=Path, help="write the markdown here too (default: print it only)")
    args = parser.parse_args(argv)
    text = study_report(args.source)
    print(text)
    if args.report is not None:
        write_text(args.report, text)
    return 0


if __name__ == "__main__":
    sys.exit(run(main))
