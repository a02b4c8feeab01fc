"""Does a change to the code change what it learns? The same seeds trained at two code trees, compared.

A speed-up that alters float rounding or a random stream (the order of the BC model's batches,
say) changes every run's trajectory; it must not change learning in distribution. This trains
seeds 0..N−1 of one preset with `train.py` in each of two code trees (e.g. a `git worktree` of the
old commit and this one), over two workers with the two sides of a seed side by side, so both
meet the same load, and compares the lab's per-run metrics (`experiments.metrics.PER_RUN`) and each
run's wall time: per side the median, and the Mann–Whitney p of the difference. `--figure` draws
the greedy-evaluation learning curves of both sides. Runs that are complete are not run again.

    git worktree add /tmp/base <old commit>
    python benchmarks/learning_before_after.py --base /tmp/base --new . --out results/before-after
    python benchmarks/learning_before_after.py --out results/before-after --no-run --figure curves.png
    python benchmarks/learning_before_after.py --quick --base . --new . --out /tmp/ba   # the CI check
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from dqfd_bc_keras.experiments.data import load_runs
from dqfd_bc_keras.experiments.metrics import PER_RUN
from dqfd_bc_keras.experiments.stats import mann_whitney

SIDES = ("base", "new")
METRICS = ("interactions_to_threshold", "episodes_to_solve", "mean_train_return", "final_eval")
WALL_FILE = "wall.jsonl"
"""One line per run this script ran: side, seed, commit, seconds (the whole `train.py` process)."""


def commit(tree: Path) -> str | None:
    done = subprocess.run(["git", "-C", str(tree), "rev-parse", "--short=12", "HEAD"], capture_output=True, text=True)
    return done.stdout.strip() or None


def train(side: str, tree: Path, seed: int, args: argparse.Namespace) -> None:
    """One `train.py` run of `tree` into OUT/side/seedN (skipped when its eval.json exists)."""
    out = args.out / side / f"seed{seed}"
    if (out / "eval.json").is_file():
        return
    command = [
        sys.executable,
        "train.py",
        "--task",
        args.task,
        "--expert-loss",
        args.expert_loss,
        "--seed",
        str(seed),
        "--out",
        str(out.resolve()),
        "--quiet",
        "--force",
        *(["--quick"] if args.quick else []),
    ]
    started = time.perf_counter()
    done = subprocess.run(
        command, cwd=tree, capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(tree.resolve())}
    )
    seconds = time.perf_counter() - started
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["(no stderr)"])[-1]
        raise SystemExit(f"{side} seed {seed} failed (exit {done.returncode}): {last}")
    line = {"side": side, "seed": seed, "commit": commit(tree), "seconds": round(seconds, 2)}
    with open(args.out / WALL_FILE, "a") as log:
        log.write(json.dumps(line) + "\n")


def run_all(args: argparse.Namespace) -> None:
    trees = {"base": args.base, "new": args.new}
    jobs = [(side, trees[side], seed) for seed in range(args.seeds) for side in SIDES]
    args.out.mkdir(parents=True, exist_ok=True)
    with ThreadPoolExecutor(args.workers) as pool:
        list(pool.map(lambda job: train(*job, args), jobs))


def summarise(out: Path) -> dict:
    """Per metric: each side's per-seed values and median, and the Mann–Whitney p."""
    runs = {side: sorted(load_runs(out / side), key=lambda r: r.config.seed) for side in SIDES}
    walls: dict[str, dict[int, float]] = {side: {} for side in SIDES}
    if (out / WALL_FILE).is_file():
        for line in (out / WALL_FILE).read_text().splitlines():
            entry = json.loads(line)
            walls[entry["side"]][entry["seed"]] = entry["seconds"]
    seeds = sorted(set.intersection(*({r.config.seed for r in runs[side]} for side in SIDES)))
    summary: dict = {"seeds": seeds, "metrics": {}}
    values = {side: {r.config.seed: r for r in runs[side]} for side in SIDES}
    columns = {name: {side: [PER_RUN[name](values[side][s]) for s in seeds] for side in SIDES} for name in METRICS}
    columns["wall_seconds"] = {side: [walls[side].get(s, math.nan) for s in seeds] for side in SIDES}
    columns["env_steps"] = {side: [float(values[side][s].metrics[-1]["env_step"]) for s in seeds] for side in SIDES}
    for name, by_side in columns.items():
        finite = all(not math.isnan(v) for side in SIDES for v in by_side[side])
        _, p = mann_whitney(by_side["base"], by_side["new"]) if finite and len(seeds) > 1 else (None, None)
        summary["metrics"][name] = {
            **{side: by_side[side] for side in SIDES},
            **{f"{side}_median": statistics.median(by_side[side]) for side in SIDES},
            "p": p,
        }
    summary["curves"] = {
        side: {s: [(e["interactions"], e["mean_return"]) for e in values[side][s].evals] for s in seeds}
        for side in SIDES
    }
    return summary


def figure(summary: dict, path: Path) -> None:
    """Greedy-evaluation mean return against interactions: each seed thin, the mean over seeds thick."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fig, ax = plt.subplots(figsize=(7, 4))
    for side, colour in zip(SIDES, ("tab:blue", "tab:orange"), strict=True):
        curves = summary["curves"][side].values()
        grid = sorted({step for curve in curves for step, _ in curve})
        # A run that stopped early keeps its last value (no survivor bias in the mean).
        filled = [np.interp(grid, [s for s, _ in c], [m for _, m in c], right=c[-1][1]) for c in curves]
        for line in filled:
            ax.plot(grid, line, color=colour, alpha=0.2, linewidth=0.8)
        ax.plot(grid, np.mean(filled, axis=0), color=colour, linewidth=2, label=f"{side} (mean of {len(filled)} seeds)")
    ax.set_xlabel("interactions")
    ax.set_ylabel("greedy evaluation mean return")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--base", type=Path, help="the code tree before the change")
    parser.add_argument("--new", type=Path, help="the code tree after it")
    parser.add_argument("--out", type=Path, required=True, help="runs go to OUT/base and OUT/new")
    parser.add_argument("--task", default="cartpole")
    parser.add_argument("--expert-loss", default="bayes")
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--quick", action="store_true", help="train.py --quick runs, 1 seed: the CI check")
    parser.add_argument("--no-run", action="store_true", help="summarise the runs in OUT, run nothing")
    parser.add_argument("--figure", type=Path, help="write the learning curves here (PNG)")
    parser.add_argument(
        "--json",
        action="store_true",
        help="print the summary (per-run metrics, wall times and evaluation curves) as one JSON object",
    )
    args = parser.parse_args(argv)
    if args.quick:
        args.seeds = 1
    if not args.no_run:
        if args.base is None or args.new is None:
            parser.error("--base and --new are needed unless --no-run")
        run_all(args)
    summary = summarise(args.out)
    if args.figure:
        figure(summary, args.figure)
    if args.json:
        print(json.dumps(summary))
        return 0
    print(f"{len(summary['seeds'])} seeds per side: {summary['seeds']}")
    for name, m in summary["metrics"].items():
        p = "—" if m["p"] is None else f"{m['p']:.2f}"
        print(
            f"{name:26s} base median {m['base_median']:9.1f}   new median {m['new_median']:9.1f}   Mann–Whitney p {p}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
