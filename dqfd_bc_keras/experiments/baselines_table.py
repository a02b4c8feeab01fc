"""The baselines table of the report: per arm, the demonstrations its runs started from (size,
where they came from, how their demonstrator returns), pre-training and outcome; and the text
on which demonstrations the arms get."""

from __future__ import annotations

import numpy as np

from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.experiments.arms import ArmRuns
from dqfd_bc_keras.experiments.stats import Summary
from dqfd_bc_keras.training.records import DemoSummary


def baselines_section(arms: list[ArmRuns]) -> list[str]:
    """The section's text and table, one row per arm."""
    return [
        "Final evaluation on the plain env against the mean plain return of the demonstrations the run "
        "started from (for cartpole-200 those are capped at 200 steps, the evaluation at 500). *Demos*, "
        "*demo transitions* (range over seeds) and *demonstrator* are D_demo before any dynamic demonstration, "
        "as each run's demonstrations.json records it (unknown: a run from before that file); *pre-training*: "
        "gradient steps on D_demo alone before the first interaction (`pretrain_steps`).",
        "",
        "| setting | arm | seeds | demos | demo transitions | pre-training | final eval | mean training return "
        "| interactions to threshold (median, reached) | demonstrator | beats it by |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
        *map(baseline_row, arms),
    ]


def _span(values: list[int]) -> str:
    low, high = min(values), max(values)
    return f"{low:,}" if low == high else f"{low:,}–{high:,}"


def demo_source(demos: DemoSummary) -> str:
    """Where a run's demonstrations came from, as its demonstrations.json says."""
    if demos.source == "file":
        return f"{demos.episodes} episodes from a file"
    if demos.source == "minari":
        return f"{demos.episodes} episodes from {demos.expert}"
    return f"{demos.episodes} × {demos.expert}"


def baseline_row(arm: ArmRuns) -> str:
    """One arm: its demonstrations (as the runs record them), pre-training, outcome and demonstrator."""
    steps = arm.values("interactions_to_threshold")
    reached = int(np.isfinite(steps).sum())  # the median is finite once more than half reached it
    median = f"{np.median(steps):,.0f}" if 2 * reached > len(steps) else "—"
    final = Summary.of(arm.values("final_eval"))
    source, transitions, pretrain, teacher, beats = "—", "0", "—", "none", "—"
    if arm.config.expert_loss != "none":
        pretrain = f"{arm.config.pretrain_steps:,}"
        records = [r.demonstrations for r in arm.runs if r.demonstrations is not None]  # each, with a method
        demonstrator = float(np.mean([r.demonstrator_return for r in arm.runs]))
        source = " · ".join(sorted({demo_source(d) for d in records}))
        transitions = _span([d.transitions for d in records])
        teacher, beats = f"{demonstrator:.1f}", f"{final.mean - demonstrator:+.1f}"
    return (
        f"| {arm.setting} | {arm.name} | {len(arm.runs)} | {source} | {transitions} | {pretrain} | "
        f"{final.format()} | {Summary.of(arm.values('mean_train_return')).format()} | "
        f"{median} ({reached}/{len(steps)}) | {teacher} | {beats} |"
    )


def demos_text() -> str:
    """Which demonstrations the arms get and why; how they return is read from the runs (baselines)."""
    cartpole, mountaincar = Config.for_task("cartpole"), Config.for_task("mountaincar")
    return (
        "Which demonstrations the paper's experiments get is not stated in the paper. Every arm that uses "
        f"them starts from the same choice: **{cartpole.demo_episodes} episodes of the {cartpole.expert} "
        "scripted expert on CartPole** (push with the pole's angular velocity, ignoring its angle) and "
        f"**{mountaincar.demo_episodes} episodes of the {mountaincar.expert} expert on MountainCar** (follows "
        "the velocity, always starting rightwards); how they return is the *demonstrator* column of the "
        "baselines table, read from each run's demonstrations.json. Why: an imperfect teacher is the case the "
        "paper's Bayesian loss is built for (an uncertain π_bc should weigh less), a handful of episodes is the "
        'paper\'s "few demonstrations" regime, and a weak teacher leaves room to show that a method beats its '
        "demonstrator. Seed k of every arm records the same episodes (reset seeds from `seeds.demo_seed(k)`), "
        "so bayes and ce differ in the loss only and the spread over seeds includes the draw of the "
        "demonstrations. The sensitivity suite swaps in the strong experts."
    )
