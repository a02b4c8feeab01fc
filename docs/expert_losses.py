"""Which expert loss holds a MinAtar agent at its teacher's level (exploratory, not pre-registered).

In the five-game study (docs/MINATAR.md) the `bayes` and `ce` agents' greedy returns on Breakout and
Freeway stay at their teachers' level from interaction 0 to 100k while plain DQN (`none`, Breakout)
and SB3's DQN (Freeway) climb past them. Both losses pull the Q-network's softmax policy toward the
BC model's on every sampled transition, the agent's own included (docs/ALGORITHM.md §2); DQfD's
`margin` acts on demonstrated transitions only, and `bc_margin` is the same margin on every
transition (a_E = argmax π_bc). This prints, game by game and seed for seed, the study's runs beside
runs of the same preset under the margins: is it the loss's form or its reach that holds the agent?
And on Freeway, where SB3's DQN leaves every arm of ours far behind, plain DQN (`none`) under SB3's
update schedule (Adam at 1e-4, an update every 4 steps, ε to 0.01, the Huber loss): is it the schedule?

    .venv/bin/python docs/expert_losses.py      # the tables, from the committed archives

The probe's runs (the presets' defaults but for the loss or the schedule; one thread each, ~10 minutes a run):

    for loss in margin bc_margin; do for s in 0 1 2 3 4 5; do .venv/bin/python train.py --task minatar-breakout \\
        --expert-loss $loss --seed $s --out runs/expert-losses/minatar-breakout-$loss/seed$s --quiet; done; done
    for s in 0 1 2; do .venv/bin/python train.py --task minatar-freeway --expert-loss margin --seed $s \\
        --out runs/expert-losses/minatar-freeway-margin/seed$s --quiet; done
    for s in 0 1 2; do .venv/bin/python train.py --task minatar-freeway --expert-loss none --seed $s \\
        --set learning_rate=1e-4 --set train_freq=4 --set epsilon_end=0.01 --set td_loss=huber \\
        --out runs/expert-losses/minatar-freeway-none-sb3-schedule/seed$s --quiet; done
    .venv/bin/python -m dqfd_bc_keras.experiments export runs/expert-losses --out docs/data/minatar-expert-losses.tar.xz
"""

from __future__ import annotations

import argparse
import statistics
import sys
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.experiments.data import load_runs, open_suite
from dqfd_bc_keras.experiments.efficiency import SB3_METHOD, interaction_evals
from studies.minatar_study import ANCHORS, BUDGET, GAMES, SEEDS, collect

DATA = Path(__file__).resolve().parent / "data"
SB3_SCHEDULE = {"learning_rate": 1e-4, "train_freq": 4, "epsilon_end": 0.01, "td_loss": "huber"}
"""SB3's DQN's update schedule in the study (rl-zoo3's Atari entry, sb3_pixels.ZOO_ATARI; SB3's Huber loss)."""
ARMS = {  # row → what its imitation applies to, in the order of the tables' rows
    "bayes": "every transition",
    "ce": "every transition",
    "bc_margin": "every transition",
    "margin": "demonstrations only",
    "none": "(no expert loss)",
    "none, SB3's schedule": "(no expert loss)",
    SB3_METHOD: "(no expert loss)",
}


def returns(runs: dict[int, list[tuple[float, float]]]) -> dict[int, list[float]]:
    """Seed → the mean greedy return of each periodic evaluation, for the runs that reached the budget."""
    return {seed: [r for _, r in evals] for seed, evals in sorted(runs.items()) if evals[-1][0] >= BUDGET}


def schedule(config: Config) -> str:
    """The row suffix of a probe run's update schedule: its preset's or SB3's (an error for any other)."""
    preset = Config.for_task(config.task)
    if all(getattr(config, name) == getattr(preset, name) for name in SB3_SCHEDULE):
        return ""
    if all(getattr(config, name) == value for name, value in SB3_SCHEDULE.items()):
        return ", SB3's schedule"
    raise SystemExit(f"{config.task} seed {config.seed}: an update schedule neither its preset's nor {SB3_SCHEDULE}")


def probe_runs(probe: Path) -> tuple[dict[tuple[str, str], dict[int, list[float]]], str]:
    """(task, row) → seed → evaluation returns of the probe's runs, and the code they ran."""
    runs, commits = {}, Counter()
    for run in load_runs(probe):
        c = run.config
        arm = c.expert_loss + schedule(c)
        if arm not in ARMS:
            raise SystemExit(f"{c.task} seed {c.seed}: {arm!r} is none of the tables' rows {list(ARMS)}")
        runs.setdefault((c.task, arm), {})[c.seed] = interaction_evals(run)
        origin = run.provenance
        commits[(origin.code_commit or "unknown")[:7] + " (modified)" * bool(origin.dirty)] += 1
    code = ", ".join(f"{commit}: {n} run{'s' * (n > 1)}" for commit, n in sorted(commits.items()))
    return {arm: returns(seeds) for arm, seeds in runs.items()}, code


def label(arm: str) -> str:
    """An arm as the tables name it: its expert loss in code type, then any schedule (SB3's as it is)."""
    if arm == SB3_METHOD:
        return arm
    loss, _, rest = arm.partition(", ")
    return f"`{loss}`" + (f", {rest}" if rest else "")


def row(loss: str, runs: dict[int, list[float]], teacher: float) -> str:
    """One loss's markdown row: where its greedy policy starts, where it ends, how much it moves."""
    start, end = [r[0] for r in runs.values()], [r[-1] for r in runs.values()]
    best = [max(r) for r in runs.values()]
    distinct = [len(set(r)) for r in runs.values()]
    n = len(next(iter(runs.values())))
    return (
        f"| {label(loss)} | {ARMS[loss]} | {len(runs)} | {statistics.median(start):.2f} | "
        f"{statistics.median(end):.2f} ({', '.join(f'{x:g}' for x in end)}) | {statistics.median(best):.2f} | "
        f"{statistics.median(distinct):g} of {n} | {sum(x > teacher for x in end)} of {len(runs)} |"
    )


def table(game: str, study: dict, probed: dict) -> str | None:
    """The game's table over the seeds every probed loss finished (None if the probe has none)."""
    probed = {loss: seeds for (task, loss), seeds in probed.items() if task == game and seeds}
    if not probed:
        return None
    seeds = set.intersection(*(set(runs) for runs in probed.values()))
    arms = {loss: returns(study.get((game, loss), {})) for loss in ARMS} | probed
    arms = {loss: {s: r for s, r in runs.items() if s in seeds} for loss, runs in arms.items()}
    teacher = ANCHORS[game][1]  # the imperfect expert's mean return over 100 episodes
    return "\n".join(
        [
            f"{game} (its teacher: {teacher:g})",
            "",
            "| expert loss | applied to | seeds | evaluation at interaction 0 (median) | at 100k: median (per seed) "
            "| best evaluation (median) | distinct evaluation returns (median) "
            f"| above the teacher's {teacher:g} at 100k |",
            "| --- | --- | --- | --- | --- | --- | --- | --- |",
            *(row(loss, arms[loss], teacher) for loss in ARMS if arms.get(loss)),
        ]
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--study", type=Path, default=DATA / "minatar.tar.xz", help="the five-game study's archive")
    parser.add_argument("--probe", type=Path, default=DATA / "minatar-expert-losses.tar.xz", help="the probe's runs")
    args = parser.parse_args()
    with open_suite(args.study) as directory:
        study = collect(directory, SEEDS).runs
    probed, code = probe_runs(args.probe)
    tables = [t for game in GAMES if (t := table(game, study, probed)) is not None]
    if not tables:
        raise SystemExit(f"{args.probe}: no run at {BUDGET:,} interactions")
    print("\n\n".join(tables))
    print(f"\nthe probe runs' code: {code}")


if __name__ == "__main__":
    main()
