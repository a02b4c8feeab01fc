"""A sweep's wall time with a fresh process per run against worker processes that take many runs.

    python benchmarks/bench_sweep.py                    # C3's two arms, seeds 0-3, 2 rounds (~15 min)
    python benchmarks/bench_sweep.py --seeds 6 --rounds 4 --json
    python benchmarks/bench_sweep.py --quick            # the quick suite's ce arm, 1 seed, 1 round (CI)

Each round runs the same runs twice into fresh directories, on the same `--workers`: once with
`--runs-per-worker 1` (every run a fresh process, as before issue N) and once with the sweep's
default (`sweep.RUNS_PER_WORKER`); the side that goes first alternates by round. It prints each
side's wall time (median, min, max over rounds), the ratio fresh ÷ reused per round, and whether
every run gave the same metrics on both sides (it must: a run sets its own seeds). Writes
nothing but its temporary run directories (removed) unless `--keep DIR`.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import interleave

SIDES = {"fresh": 1, "reused": None}
"""Side → runs per worker (None: the sweep's default)."""


def arms(quick: bool):
    from dqfd_bc_keras.experiments.suites import SUITES

    if quick:
        return [a for a in SUITES["quick"] if a.expert_loss == "ce"]
    return [a for a in SUITES["paper"] if (a.task, a.timeout) == ("cartpole", "bootstrap")]


def results(root: Path) -> dict[str, list]:
    """Every run's metrics (wall time dropped) and final returns, by its directory."""
    found = {}
    for metrics in sorted(root.glob("*/seed*/metrics.csv")):
        rows = [{k: v for k, v in row.items() if k != "wall_time"} for row in csv.DictReader(metrics.open())]
        returns = json.loads((metrics.parent / "eval.json").read_text())["returns"]
        found[str(metrics.parent.relative_to(root))] = [rows, returns]
    return found


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=4, help="seeds 0 … N−1 of each arm (default 4)")
    parser.add_argument("--rounds", type=int, default=2, help="rounds, each running both sides (default 2)")
    parser.add_argument("--workers", type=int, default=2, help="runs at once (default 2: one per core)")
    parser.add_argument("--quick", action="store_true", help="the quick suite's ce arm, 1 seed, 1 round")
    parser.add_argument("--keep", help="keep the run directories under this directory")
    parser.add_argument("--json", action="store_true", help="print the report as one JSON object")
    args = parser.parse_args(argv)
    if args.quick:
        args.seeds, args.rounds = 1, 1
    if min(args.seeds, args.rounds, args.workers) < 1:
        parser.error("--seeds, --rounds and --workers must be ≥ 1")
    from dqfd_bc_keras import runtime

    runtime.configure()  # as the lab's command line does, before TensorFlow loads; its workers inherit it
    from dqfd_bc_keras.experiments.sweep import RUNS_PER_WORKER, SweepOptions, run_jobs, sweep_jobs

    chosen = arms(args.quick)
    load_start = os.getloadavg()
    seconds: dict[str, list[float]] = {side: [] for side in SIDES}
    same: list[bool] = []
    with tempfile.TemporaryDirectory() as temporary:
        scratch = Path(args.keep or temporary)
        for r in range(args.rounds):
            found = {}
            for side in list(SIDES) if r % 2 == 0 else list(SIDES)[::-1]:
                out = scratch / f"round{r + 1}-{side}"
                jobs = sweep_jobs(chosen, args.seeds, out)
                start = time.perf_counter()
                run_jobs(
                    jobs,
                    out,
                    f"bench_sweep {side}",
                    args.seeds,
                    SweepOptions(args.workers, runs_per_worker=SIDES[side] or RUNS_PER_WORKER, progress=lambda _: None),
                )
                seconds[side].append(time.perf_counter() - start)
                found[side] = results(out)
                if not args.json:
                    print(f"round {r + 1}: {side} {seconds[side][-1]:.1f} s", flush=True)
            same.append(found["fresh"] == found["reused"] and len(found["fresh"]) == len(jobs))
    ratios = [f / u for f, u in zip(seconds["fresh"], seconds["reused"], strict=True)]
    report = {
        "benchmark": "bench_sweep",
        "rounds": args.rounds,
        "settings": {
            "arms": [a.name for a in chosen],
            "seeds": args.seeds,
            "workers": args.workers,
            "runs": len(chosen) * args.seeds,
            "runs_per_worker": RUNS_PER_WORKER,
        },
        "seconds": {side: interleave.spread(values, 1) for side, values in seconds.items()},
        "ratio_fresh_over_reused": interleave.spread(ratios, 3),
        "same_results": all(same),
        "code": interleave.code(__file__),
        "versions": interleave.versions(),
        "machine": {
            "cpu_count": os.cpu_count(),
            "loadavg_start": [round(x, 2) for x in load_start],
            "loadavg_end": [round(x, 2) for x in os.getloadavg()],
        },
    }
    if args.json:
        print(json.dumps(report))
    else:
        s, q = report["seconds"], report["ratio_fresh_over_reused"]
        print(
            f"{len(chosen) * args.seeds} runs on {args.workers} workers, {args.rounds} round(s): "
            f"fresh process per run {s['fresh']['median']} s [{s['fresh']['min']}, {s['fresh']['max']}], "
            f"reused workers {s['reused']['median']} s [{s['reused']['min']}, {s['reused']['max']}]; "
            f"fresh ÷ reused {q['median']} [{q['min']}, {q['max']}]; same results per run: {report['same_results']}"
        )
    return 0 if all(same) else 1


if __name__ == "__main__":
    sys.exit(main())
