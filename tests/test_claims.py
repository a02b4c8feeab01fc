"""The claims analysis on synthetic run directories whose every number is known by hand."""

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from dqfd_bc_keras.experiments import claims as analysis, report as results
from dqfd_bc_keras.experiments.claims import ArmRuns
from dqfd_bc_keras.experiments.data import FinishedRun, load_runs
from dqfd_bc_keras.config import Config
from dqfd_bc_keras.demos import record, save
from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.runs import EVAL_FIELDS
from dqfd_bc_keras.training import METRIC_FIELDS

# cartpole-200 naive: an episode of length L < 200 is a fall, task return L − 1 − 100, plain L
SOLVER = [50] * 5 + [200] + [80] + [200] * 10  # peak at 6, collapse at 7, rule fires at 17
UNFINISHED = ([200] * 9 + [60]) * 2  # never 10 in a row; 2 collapses (the 60s) after the first peak
SOLVER_MEAN = (5 * 50 + 200 + 80 + 10 * 200) / 17


def cartpole_rows(lengths: list[int]) -> list[dict]:
    return [{"return": 200.0 if n >= 200 else n - 101.0, "plain_return": float(n), "length": n, "goals": 0}
            for n in lengths]


def goal_rows(goals: list[int]) -> list[dict]:
    return [{"return": 100.0 * g - (200 - g), "plain_return": -150.0 if g else -200.0, "length": 200, "goals": g}
            for g in goals]


def make_run(path: Path, rows: list[dict], evals: list[float] = (0.0,), final: float = 0.0, **fields) -> FinishedRun:
    """A run of `rows` (episode, env_step, wall_time and losses filled in); evals every 5k steps."""
    config = Config.for_task(**fields)
    steps = np.cumsum([r["length"] for r in rows])
    metrics = [{**{f: 0.0 for f in METRIC_FIELDS}, **r, "episode": i + 1, "env_step": int(steps[i]),
                "wall_time": 60.0 * (i + 1) / len(rows)} for i, r in enumerate(rows)]
    evaluations = [{"env_step": 5000 * i, "episode": 0, "mean_return": m, "std_return": 0.0, "mean_goals": None}
                   for i, m in enumerate(evals)]
    return FinishedRun(path, config, metrics, evaluations, {"task": config.task, "mean_return": final})


def write_run(run: FinishedRun) -> None:
    run.path.mkdir(parents=True)
    (run.path / "config.json").write_text(json.dumps(run.config.to_dict()))
    for name, fields, rows in (("metrics.csv", METRIC_FIELDS, run.metrics), ("evals.csv", EVAL_FIELDS, run.evals)):
        with (run.path / name).open("w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=fields)
            writer.writeheader()
            writer.writerows(rows)
    (run.path / "eval.json").write_text(json.dumps(run.final))


def arm(runs: list[FinishedRun]) -> ArmRuns:
    return analysis.group_arms(runs)[0]


CP = {"task": "cartpole-200", "timeout": "naive"}
MC = {"task": "mountaincar-goals"}


@pytest.fixture(scope="module")
def suite(tmp_path_factory) -> Path:
    """cartpole-200/naive: bayes, ce (3 seeds each, one unfinished run each) and none (2 seeds);
    mountaincar-goals: bayes and ce (4 seeds) and bayes σ0² = 0.05 (4 seeds, fewer goals than ce).
    Directory names are shuffled on purpose: the analysis must group by config.json."""
    root = tmp_path_factory.mktemp("suite")
    runs = []
    for loss in ("bayes", "ce"):
        for seed, lengths in enumerate((SOLVER, UNFINISHED, SOLVER)):
            runs.append((cartpole_rows(lengths), [20.0, 300.0, 480.0, 500.0], 500.0,
                         {**CP, "expert_loss": loss, "seed": seed}))
    runs += [(cartpole_rows([30] * 20), [20.0], 25.0, {**CP, "expert_loss": "none", "seed": s}) for s in (0, 1)]
    for loss, sigma, base in (("bayes", 0.5, 2), ("ce", 0.5, 1), ("bayes", 0.05, 0)):
        for seed in range(4):
            goals = [base + 1] * seed + [base] * (30 - seed) + [3] * 10  # goals_first30 = base + seed/30
            runs.append((goal_rows(goals), [-200.0, -120.0], -130.0,
                         {**MC, "expert_loss": loss, "sigma0_sq": sigma, "seed": seed}))
    order = np.random.default_rng(0).permutation(len(runs))
    for i, (rows, evals, final, fields) in zip(order, runs):
        write_run(make_run(root / f"x{i:02d}" / "run", rows, evals, final, **fields))
    (root / "incomplete").mkdir()
    (root / "incomplete" / "config.json").write_text(json.dumps(Config.for_task("cartpole").to_dict()))
    return root


def test_per_run_metrics_by_hand(tmp_path):
    solver = make_run(tmp_path, cartpole_rows(SOLVER), [20.0, 300.0, 480.0, 500.0], **CP)
    assert analysis.episodes_to_solve(solver) == 17 and analysis.finished(solver)
    assert analysis.collapses(solver) == 1
    assert analysis.PER_RUN["mean_train_return"](solver) == pytest.approx(SOLVER_MEAN)
    assert analysis.steps_to_threshold(solver) == 10_000  # 480 ≥ 475 at the third evaluation
    unfinished = make_run(tmp_path, cartpole_rows(UNFINISHED), [20.0, 400.0], **CP)
    assert analysis.episodes_to_solve(unfinished) is None and not analysis.finished(unfinished)
    assert analysis.PER_RUN["episodes_to_solve"](unfinished) == 21  # censored: its 20 episodes + 1
    assert analysis.PER_RUN["unfinished"](unfinished) == 1.0
    assert analysis.collapses(unfinished) == 2
    assert analysis.steps_to_threshold(unfinished) is None
    goals = make_run(tmp_path, goal_rows([1] * 30 + [3] * 10), [-200.0, -110.0], **MC)
    assert analysis.PER_RUN["goals_first30"](goals) == 1.0
    assert analysis.PER_RUN["goals_all"](goals) == pytest.approx(60 / 40)
    assert analysis.steps_to_threshold(goals) == 5000  # −110 reaches MountainCar-v0's threshold
    assert analysis.episodes_to_solve(goals) is None  # no early-stopping rule on MountainCar


def test_early_stop_rule_follows_the_config(tmp_path):
    run = make_run(tmp_path, cartpole_rows([200] * 3 + [150] + [200] * 3), early_stop_window=3, **CP)
    assert analysis.episodes_to_solve(run) == 3
    run = make_run(tmp_path, cartpole_rows([200] * 3 + [150] + [200] * 3), early_stop_window=3,
                   early_stop_fraction=0.5, max_steps=400, **CP)  # limit 400: 200 ≥ 0.5 × 400
    assert analysis.episodes_to_solve(run) == 3
    assert analysis.collapses(run) == 0  # never ≥ 0.98 × 400


def test_runs_are_grouped_into_arms_by_config(suite):
    runs = load_runs(suite)
    assert len(runs) == 20  # the run without eval.json is left out
    arms = analysis.group_arms(runs)
    assert [(a.label, len(a.runs)) for a in arms] == [
        ("cartpole-200/naive · bayes", 3), ("cartpole-200/naive · ce", 3), ("cartpole-200/naive · none", 2),
        ("mountaincar-goals/bootstrap · bayes sigma0_sq=0.05", 4),
        ("mountaincar-goals/bootstrap · bayes sigma0_sq=0.5", 4), ("mountaincar-goals/bootstrap · ce", 4)]
    assert sorted(r.config.seed for r in arms[0].runs) == [0, 1, 2]
    pairs = analysis.bayes_ce_pairs(arms, "mountaincar-goals", None)
    assert [(b.name, c.name) for b, c in pairs] == [("bayes sigma0_sq=0.5", "ce"), ("bayes sigma0_sq=0.05", "ce")]


def cartpole_arm(tmp_path, loss: str, lengths: list[list[int]]) -> ArmRuns:
    return arm([make_run(tmp_path, cartpole_rows(n), expert_loss=loss, seed=s, **CP) for s, n in enumerate(lengths)])


def test_c1_verdicts_on_clear_data(tmp_path):
    solving = [[100 + i] + [200] * 10 for i in range(4)]  # mean returns 190.9 … 191.2: within ±10
    verdict, comparisons = analysis.judge_c1(cartpole_arm(tmp_path, "bayes", solving),
                                             cartpole_arm(tmp_path, "ce", solving[::-1]))
    assert verdict == "holds"
    assert [c.metric for c in comparisons] == ["episodes_to_solve", "mean_train_return"]
    failing = [[50] * 20] * 4
    verdict, comparisons = analysis.judge_c1(cartpole_arm(tmp_path, "bayes", solving),
                                             cartpole_arm(tmp_path, "ce", failing))
    assert verdict == "does not hold"
    assert comparisons[1].diff[0] > 100 and comparisons[0].p < analysis.ALPHA  # 11 episodes against 21
    mixed = analysis.judge_c1(cartpole_arm(tmp_path, "bayes", [solving[0], failing[0], solving[1]]),
                              cartpole_arm(tmp_path, "ce", [failing[0], solving[2], failing[0]]))[0]
    assert mixed == "inconclusive"


def goals_arm(tmp_path, loss: str, first30: list[float]) -> ArmRuns:
    return arm([make_run(tmp_path, goal_rows([g] * 30), expert_loss=loss, seed=s, **MC)
                for s, g in enumerate(first30)])


def test_c4_verdicts_on_clear_data(tmp_path):
    high, low = goals_arm(tmp_path, "bayes", [5, 6, 7, 8]), goals_arm(tmp_path, "ce", [1, 2, 2, 3])
    assert analysis.judge_c4(high, low)[0] == "holds"
    assert analysis.judge_c4(goals_arm(tmp_path, "bayes", [1, 2, 2, 3]), goals_arm(tmp_path, "ce", [5, 6, 7, 8]))[0] \
        == "does not hold"
    same = analysis.judge_c4(goals_arm(tmp_path, "bayes", [2, 2, 2, 2]), goals_arm(tmp_path, "ce", [2, 2, 2, 2]))
    assert same[0] == "does not hold" and same[1][0].diff == (0.0, 0.0)


def test_c2_and_n_below_two(suite):
    arms = analysis.group_arms(load_runs(suite))
    bayes, ce = analysis.bayes_ce_pairs(arms, "cartpole-200", "naive")[0]
    verdict, (unfinished, falls) = analysis.judge_c2(bayes, ce)
    assert verdict == "holds"  # 1 of 3 unfinished in each arm, collapses in both
    assert unfinished.bayes.mean == pytest.approx(1 / 3) and unfinished.p == 1.0
    assert falls.bayes.mean == pytest.approx((1 + 2 + 1) / 3)
    lone = ArmRuns(bayes.config, bayes.runs[:1], "bayes")
    assert analysis.judge(analysis.CLAIMS[1], lone, ce)[0] == "inconclusive (n < 2)"


def test_demonstrator_return(tmp_path):
    run = make_run(tmp_path / "run", cartpole_rows(SOLVER), expert_loss="bayes", seed=1, **CP)
    recorded = record("cartpole-200", "imperfect", 5, seed=1000, timeout="naive")
    assert analysis.demonstrator_return(run) == pytest.approx(np.mean(recorded.meta.plain_returns))
    strong = record("cartpole-200", "strong", 2, timeout="naive")
    save(strong, tmp_path / "run" / "demos.npz")
    assert analysis.demonstrator_return(run) == pytest.approx(200.0)  # D_demo as saved
    (tmp_path / "run" / "dynamic_demos.json").write_text("[]")  # D_demo grew with the agent's own episodes
    assert analysis.demonstrator_return(run) == pytest.approx(np.mean(recorded.meta.plain_returns))
    assert analysis.demonstrator_return(make_run(tmp_path, cartpole_rows([30]), expert_loss="none", **CP)) is None


def test_report_writes_markdown_and_figures(suite, tmp_path):
    out = tmp_path / "docs" / "RESULTS.md"
    text = results.report(suite, out, tmp_path / "docs" / "figures")
    assert out.read_text() == text
    rows = [line for line in text.splitlines() if line.startswith("| C")]
    claims = [r for r in rows if r.split("|")[2].strip() in ("cartpole/naive", "cartpole/bootstrap")
              or "(n = " in r]
    assert [r.split("|")[1].strip() for r in claims] == ["C1", "C1", "C2", "C3", "C4"]
    assert "not run" in claims[0] and "not run" in claims[3]  # no cartpole runs
    assert "**holds**" in claims[2] and "Fisher exact p = 1" in claims[2]
    assert "**holds**" in claims[4] and "p = 0.0286" in claims[4]  # 4 vs 4 separated: exact p = 2/70
    sensitivity = [r for r in rows if "sigma0_sq=0.05" in r]
    assert len(sensitivity) == 1 and sensitivity[0].endswith("| does not hold | yes |")
    assert "total training wall time 20.0 min" in text
    assert analysis.REGENERATE in text
    assert "| cartpole-200/naive | none | 2 | — | 25.0 [25.0, 25.0] (IQM 25.0) |" in text
    assert "| 500.0 [500.0, 500.0] (IQM 500.0) | " in text and "10,000 (3/3)" in text
    for setting in ("cartpole-200-naive", "mountaincar-goals-bootstrap"):
        for kind in ("curves", "cases"):
            png = tmp_path / "docs" / "figures" / f"{setting}-{kind}.png"
            assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
            assert f"(figures/{setting}-{kind}.png)" in text


def test_report_on_an_empty_suite_says_not_run(tmp_path):
    text = results.report(tmp_path, tmp_path / "RESULTS.md", tmp_path / "figures")
    rows = [line for line in text.splitlines() if line.startswith("| C")]
    assert [r.split("|")[1].strip() for r in rows] == ["C1", "C1", "C2", "C3", "C4"]
    assert all(r.endswith("| not run |") for r in rows)
    assert "0 complete runs" in text and not (tmp_path / "figures").exists()


def test_a_bad_config_names_its_file(tmp_path):
    write_run(make_run(tmp_path / "run", cartpole_rows([30]), **CP))
    (tmp_path / "run" / "config.json").write_text(json.dumps({"task": "cartpole", "colour": "red"}))
    with pytest.raises(ConfigError, match=r"run/config.json: unknown config field\(s\) \['colour'\]"):
        load_runs(tmp_path)


def test_a_run_repeated_in_another_suite_directory_counts_once(tmp_path):
    """Suites sharing arms (paper, sensitivity, the benchmark) may hold the same run twice."""
    for where in ("paper", "sensitivity"):
        write_run(make_run(tmp_path / where / "run", cartpole_rows([30]), expert_loss="ce", seed=3, **CP))
    write_run(make_run(tmp_path / "paper" / "other", cartpole_rows([30]), expert_loss="ce", seed=4, **CP))
    [only] = analysis.group_arms(load_runs(tmp_path))
    assert [r.config.seed for r in only.runs] == [3, 4]


def test_the_reference_pair_is_the_one_at_the_preset(tmp_path):
    """A variant with more seeds (a shorter budget, σ0² …) never displaces the preset pair."""
    runs = []
    for loss in ("bayes", "ce"):
        runs.append(make_run(tmp_path / loss, goal_rows([1]), expert_loss=loss, **MC))
        runs += [make_run(tmp_path / f"{loss}{s}", goal_rows([1]), expert_loss=loss, total_steps=20_000, seed=s, **MC)
                 for s in range(3)]
    arms = analysis.group_arms(runs)
    assert sorted(analysis.preset_distance(a) for a in arms) == [0, 0, 1, 1]
    bayes, ce = analysis.bayes_ce_pairs(arms, "mountaincar-goals", "bootstrap")[0]
    assert (bayes.config["total_steps"], ce.config["total_steps"], len(bayes.runs)) == (100_000, 100_000, 1)


def test_report_quotes_the_sweep_log_and_the_efficiency_table(tmp_path):
    (tmp_path / "sweeps.jsonl").write_text("".join(json.dumps(
        {"suite": suite, "seeds": 10, "runs": runs, "workers": 2, "backend": "local", "seconds": seconds,
         "ended": "2026-11-26 08:00:00"}) + "\n" for suite, runs, seconds in (("paper", 80, 600.0), ("baselines", 9, 300.0))))
    (tmp_path / results.EFFICIENCY_FILE).write_text(json.dumps([
        {"arm": "cartpole bayes", "seeds": 10, "reached": 9, "median_steps": 3000.0, "ci": [2000.0, None],
         "above_at_end": 9},
        {"arm": "mountaincar none", "seeds": 10, "reached": 2, "median_steps": None, "ci": [None, None],
         "above_at_end": 0},
        {"arm": f"cartpole {results.SB3_LABEL}", "seeds": 10, "reached": 10, "median_steps": 22500.0,
         "ci": [16000.0, 27000.0], "above_at_end": 7}]))
    text = results.report(tmp_path, tmp_path / "RESULTS.md", tmp_path / "figures")
    assert "| paper | 10 | 80 | 2 × local | 10.0 min | 2026-11-26 08:00:00 |" in text
    assert "| baselines | 10 | 9 | 2 × local | 5.0 min |" in text and "Sum: 15.0 min" in text
    assert "| cartpole bayes | 3,000 | [2,000, ∞] | 9/10 | 9/10 | 7.5× |" in text  # 22,500 / 3,000
    assert "| mountaincar none | not reached | [∞, ∞] | 2/10 | 0/10 | — |" in text  # no SB3 row, no median
    assert f"| cartpole {results.SB3_LABEL} | 22,500 | [16,000, 27,000] | 10/10 | 7/10 | 1.0× |" in text
    assert "5 episodes of the imperfect scripted expert on CartPole" in text


def test_regenerating_the_report_keeps_the_hand_written_notes(tmp_path):
    out = tmp_path / "RESULTS.md"
    notes = f"{results.NOTES[0]}\n## Summary\nC4 does not hold: see below.\n{results.NOTES[1]}"
    out.write_text(f"# old report\n\n{notes}\n\n| stale | table |\n")
    text = results.report(tmp_path, out, tmp_path / "figures")
    assert text.count(notes) == 1 and "stale" not in text
    assert text.index(notes) < text.index("## Claims")
    assert results.report(tmp_path, out, tmp_path / "figures") == text  # stable on a second pass


def test_trailing_mean_by_hand():
    from dqfd_bc_keras.experiments.figures import trailing_mean

    np.testing.assert_allclose(trailing_mean(np.array([2.0, 4.0, 0.0, 8.0]), 2), [2.0, 3.0, 2.0, 4.0])
    np.testing.assert_allclose(trailing_mean(np.array([1.0, 2.0]), 1), [1.0, 2.0])
