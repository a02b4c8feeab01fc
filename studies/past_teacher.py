"""Past the teacher (issue W; rules: docs/PREREGISTRATION.md §14): the pilot that picks the new arm
among the methods of ALGORITHM.md §8, and that arm's runs on the five MinAtar games, beside §13's
`bayes`, `ce`, DQN and SB3 runs (docs/data/minatar.tar.xz).

The pilot: `qfilter`, `ce_decay` and `bayes_local` on Breakout and Freeway, tuning seeds, 100,000
interactions, each run as `train.py --task GAME --expert-loss METHOD --seed SEED` runs it. The new
arm is the method with the highest mean normalised score at the budget; within CLOSE of the best,
the one that imitates least on the agent's own states (mean `imitation_weight_agent` over the last
10% of its episodes).

    python -m studies.past_teacher --pilot docs/data/past-teacher-pilot.tar.xz   # the choice, from the data
    python -m studies.past_teacher --out runs/past-teacher --archive runs/past-teacher.tar.xz
    python -m studies.past_teacher --out docs/data/past-teacher.tar.xz --no-run --report docs/PAST_TEACHER.md \\
        --figures docs/figures
    python -m studies.past_teacher --out /tmp/past-teacher --quick   # seconds: tiny budgets

Writes only under --out, into --archive, and, with --report and --figures, that file and the figures
`past_teacher_*.png` in that directory.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dqfd_bc_keras.commands.cli import ArgumentParser, run
from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.experiments.data import load_runs, open_suite
from dqfd_bc_keras.experiments.run_files import FinishedRun
from dqfd_bc_keras.seeds import TUNE_SEED
from studies.minatar_study import (
    ANCHORS,
    BUDGET,
    DQFD,
    METHODS,
    SEEDS,
    Study,
    aggregate_rows,
    arms,
    collect,
    difference,
    emit,
    figures,
    normalised,
    run_or_read,
    sooner_rows,
    status,
    study_arguments,
    teacher_rows,
)

CANDIDATES = ("qfilter", "ce_decay", "bayes_local")
"""The methods of ALGORITHM.md §8 the pilot chooses among."""
PILOT_GAMES = ("minatar-breakout", "minatar-freeway")
PILOT_SEEDS = (TUNE_SEED, TUNE_SEED + 1)
CLOSE = 0.05
"""Mean normalised scores within this of the best are a tie, broken by the lower weight on the agent's states."""
LAST = 0.10
"""The share of a run's last episodes whose `imitation_weight_agent` is averaged."""
NEW_ARM = "ce_decay"
"""The pilot's choice (§14), which tests/test_past_teacher_study.py recomputes from the committed pilot."""
BASELINE = Path(__file__).resolve().parents[1] / "docs" / "data" / "minatar.tar.xz"
"""§13's runs of bayes, ce, DQN and SB3, which stand for those arms (§14's reuse check)."""


def agent_weight(run: FinishedRun) -> float:
    """The mean weight J_E put on the agent's own states over the last LAST of the run's episodes (NaN: none logged)."""
    weights = run.column("imitation_weight_agent")
    tail = weights[-max(1, int(np.ceil(LAST * weights.size))) :]
    return float(np.nanmean(tail)) if np.isfinite(tail).any() else float("nan")


@dataclass(frozen=True)
class PilotArm:
    """One candidate's pilot runs."""

    method: str
    scores: dict[tuple[str, int], float]
    """(game, seed) → normalised score at the budget."""
    weights: dict[tuple[str, int], float]
    """(game, seed) → `agent_weight`."""

    @property
    def mean_score(self) -> float:
        return float(np.mean(list(self.scores.values())))

    @property
    def mean_weight(self) -> float:
        return float(np.nanmean(list(self.weights.values())))


def pilot_arms(source: str | Path) -> list[PilotArm]:
    """Each candidate's pilot runs in `source` (a directory of train.py runs, or its archive); every one of
    the pilot's runs must be there, each at the budget."""
    found: dict[str, PilotArm] = {m: PilotArm(m, {}, {}) for m in CANDIDATES}
    for finished in load_runs(source):
        c = finished.config
        if c.expert_loss in found and c.task in PILOT_GAMES and c.seed in PILOT_SEEDS:
            last = finished.evals[-1]
            if last.interactions < BUDGET:
                raise ConfigError(f"{finished.path}: stopped at {last.interactions:,} interactions, before {BUDGET:,}")
            found[c.expert_loss].scores[c.task, c.seed] = float(normalised(c.task, last.mean_return))
            found[c.expert_loss].weights[c.task, c.seed] = agent_weight(finished)
    missing = [(m, g, s) for m in CANDIDATES for g in PILOT_GAMES for s in PILOT_SEEDS if (g, s) not in found[m].scores]
    if missing:
        raise ConfigError(f"{source}: the pilot lacks {len(missing)} run(s), the first {missing[0]}")
    return list(found.values())


def choose(arms: Sequence[PilotArm]) -> str:
    """§14's rule: the highest mean normalised score; within CLOSE of it, the lowest mean weight on the
    agent's states."""
    best = max(arm.mean_score for arm in arms)
    close = [arm for arm in arms if arm.mean_score >= best - CLOSE]
    return min(close, key=lambda arm: (arm.mean_weight, -arm.mean_score)).method


def pilot_report(arms: Sequence[PilotArm]) -> str:
    """The pilot's runs, a row per candidate, and the choice."""
    lines = [
        "| method | "
        + " | ".join(f"{g.removeprefix('minatar-')} seed {s}" for g in PILOT_GAMES for s in PILOT_SEEDS)
        + " | mean normalised score | mean weight on the agent's states (last 10% of episodes) |",
        "| --- | " + " | ".join("---" for _ in PILOT_GAMES for _ in PILOT_SEEDS) + " | --- | --- |",
    ]
    for arm in arms:
        cells = [f"{arm.scores[g, s]:.2f} (w {arm.weights[g, s]:.2f})" for g in PILOT_GAMES for s in PILOT_SEEDS]
        lines.append(f"| {arm.method} | {' | '.join(cells)} | {arm.mean_score:.3f} | {arm.mean_weight:.3f} |")
    return "\n".join([*lines, "", f"The new arm by §14's rule: **{choose(arms)}**."])


def agent_weights(directory: Path, methods: Sequence[str], quick: bool = False) -> dict[tuple[str, str], list[float]]:
    """(game, method) → each finished run's `agent_weight`, for the runs of the arms of `methods` in `directory`
    (only theirs are read: a run's metrics are most of the time a report takes)."""
    weights: dict[tuple[str, str], list[float]] = {}
    for a in arms(quick, methods):
        for finished in load_runs(directory / a.name) if (directory / a.name).is_dir() else []:
            weights.setdefault((a.task, a.expert_loss), []).append(agent_weight(finished))
    return weights


def report(study: Study, baseline: Study, weights: dict[tuple[str, str], list[float]], figure_dir: Path | None) -> str:
    """The new arm beside §13's arms, by §14's questions: interim (described) until every arm has every seed on
    every game, then the pre-registered verdicts."""
    both = Study(
        {**baseline.runs, **study.runs},
        study.budget,
        SEEDS,
        study.commits,
        methods=(NEW_ARM, *METHODS),
        dqfd=(NEW_ARM, *DQFD),
        anchors=study.anchors,  # the new arm's games: all five, or --quick's two
    )
    judged = both.complete
    lines = [
        "| game | teacher | arm | runs | weight on the agent's states (median over runs) |",
        "| --- | --- | --- | --- | --- |",
    ]
    for game in both.games:
        for method in (NEW_ARM, "bayes"):
            logged = [w for w in weights.get((game, method), []) if np.isfinite(w)]
            median = f"{np.median(logged):.3f}" if logged else "none logged"
            lines.append(f"| {game} | {ANCHORS[game][1]:g} | {method} | {len(logged)} | {median} |")
    return "\n".join(
        [
            "# Past the teacher: the new arm on the five MinAtar games",
            "",
            "Generated by `python -m studies.past_teacher --out docs/data/past-teacher.tar.xz --no-run --report "
            "docs/PAST_TEACHER.md --figures docs/figures` from the new arm's runs (docs/data/past-teacher.tar.xz) "
            "and §13's (docs/data/minatar.tar.xz); rules: docs/PREREGISTRATION.md §14.",
            "",
            status(both),
            "",
            f"`{NEW_ARM}`'s runs' code: {', '.join(study.commits) or 'none yet'}; §13's arms: "
            f"{', '.join(baseline.commits)}.",
            "",
            f"Protocol: §13's, unchanged (docs/MINATAR.md): each game's preset, {study.budget:,} interactions, the "
            "mean of 10 greedy episodes at the budget normalised per game (random 0, teacher 1), IQM with 95% "
            f"stratified-bootstrap intervals. The new arm `{NEW_ARM}` was picked by §14's pilot; `bayes`, `ce`, "
            "`none` (DQN) and SB3's DQN are §13's runs, reused after §14's check.",
            "",
            *questions(both, judged, ["§13's verdict stands as it was read (docs/MINATAR.md); no new runs of either."]),
            "## The weight on the agent's states (described, not judged)",
            "",
            *lines,
            "",
            "Per run: the mean `imitation_weight_agent` over its last 10% of episodes, the weight J_E puts on "
            f"D_replay's rows (w_E for {NEW_ARM}, 1/(2σ²) for bayes; §13's bayes runs logged the mean over every row, "
            "today's code reads 1,024).",
            "",
            *(["## Figures", "", *figures(both, figure_dir, "past_teacher"), ""] if figure_dir is not None else []),
        ]
    )


def questions(study: Study, judged: bool, q3: Sequence[str]) -> list[str]:
    """§14's questions, as §14 and §15 ask them: Q1 and Q2 by §13's rules, Q3 (`q3`, its lines), Q4 (the new arm
    against ce)."""
    comparisons = f"{len(study.dqfd)} DQfD arms × DQN and SB3 × {len(study.games)} {study.unit}s"
    return [
        "## Q1: does each DQfD arm beat its teacher?",
        "",
        *aggregate_rows(study, judged),
        "",
        *teacher_rows(study, judged),
        "",
        "## Q2: does it reach the teacher's score sooner than DQN and SB3?",
        "",
        f"Holm over the {len(study.dqfd) * 2 * len(study.games)} comparisons ({comparisons}).",
        "",
        *sooner_rows(study, judged),
        "",
        "## Q3: do bayes and ce differ?",
        "",
        *q3,
        "",
        f"## Q4: does {NEW_ARM} differ from ce?",
        "",
        *difference(study, judged, NEW_ARM, "ce"),
        "",
    ]


def main(argv: Sequence[str] | None = None) -> int:
    parser = ArgumentParser(prog="python -m studies.past_teacher", description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--pilot", type=Path, help="report the pilot's runs in this directory or archive, and its choice"
    )
    study_arguments(parser, "the new arm's runs", "game", "past_teacher")
    args = parser.parse_args(argv)
    if args.pilot is not None:
        return emit(pilot_report(pilot_arms(args.pilot)), args.report)
    if args.out is None:
        raise ConfigError("give --pilot PATH, or --out DIR for the new arm's runs")
    seeds = 1 if args.quick else args.seeds
    study = run_or_read(args.out, seeds, args.quick, args.no_run, args.archive, args.workers, (NEW_ARM,), False)
    with open_suite(BASELINE) as directory:
        baseline, weights = collect(directory, SEEDS), agent_weights(directory, ("bayes",))
    ours: dict[tuple[str, str], list[float]] = {}
    if args.out.exists():
        with open_suite(args.out) as directory:
            ours = agent_weights(directory, (NEW_ARM,), args.quick)
    return emit(report(study, baseline, {**weights, **ours}, args.figures), args.report)


if __name__ == "__main__":
    raise SystemExit(run(main))
