"""The benchmark scripts run and print what they promise (tiny budgets; figures are not judged here)."""

import importlib.util
import json
import statistics
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import call

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[1]


def bench(name, *args):
    done = subprocess.run(
        [sys.executable, str(REPO / "benchmarks" / name), *map(str, args)],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=REPO,
    )
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def efficiency(*args):
    """The lab's `efficiency` command, which bench_sample_efficiency.py is, answered in this process (the
    script itself is run as a user types it once per test: a process each time would only add imports)."""
    done = call("dqfd_bc_keras.experiments", "efficiency", *args)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def check_interleaved(report, sides, rounds=2):
    """`rounds` rounds, first place alternating, each side's figures as median/min/max over them, the
    ratio paired by round."""
    present = [["ours", "sb3"], ["sb3", "ours"]] if report["sides"]["sb3"] else [["ours"], ["ours"]]
    assert report["rounds"] == rounds and report["order"] == present[:rounds]
    assert report["versions"]["tensorflow"] and "stable-baselines3" in report["versions"]
    assert report["machine"]["threads"] == {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "DQFD_TF_THREADS": "1"}
    processes = report["machine"]["processes"]
    assert processes["ours"]["torch_imported"] is False and processes["ours"]["tf_intra_op_threads"] == 1
    assert set(report["code"]) == {"commit", "package_modified"}
    for side, figure in sides:
        s = report["sides"][side][figure]
        assert len(s["per_round"]) == rounds and 0 < s["min"] <= s["median"] <= s["max"]
        assert s["median"] == pytest.approx(statistics.median(s["per_round"]), abs=1e-3)  # rounded to 3 decimals
    if report["sides"]["sb3"] is None:  # SB3 not installed: reported absent, no ratio
        assert report["ratio"] is None
        return
    assert processes["sb3"]["tensorflow_imported"] is False and processes["sb3"]["torch_threads"] == 1
    ratio = report["ratio"]
    assert 0 < ratio["min"] <= ratio["median"] <= ratio["max"]
    assert ratio["median"] == pytest.approx(statistics.median(ratio["per_round"]), abs=1e-4)
    ours_figure, sb3_figure = sides[0][1], sides[-1][1]
    per_round = [
        a / b
        for a, b in zip(
            report["sides"]["ours"][ours_figure]["per_round"],
            report["sides"]["sb3"][sb3_figure]["per_round"],
            strict=True,
        )
    ]
    assert ratio["per_round"] == pytest.approx(per_round, rel=1e-3)  # paired by round, not medians divided


def test_bench_updates_reports_rates_and_ratios():
    report = bench("bench_updates.py", "--quick", "--json")
    ours = report["sides"]["ours"]
    assert set(ours) == {
        "bayes/fused",
        "bayes/per_call",
        "bayes/ratio",
        "bayes/train_step_only",
        "bayes/sample_and_priorities_only",
    }
    for fused, per_call, ratio in zip(
        *(ours[f"bayes/{k}"]["per_round"] for k in ("fused", "per_call", "ratio")), strict=True
    ):
        assert ratio == pytest.approx(fused / per_call, rel=1e-3)
    check_interleaved(
        report, [("ours", "bayes/fused"), ("sb3", "train")] if report["sides"]["sb3"] else [("ours", "bayes/fused")]
    )
    assert report["ratio"] is None or report["ratio"]["of"] == "ours bayes/fused / sb3 train"


def test_bench_online_reports_steps_per_second():
    report = bench("bench_online.py", "--quick", "--json")
    check_interleaved(
        report,
        [("ours", "steps_per_s"), ("sb3", "steps_per_s")] if report["sides"]["sb3"] else [("ours", "steps_per_s")],
        rounds=1,
    )
    assert report["settings"]["steps"] == 300


def test_a_failing_side_fails_the_benchmark_in_one_line():
    done = subprocess.run(
        [
            sys.executable,
            str(REPO / "benchmarks" / "bench_online.py"),
            "--rounds",
            "1",
            "--expert-loss",
            "nope",
            "--json",
        ],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=REPO,
    )
    assert done.returncode != 0
    [line] = done.stderr.strip().splitlines()
    assert "the ours side failed in round 1" in line and "expert_loss='nope'" in line


def test_interleave_alternates_first_place_and_pairs_ratios_by_round():
    interleave = load_bench("interleave.py")
    assert interleave.order(4) == [["ours", "sb3"], ["sb3", "ours"], ["ours", "sb3"], ["sb3", "ours"]]
    assert interleave.order(3, ["ours"]) == [["ours"]] * 3
    ours = [{"rate": 10.0}, {"rate": 30.0}, {"rate": 20.0}]
    sb3 = [{"rate": 10.0}, {"rate": 10.0}, {"rate": 40.0}]
    summary = interleave.summarise({"ours": ours, "sb3": sb3}, {"rate": ("rate", "rate")})
    assert summary["sides"]["ours"]["rate"] == {
        "median": 20.0,
        "min": 10.0,
        "max": 30.0,
        "per_round": [10.0, 30.0, 20.0],
    }
    ratio = summary["ratios"]["rate"]
    assert ratio["per_round"] == [1.0, 3.0, 0.5]  # round by round, not median ÷ median (20 / 10 = 2)
    assert (ratio["median"], ratio["min"], ratio["max"]) == (1.0, 0.5, 3.0)
    assert (
        interleave.summarise({"ours": ours[:2], "sb3": sb3[:2]}, {"rate": ("rate", "rate")})["ratios"]["rate"]["median"]
        == 2.0
    )  # an even count: the mean of the middle two
    absent = interleave.summarise({"ours": ours, "sb3": None}, {"rate": ("rate", "rate")})
    assert absent["sides"]["sb3"] is None and absent["ratios"]["rate"] is None


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
    ours, sb3 = efficiency("--quick", "--out", tmp_path, "--json")
    assert sb3 == alone and sb3_file.stat().st_mtime_ns == written  # its run is reused, not repeated
    assert ours["arm"] == "cartpole bayes" and ours["seeds"] == 1 and sb3["arm"] == "cartpole SB3 DQN (rl-zoo3)"
    assert ours["reached"] in (0, 1) and ours["above_at_end"] in (0, 1) and len(ours["ratio"]) == 3
    assert (tmp_path / "cartpole-bootstrap-bayes-eff" / "seed0" / "evals.csv").is_file()
    run = json.loads(sb3_file.read_text())
    assert [step for step, _ in run["evals"]] == list(range(0, 1501, 300))
    assert set(run["versions"]) == {"stable-baselines3", "torch", "gymnasium"}
    assert not (tmp_path / "efficiency.json").exists()  # --quick never writes the table
    again = efficiency("--quick", "--no-run", "--out", tmp_path, "--json")
    assert again == [ours, sb3]  # --no-run summarises what is there and runs nothing
    empty = tmp_path / "empty"
    empty.mkdir()
    assert efficiency("--quick", "--no-run", "--out", empty, "--json") == []
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
    for task, seed, first in (
        ("cartpole", 0, 20_000),
        ("cartpole", 1, 30_000),
        ("mountaincar", 0, None),
        ("mountaincar", 1, None),
    ):
        budget = module.ZOO[task]["n_timesteps"]
        evals = [(step, 500.0 if first and step >= first else -200.0) for step in range(0, budget + 1, 1000)]
        (tmp_path / "sb3-dqn" / task).mkdir(parents=True, exist_ok=True)
        (tmp_path / "sb3-dqn" / task / f"seed{seed}.json").write_text(
            json.dumps({**module.sb3_settings(task, seed, budget, 1000), "evals": evals})
        )
    ours = ArmSteps("cartpole", "bayes", [2500.0, 2500.0], [500.0, 500.0], 475.0)
    save(tmp_path / EFFICIENCY_FILE, module.PROTOCOL, [ours])
    assert (
        module.main(["--parts", "sb3", "--seeds", "2", "--tasks", "cartpole,mountaincar", "--out", str(tmp_path)]) == 0
    )
    printed = capsys.readouterr().out
    assert "0 to run" in printed and "25,000; independent check ≈ 28,000" in printed
    assert "| cartpole bayes | 2,500 | [2,500, 2,500] | 2/2 | 2/2 (500.0) | 10.0× [8.0×, 12.0×] | 10×: met |" in printed
    _, arms = load(tmp_path / EFFICIENCY_FILE)
    assert [a.label for a in arms] == [
        "cartpole bayes",
        f"cartpole {module.SB3_METHOD}",
        f"mountaincar {module.SB3_METHOD}",
    ]
    assert arms[1].first == [20_000.0, 30_000.0] and arms[2].first == [None, None]


def test_memory_long_run_quick_samples_the_curve(tmp_path):
    done = subprocess.run(
        [
            sys.executable,
            str(REPO / "benchmarks" / "memory_long_run.py"),
            "--quick",
            "--json",
            str(tmp_path / "rss.json"),
        ],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=REPO,
    )
    assert done.returncode == 0, done.stderr
    assert (
        "MountainCar, 5,000 env steps" in done.stdout and "RSS over the last tenth ÷ RSS over 500–1,000" in done.stdout
    )
    samples = json.loads((tmp_path / "rss.json").read_text())["samples"]
    assert max(step for step, _ in samples) >= 4_000 and samples[-1][1] > 100  # TensorFlow alone is more


def test_learning_before_after_quick_same_code_same_seed_learns_the_same(tmp_path):
    """Both sides the same tree: every metric of seed 0 is identical (training is deterministic), the
    wall time of each run is logged, and a summary with --no-run runs nothing again."""
    summary = bench("learning_before_after.py", "--quick", "--base", REPO, "--new", REPO, "--out", tmp_path, "--json")
    assert summary["seeds"] == [0]
    for name in ("interactions_to_threshold", "episodes_to_solve", "mean_train_return", "final_eval", "env_steps"):
        metric = summary["metrics"][name]
        assert metric["base"] == metric["new"] and len(metric["base"]) == 1, name
    assert all(s > 0 for side in ("base", "new") for s in summary["metrics"]["wall_seconds"][side])
    logged = (tmp_path / "wall.jsonl").read_text()
    again = bench("learning_before_after.py", "--no-run", "--out", tmp_path, "--figure", tmp_path / "c.png", "--json")
    assert again == summary and (tmp_path / "wall.jsonl").read_text() == logged
    assert (tmp_path / "c.png").read_bytes()[:4] == b"\x89PNG"


def test_sample_efficiency_refuses_an_unknown_task(capsys):
    module = load_bench("bench_sample_efficiency.py")
    with pytest.raises(SystemExit) as exit:
        module.main(["--tasks", "cartpole,pong", "--no-run"])
    assert exit.value.code == 2 and "unknown task(s) ['pong']" in capsys.readouterr().err


def test_bench_pixels_quick_reports_both_sides_on_minatar():
    report = bench("bench_pixels.py", "--quick", "--json")
    assert report["settings"]["task"] == "minatar-breakout" and report["settings"]["train_freq"] == 4
    ours, sb3 = report["sides"]["ours"], report["sides"]["sb3"]
    assert ours["env_steps_per_s"]["median"] > 0 and ours["pretrain_updates_per_s"]["median"] > 0
    assert sb3["env_steps_per_s"]["median"] > 0 and sb3["train_updates_per_s"]["median"] > 0
    assert set(report["ratios"]) == {"env_steps_per_s", "pretrain_vs_sb3_train"}


def test_memory_frames_quick_states_the_pool_and_the_alternatives():
    done = subprocess.run(
        [sys.executable, str(REPO / "benchmarks" / "memory_frames.py"), "--quick"],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=REPO,
    )
    assert done.returncode == 0, done.stderr
    rows = {line[:30].strip(): line[30:].split() for line in done.stdout.splitlines()[2:]}
    # Atari at 1,000 transitions, scaled to 100k: 2 slots × 7,056 bytes × (1,000 + 10 + 4) rows ÷ 1,000 × 100k.
    assert float(rows["Atari (84×84, 4 stacked)"][1].replace(",", "")) == pytest.approx(
        2 * 84 * 84 * 1014 * 100 / 1e6, abs=0.1
    )
    assert float(rows["cartpole (4 floats)"][1]) == 0.0  # no pool for vectors


def test_bench_sweep_quick_times_both_sides_and_finds_the_same_results():
    report = bench("bench_sweep.py", "--quick", "--json")
    assert report["same_results"] and set(report["seconds"]) == {"fresh", "reused"}
    fresh, reused = report["seconds"]["fresh"]["per_round"], report["seconds"]["reused"]["per_round"]
    # The ratio is of the unrounded times; the report's seconds are rounded to 0.1 s, the ratio to 0.001.
    for ratio, f, r in zip(report["ratio_fresh_over_reused"]["per_round"], fresh, reused, strict=True):
        assert (f - 0.05) / (r + 0.05) - 5e-4 <= ratio <= (f + 0.05) / (r - 0.05) + 5e-4, (ratio, f, r)


def test_the_numpy_loop_probe_computes_what_the_package_computes():
    """The probe's figure is only worth reading if its numpy parts are the package's: Q of MinAtar's
    network, the n-step views of D_demo, and the BC model's MC-dropout view (its mean over many
    draws; the draws themselves are numpy's)."""
    import numpy as np
    import tensorflow as tf

    from dqfd_bc_keras.core.config import Config
    from dqfd_bc_keras.training.loop import build

    probe = load_bench("numpy_loop_probe.py")
    c = Config.for_task("minatar-breakout", total_steps=100, pretrain_steps=20, bc_epochs=1, demo_episodes=2)
    learner, _ = build(c)
    agent, demos = learner.agent, learner.demos
    scale = agent.net_input.frames.scale
    theta = [w.numpy() for w in agent.q_network.trainable_weights]
    np.testing.assert_allclose(
        probe.minatar_forward(theta, demos.obs[:64], scale), agent.q_network(demos.obs[:64]).numpy(), atol=1e-5
    )
    view = probe.bc_view(learner.bc, scale, np.random.default_rng(0))
    replay = probe.NumpyReplay(
        agent.net_input.shape, agent.n_actions, c.replay_capacity, c.demo_capacity, c.n_step, c.gamma,
        c.priority_alpha, c.priority_eps_agent, c.priority_eps_demo, c.seed,
    )  # fmt: skip
    replay.set_demos(demos.obs, demos.actions, demos.rewards, demos.next_obs, demos.terminated, demos.truncated,
                     *view(demos.obs))  # fmt: skip
    n = len(demos.obs)
    package = agent.replay._batch(tf.range(n), tf.ones([n]))
    np.testing.assert_allclose(replay.n_return[:n], package.n_returns.numpy(), rtol=1e-6)
    np.testing.assert_allclose(replay.n_discount[:n], package.n_discount.numpy(), rtol=1e-6)
    np.testing.assert_array_equal(replay.next_obs[replay.n_last[:n]], package.n_next_obs.numpy())
    states = demos.obs[:16]
    ours = np.mean([view(states)[0] for _ in range(400)], axis=0)
    theirs = np.mean([learner.bc.predictive(tf.constant(states))[0].numpy() for _ in range(400)], axis=0)
    np.testing.assert_allclose(ours, theirs, atol=0.02)


def test_bench_pixels_quick_times_the_numpy_loop_probe():
    report = bench("bench_pixels.py", "--quick", "--json", "--design", "numpy-probe", "--sides", "ours")
    assert report["settings"]["design"] == "numpy-probe" and report["sides"]["sb3"] is None
    assert report["sides"]["ours"]["env_steps_per_s"]["median"] > 0
    assert set(report["ratios"]) == {"env_steps_per_s"}  # the probe does not time pre-training


def test_the_numpy_loop_probe_refuses_plain_dqn_in_one_line():
    done = subprocess.run(
        [sys.executable, str(REPO / "benchmarks" / "bench_pixels.py"), "--design", "numpy-probe", "--expert-loss=none"],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=REPO,
    )
    assert done.returncode == 2 and "needs demonstrations" in done.stderr.splitlines()[-1]
