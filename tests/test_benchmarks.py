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


def load_bench(name):
    spec = importlib.util.spec_from_file_location(name.removesuffix(".py"), REPO / "benchmarks" / name)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_bench_sample_efficiency_quick(tmp_path):
    [alone] = bench("bench_sample_efficiency.py", "--quick", "--parts", "sb3", "--out", tmp_path, "--json")
    assert [p.name for p in tmp_path.iterdir()] == ["sb3-dqn"]  # SB3 alone needs none of our runs
    sb3_file = tmp_path / "sb3-dqn" / "cartpole" / "seed0-quick.json"
    written = sb3_file.stat().st_mtime_ns
    ours, sb3 = bench("bench_sample_efficiency.py", "--quick", "--out", tmp_path, "--json")
    assert sb3 == alone and sb3_file.stat().st_mtime_ns == written  # its run is reused, not repeated
    assert ours["arm"] == "cartpole bayes" and ours["seeds"] == 1 and sb3["arm"] == "cartpole SB3 DQN (rl-zoo3)"
    assert ours["reached"] in (0, 1) and ours["above_at_end"] in (0, 1) and len(ours["ratio"]) == 3
    assert (tmp_path / "cartpole-bootstrap-bayes-eff" / "seed0" / "evals.csv").is_file()
    run = json.loads(sb3_file.read_text())
    assert [step for step, _ in run["evals"]] == list(range(0, 1501, 300))
    assert set(run["versions"]) == {"stable-baselines3", "torch", "gymnasium"}
    assert not (tmp_path / "efficiency.json").exists()  # --quick never writes the table
    again = bench("bench_sample_efficiency.py", "--quick", "--no-run", "--out", tmp_path, "--json")
    assert again == [ours, sb3]  # --no-run summarises what is there and runs nothing
    empty = tmp_path / "empty"
    empty.mkdir()
    assert bench("bench_sample_efficiency.py", "--quick", "--no-run", "--out", empty, "--json") == []
    assert [p.name for p in empty.iterdir()] == []


def test_sb3_runs_as_rl_zoo3_does_one_learn_call_evaluated_on_the_exact_grid(tmp_path, monkeypatch):
    """One `learn()` of the whole budget; evaluations at 0, E, 2E, … ≤ budget, although the last
    rollout (train_freq = 256) runs on to step 1,280 past a grid point at 1,200."""
    from stable_baselines3 import DQN

    module, calls, learn = load_bench("bench_sample_efficiency.py"), [], DQN.learn
    monkeypatch.setattr(DQN, "learn", lambda self, **kwargs: calls.append(kwargs) or learn(self, **kwargs))
    module.sb3_run("cartpole", 0, 1150, 100, tmp_path / "run.json")
    run = json.loads((tmp_path / "run.json").read_text())
    assert [c["total_timesteps"] for c in calls] == [1150]
    assert [step for step, _ in run["evals"]] == list(range(0, 1101, 100))
    assert run["hyperparameters"] == {"policy": "MlpPolicy", **module.ZOO["cartpole"]["kwargs"]}
    assert (run["n_timesteps"], run["eval_seed"]) == (1150, 10_000)


def test_sb3_part_alone_reuses_its_runs_and_keeps_our_arms(tmp_path, capsys):
    """`--parts sb3` on finished SB3 files runs nothing, and the table file keeps the arms of ours."""
    from dqfd_bc_keras.experiments.efficiency import EFFICIENCY_FILE, ArmSteps, load, save

    module = load_bench("bench_sample_efficiency.py")
    for task, seed, first in (("cartpole", 0, 20_000), ("cartpole", 1, 30_000), ("mountaincar", 0, None),
                              ("mountaincar", 1, None)):
        budget = module.ZOO[task]["n_timesteps"]
        evals = [(step, 500.0 if first and step >= first else -200.0) for step in range(0, budget + 1, 1000)]
        (tmp_path / "sb3-dqn" / task).mkdir(parents=True, exist_ok=True)
        (tmp_path / "sb3-dqn" / task / f"seed{seed}.json").write_text(
            json.dumps({**module.sb3_settings(task, seed, budget, 1000), "evals": evals}))
    ours = ArmSteps("cartpole", "bayes", [2500.0, 2500.0], [500.0, 500.0], 475.0)
    save(tmp_path / EFFICIENCY_FILE, module.PROTOCOL, [ours])
    assert module.main(["--parts", "sb3", "--seeds", "2", "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert "0 to run" in printed and "25,000; independent check ≈ 28,000" in printed
    assert "| cartpole bayes | 2,500 | [2,500, 2,500] | 2/2 | 2/2 | 10.0× [8.0×, 12.0×] | 10× met |" in printed
    _, arms = load(tmp_path / EFFICIENCY_FILE)
    assert [a.label for a in arms] == ["cartpole bayes", f"cartpole {module.SB3_METHOD}",
                                       f"mountaincar {module.SB3_METHOD}"]
    assert arms[1].first == [20_000.0, 30_000.0] and arms[2].first == [None, None]


def test_memory_long_run_quick_samples_the_curve(tmp_path):
    done = subprocess.run([sys.executable, str(REPO / "benchmarks" / "memory_long_run.py"), "--quick", "--json",
                           str(tmp_path / "rss.json")], capture_output=True, text=True, timeout=600, cwd=REPO)
    assert done.returncode == 0, done.stderr
    assert "MountainCar, 5,000 env steps" in done.stdout and "RSS over the last tenth ÷ RSS over 500–1,000" in done.stdout
    samples = json.loads((tmp_path / "rss.json").read_text())["samples"]
    assert max(step for step, _ in samples) >= 4_000 and samples[-1][1] > 100  # TensorFlow alone is more
