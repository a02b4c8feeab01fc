"""Which expert loss holds a MinAtar agent at its teacher's level (exploratory, not pre-registered).

In the five-game study (docs/MINATAR.md) the `bayes` and `ce` agents' greedy returns on Breakout and
Freeway stay at their teachers' level from interaction 0 to 100k while plain DQN (`none`, Breakout)
and SB3's DQN (Freeway) climb past them. Both losses pull the Q-network's softmax policy toward the
BC model's on every sampled transition, the agent's own included (docs/ALGORITHM.md §2); DQfD's
`margin` acts on demonstrated transitions only, and `bc_margin` is the same margin on every
transition (a_E = argmax π_bc). This prints, game by game and seed for seed, the study's runs beside
runs of the same preset under the margins: is it the loss's form or its reach that holds the agent?

    .venv/bin/python docs/expert_losses.py      # the tables, from the committed archives

The margin runs (the presets' defaults; one thread each, ~10 minutes a run here):

    for loss in margin bc_margin; do for s in 0 1 2 3 4 5; do .venv/bin/python train.py --task \\
        minatar-breakout --expert-loss $loss --seed $s --out runs/minatar-breakout-$loss/seed$s --quiet; done; done
    for s in 0 1 2; do .venv/bin/python train.py --task minatar-freeway --expert-loss margin --seed $s \\
        --out runs/minatar-freeway-margin/seed$s --quiet; done
    tar -cJf docs/data/minatar-expert-losses.tar.xz -C runs \\
        $(cd runs && ls minatar-*-*margin/seed*/{evals,config,provenance}.*)
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import statistics
import sys
import tarfile
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from dqfd_bc_keras.experiments.minatar_study import ANCHORS, BUDGET, GAMES

DATA = Path(__file__).resolve().parent / "data"
REACH = {  # in the order of the tables' rows
    "bayes": "every transition",
    "ce": "every transition",
    "bc_margin": "every transition",
    "margin": "demonstrations only",
    "none": "(no expert loss)",
}
STUDIED = ("bayes", "ce", "none")  # the five-game study's own arms; the others come from the probe


def evaluations(archive: Path, run: str) -> dict[int, list[float]]:
    """Seed → the mean greedy return of each periodic evaluation (every 5,000 interactions from 0), for
    the runs `run`/seedN/ of a tar archive of run files that reached the budget."""
    runs: dict[int, list[float]] = {}
    with tarfile.open(archive) as tar:
        for member in tar.getmembers():
            parts = member.name.split("/")
            if parts[0] == run and parts[-1] == "evals.csv":
                rows = list(csv.DictReader(io.TextIOWrapper(tar.extractfile(member), encoding="utf-8")))
                if rows and float(rows[-1]["interactions"]) >= BUDGET:
                    runs[int(parts[1].removeprefix("seed"))] = [float(row["mean_return"]) for row in rows]
    return dict(sorted(runs.items()))


def provenance(archive: Path) -> str:
    """The code commits the archive's runs were made with, and how many ran on a modified work tree."""
    with tarfile.open(archive) as tar:
        runs = [json.load(tar.extractfile(m)) for m in tar.getmembers() if m.name.endswith("provenance.json")]
    commits = Counter(run["code_commit"][:7] + (" (modified)" if run["dirty"] else "") for run in runs)
    return ", ".join(f"{commit}: {n} run{'s' * (n > 1)}" for commit, n in sorted(commits.items()))


def row(loss: str, runs: dict[int, list[float]], teacher: float) -> str:
    """One loss's markdown row: where its greedy policy starts, where it ends, how much it moves."""
    start, end = [r[0] for r in runs.values()], [r[-1] for r in runs.values()]
    best = [max(r) for r in runs.values()]
    distinct = [len(set(r)) for r in runs.values()]
    n = len(next(iter(runs.values())))
    return (
        f"| `{loss}` | {REACH[loss]} | {len(runs)} | {statistics.median(start):.2f} | "
        f"{statistics.median(end):.2f} ({', '.join(f'{x:g}' for x in end)}) | {statistics.median(best):.2f} | "
        f"{statistics.median(distinct):g} of {n} | {sum(x > teacher for x in end)} of {len(runs)} |"
    )


def table(game: str, study: Path, probe: Path) -> str | None:
    """The game's table over the seeds every probed loss finished (None if the probe has none)."""
    probed = {loss: evaluations(probe, f"{game}-{loss}") for loss in REACH if loss not in STUDIED}
    probed = {loss: runs for loss, runs in probed.items() if runs}
    if not probed:
        return None
    seeds = set.intersection(*(set(runs) for runs in probed.values()))
    arms = {loss: evaluations(study, f"{game}-bootstrap-{loss}") for loss in STUDIED} | probed
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
            *(row(loss, arms[loss], teacher) for loss in REACH if arms.get(loss)),
        ]
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--study", type=Path, default=DATA / "minatar.tar.xz", help="the five-game study's archive")
    parser.add_argument("--probe", type=Path, default=DATA / "minatar-expert-losses.tar.xz", help="the margin runs")
    args = parser.parse_args()
    tables = [t for game in GAMES if (t := table(game, args.study, args.probe)) is not None]
    if not tables:
        raise SystemExit(f"{args.probe}: no run at {BUDGET:,} interactions")
    print("\n\n".join(tables))
    print(f"\nthe margin runs' code: {provenance(args.probe)}")


if __name__ == "__main__":
    main()
