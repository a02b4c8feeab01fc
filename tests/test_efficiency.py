"""Steps to threshold, SB3 ratios with bootstrap intervals, and the efficiency table (by hand)."""

import csv
import json

import numpy as np
import pytest

from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.demos.experts import expert_returns
from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.evaluation import EvalResult
from dqfd_bc_keras.experiments.data import load_runs
from dqfd_bc_keras.experiments.efficiency import (
    EFFICIENCY_FILE,
    SB3_METHOD,
    ArmSteps,
    efficiency_section,
    interaction_evals,
    load,
    ratio_ci,
    rows,
    save,
    summarise,
    table,
    teacher_table,
    teacher_verdict,
    teachers,
)
from dqfd_bc_keras.training.loop import METRIC_FIELDS

INF = np.inf


def write_run(path, evals: list[dict], final: float = 500.0) -> None:
    """A complete run directory of plain DQN as the lab reads it (config, metrics, evals.csv with the
    columns of `evals`' rows, eval.json, provenance.json)."""
    path.mkdir(parents=True)
    (path / "config.json").write_text(json.dumps(Config.for_task("cartpole", expert_loss="none").to_dict()))
    evals = [{"episode": 0, "std_return": 0.0, "mean_goals": None, **row} for row in evals]
    for name, table_rows in (("metrics.csv", [{f: 0.0 for f in METRIC_FIELDS}]), ("evals.csv", evals)):
        with (path / name).open("w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(table_rows[0]))
            writer.writeheader()
            writer.writerows(table_rows)
    (path / "eval.json").write_text(json.dumps(EvalResult("cartpole", "q", 0, [final], [500]).to_dict()))
    (path / "provenance.json").write_text(
        json.dumps({"code_commit": None, "rules_commit": None, "dirty": None, "versions": {}})
    )


def test_our_steps_are_interactions_not_env_steps(tmp_path):
    """Dynamic-demonstration roll-outs make `interactions` run ahead of `env_step`: only it counts."""
    write_run(
        tmp_path / "run",
        [
            {"env_step": s, "interactions": i, "mean_return": m}
            for s, i, m in ((0, 0, 9.0), (800, 1000, 300.0), (1500, 2000, 480.0))
        ],
    )
    [run] = load_runs(tmp_path)
    assert interaction_evals(run) == [(0.0, 9.0), (1000.0, 300.0), (2000.0, 480.0)]
    arm = ArmSteps.of("cartpole", "bayes", [interaction_evals(run)], [run.final.mean_return], 475.0)
    assert arm.first == [2000.0]


def test_a_run_without_the_interactions_column_is_named_in_the_error(tmp_path):
    write_run(tmp_path / "old", [{"env_step": 1000, "mean_return": 500.0}])
    with pytest.raises(
        ConfigError, match=r"old/evals.csv: no column\(s\) \['interactions'\] in the header: written by"
    ):
        load_runs(tmp_path)


def test_median_counts_never_reached_as_infinite():
    evals = [[(1000, 100.0), (2000, 480.0)], [(0, 500.0)], [(1000, 10.0), (2000, 20.0)]]
    row = summarise(ArmSteps.of("cartpole", "x", evals, [500.0, 474.0, 20.0], 475.0))
    # firsts 2,000, 0 (step 0 counts) and ∞: the median is 2,000
    assert (row["median_steps"], row["reached"], row["above_at_end"], row["seeds"]) == (2000.0, 2, 1, 3)
    never_twice = ArmSteps.of("cartpole", "y", evals[2:] * 2 + evals[:1], [0.0] * 3, 475.0)
    assert summarise(never_twice)["median_steps"] == INF
    half_never = ArmSteps.of("cartpole", "z", evals[:2] + evals[2:] * 2, [0.0] * 4, 475.0)  # 2,000, 0, ∞, ∞
    assert summarise(half_never)["median_steps"] == INF


@pytest.mark.parametrize(
    "theirs, ours, expected",
    [
        ([20_000.0] * 3, [2_000.0] * 5, (10.0, 10.0, 10.0)),  # constant samples: a point interval at the ratio
        ([INF] * 3, [2_000.0] * 2, (INF, INF, INF)),  # SB3 never reaches it: ∞ ÷ finite
        ([30_000.0], [INF, INF], (0.0, 0.0, 0.0)),  # ours never does: finite ÷ ∞
    ],
)
def test_ratio_of_constant_samples(theirs, ours, expected):
    assert ratio_ci(np.array(theirs), np.array(ours)) == expected


def test_ratio_interval_is_open_ended_when_sbs_median_can_be_infinite():
    """theirs = [1000, ∞]: a resample's median is 1,000 with probability ¼ (both draws 1,000), else
    ∞; ours = [100]. So the ratio is 10 w.p. ¼ and ∞ otherwise: point ∞, CI [10, ∞]."""
    assert ratio_ci(np.array([1000.0, INF]), np.array([100.0])) == (INF, 10.0, INF)


def test_ratio_interval_is_undefined_when_neither_side_reaches_it():
    point, low, high = ratio_ci(np.array([INF]), np.array([INF]))
    assert np.isnan(point) and np.isnan(low) and np.isnan(high)


def test_ratio_interval_by_hand():
    """theirs = [20k, 40k], ours = [1k]: resampled medians 20k, 30k (twice as likely), 40k → the
    ratio is 20, 30 or 40 with probabilities ¼, ½, ¼; the 2.5% and 97.5% order statistics: 20 and 40."""
    point, low, high = ratio_ci(np.array([20_000.0, 40_000.0]), np.array([1_000.0]))
    assert (point, low, high) == (30.0, 20.0, 40.0)


def arms() -> list[ArmSteps]:
    return [
        ArmSteps("cartpole", "bayes", [2000.0] * 3, [500.0, 500.0, 400.0], 475.0),
        ArmSteps("cartpole", "none", [None, None, 30_000.0], [0.0] * 3, 475.0),
        ArmSteps("cartpole", SB3_METHOD, [28_000.0, 22_000.0, None], [500.0] * 3, 475.0, anchor=28_000),
        ArmSteps("mountaincar", "bayes", [5000.0], [-100.0], -110.0),
    ]


def test_table_marks_the_goal_on_the_point_estimate_and_states_the_anchor():
    lines = table(arms())
    bayes, none, sb3, mountaincar = lines[2:6]
    assert bayes.startswith("| cartpole bayes | 2,000 | [2,000, 2,000] | 3/3 | 2/3 (500.0) | 14.0× [")
    assert bayes.endswith("| 10×: met |")
    assert none.startswith("| cartpole none | ∞ (not reached) |") and "| 1/3 | 0/3 (0.0) |" in none
    assert sb3.startswith(f"| cartpole {SB3_METHOD} | 28,000; independent check ≈ 28,000 |")
    assert sb3.endswith("| — | — |")
    assert mountaincar.endswith("| — | — |")  # no SB3 arm on MountainCar: no ratio
    assert any("open-ended" in line for line in lines) and any("Undefined" in line for line in lines)
    [row] = [r for r in rows(arms()) if r["arm"] == "cartpole bayes"]
    assert row["ratio"][0] == 14.0 and row["ratio"][2] == INF and row["target_met"]


def test_new_tasks_have_the_5x_goal_and_their_published_anchor():
    """The goal on Acrobot is 5×; SB3's row shows rl-zoo3's published final return beside its median."""
    acrobot = [
        ArmSteps("acrobot", "bayes", [4000.0] * 3, [-80.0, -90.0, -85.0], -100.0),
        ArmSteps("acrobot", SB3_METHOD, [24_000.0] * 3, [-75.0, -77.0, -90.0], -100.0, anchor_final=-76.6),
    ]
    ours, sb3 = table(acrobot)[2:4]
    assert ours.endswith("| 3/3 (-85.0) | 6.0× [6.0×, 6.0×] | 5×: met |")
    assert "| 3/3 (-77.0; published ≈ -76.6) |" in sb3
    assert ArmSteps("acrobot", "ce", [None], [0.0], -100.0).target == 5.0


def test_teacher_rule_reads_the_ci_of_the_median():
    assert teacher_verdict([-80.0] * 5, -112.68) == (-80.0, -80.0, -80.0, "beats its teacher")
    assert teacher_verdict([-150.0] * 5, -112.68)[3] == "does not"
    # median −100, but resampled medians reach −500 (3 of 5 draws at −500 happen): inconclusive
    assert teacher_verdict([-500.0, -500.0, -100.0, -90.0, -80.0], -112.68)[3] == "inconclusive"
    lines = teacher_table(
        [
            ArmSteps("acrobot", "bayes", [1000.0], [-80.0], -100.0),
            ArmSteps("acrobot", SB3_METHOD, [1000.0], [-90.0], -100.0),
        ]
    )
    assert lines[2] == "| acrobot bayes | -112.68 | -80.0 [-80.0, -80.0] | beats its teacher |" and len(lines) == 3
    assert teacher_table(arms()) == []  # no teacher rule on the paper's tasks


@pytest.mark.slow
@pytest.mark.parametrize("task", sorted(teachers()))
def test_teacher_means_are_the_measured_ones(task):
    assert round(expert_returns(task, "imperfect", episodes=100, seed=0).mean(), 2) == teachers()[task]


def test_section_reads_the_file_and_quotes_no_numbers_of_its_own(tmp_path):
    assert "Not run" in efficiency_section(tmp_path)[0]
    (tmp_path / EFFICIENCY_FILE).write_text(json.dumps([{"arm": "cartpole bayes", "median_steps": 3000.0}]))
    assert load(tmp_path / EFFICIENCY_FILE) is None and "predates" in efficiency_section(tmp_path)[0]
    save(tmp_path / EFFICIENCY_FILE, {"eval_every": 1000, "eval_episodes": 10}, arms())
    protocol, loaded = load(tmp_path / EFFICIENCY_FILE)
    assert loaded == arms() and protocol["eval_every"] == 1000
    section = efficiency_section(tmp_path)
    assert "10-episode greedy evaluation" in section[0] and "every 1,000 steps" in section[0]
    assert section[2:] == table(arms())
