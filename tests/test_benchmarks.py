"""The benchmark scripts run and print what they promise (tiny budgets; figures are not judged here)."""

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def bench(name, *args):
    done = subprocess.run([sys.executable, str(REPO / "benchmarks" / name), *map(str, args)],
                          capture_output=True, text=True, timeout=600, cwd=REPO)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_bench_updates_reports_rates_and_ratios():
    figures = bench("bench_updates.py", "--updates", 50, "--steps-per-call", 25, "--losses", "bayes", "--json")
    for key in ("bayes/fused", "bayes/per_call", "bayes/ratio", "bayes/train_step_only",
                "bayes/sample_and_priorities_only"):
        assert figures[key] > 0
    assert abs(figures["bayes/ratio"] - figures["bayes/fused"] / figures["bayes/per_call"]) < 1e-2


def test_bench_online_reports_steps_per_second():
    figures = bench("bench_online.py", "--steps", 300, "--json")
    assert figures["steps_per_s"] > 0
    assert set(figures) == {"steps_per_s", "sb3_steps_per_s", "ratio"}


def test_bench_sample_efficiency_quick(tmp_path):
    rows = bench("bench_sample_efficiency.py", "--quick", "--out", tmp_path, "--json")
    ours = rows[0]
    assert ours["arm"] == "cartpole bayes" and ours["seeds"] == 1
    assert ours["reached"] in (0, 1) and ours["above_at_end"] in (0, 1)
    assert (tmp_path / "cartpole-bootstrap-bayes-eff" / "seed0" / "evals.csv").is_file()


def test_sample_efficiency_median_counts_never_reached_as_infinite():
    spec = importlib.util.spec_from_file_location("bench_se", REPO / "benchmarks" / "bench_sample_efficiency.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    evals = [[(1000, 100.0), (2000, 480.0)], [(1000, 500.0)], [(1000, 10.0), (2000, 20.0)]]
    row = module.summarise("cartpole x", evals, [500.0, 474.0, 20.0], 475.0)
    assert (row["median_steps"], row["reached"], row["above_at_end"], row["seeds"]) == (2000.0, 2, 1, 3)
    assert module.summarise("y", evals[2:] * 2 + evals[:1], [0.0] * 3, 475.0)["median_steps"] is None
