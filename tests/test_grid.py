"""The lab's quality × quantity grid (rules, `grid --quick` end to end), BC alone, and
the estimators' calibration and section."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from dqfd_bc_keras.demos.experts import expert_returns
from dqfd_bc_keras.experiments.estimators import (
    CALIBRATION_FILE,
    OFF_DEMO,
    STATE_SETS,
    best_other,
    estimators_section,
    meets_goal,
)
from dqfd_bc_keras.experiments.grid import BC_ALONE, DQN, GRID_FILE, Cell, Entry, effect, escapes
from dqfd_bc_keras.experiments.imitation import IMITATION_DIR
from dqfd_bc_keras.experiments.lab_settings import lab_settings
from dqfd_bc_keras.experiments.suites import GRID_METHODS, GRID_TASKS, SUITES, grid_arms, grid_cells

REPO = Path(__file__).resolve().parents[1]
INF = np.inf


def lab(*args, timeout=600):
    return subprocess.run(
        [sys.executable, "-m", "dqfd_bc_keras.experiments", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=REPO,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )


TEACHERS = [(task, teacher) for task in GRID_TASKS for teacher in sorted(lab_settings(task).grid_teachers)]


@pytest.mark.slow
@pytest.mark.parametrize("task, teacher", TEACHERS)
def test_teacher_means_are_the_measured_ones(task, teacher):
    expert, epsilon = teacher
    measured = expert_returns(task, expert, episodes=100, seed=0, epsilon=epsilon).mean()
    assert round(measured, 2) == lab_settings(task).grid_teachers[teacher]


def test_the_grid_is_every_method_on_every_cell_of_each_task_with_plain_dqn_once():
    cells = grid_cells()
    assert len(cells) == 12 and {c["demo_episodes"] for c in cells} == {1, 5, 20}
    arms = SUITES["demos"]
    assert GRID_TASKS == ("cartpole", "mountaincar") and len(arms) == 2 * (1 + 12 * len(GRID_METHODS))
    for task in GRID_TASKS:
        assert {(c["expert"], c["expert_epsilon"]) for c in cells} == set(lab_settings(task).grid_teachers)
        on_task = [a for a in arms if a.task == task]
        assert len(on_task) == 1 + 12 * len(GRID_METHODS) and sum(a.expert_loss == "none" for a in on_task) == 1
    assert all(a.seeds == 5 for a in arms) and len({a.name for a in arms}) == len(arms)
    # CartPole's own cell (imperfect × 5) is the efficiency suite's arms, and plain DQN on both tasks: runs shared
    # (MountainCar's efficiency arms demonstrate 10 episodes, none of the grid's cells).
    efficiency = {a.name for a in SUITES["efficiency"]}
    assert {a.name for a in arms} & efficiency == {
        "cartpole-bootstrap-ce",
        "cartpole-bootstrap-bayes",
        "cartpole-bootstrap-margin",
        "cartpole-bootstrap-none",
        "mountaincar-bootstrap-none-eval1000",
    }
    config = next(a for a in arms if a.name == "cartpole-bootstrap-sqil-strong-eps0.5-demos20").config(3)
    assert (config.expert, config.expert_epsilon, config.demo_episodes, config.seed) == ("strong", 0.5, 20, 3)
    name = "mountaincar-bootstrap-bayes-strong-eps0.2-demos1-distance-eval1000"
    config = next(a for a in arms if a.name == name).config(0)
    assert (config.task, config.total_steps, config.early_stop_window, config.eval_every) == (
        "mountaincar",
        100_000,
        0,
        1_000,
    )
    assert all(a.config(0).total_steps == 600 and a.seeds == 1 for a in grid_arms("cartpole", quick_budget=True))


@pytest.mark.parametrize(
    "method, dqn, expected",
    [
        ([1000] * 5, [9000] * 5, "helps"),
        ([9000] * 5, [1000] * 5, "hurts"),
        ([1000, 9000, 2000, 8000, 5000], [2000, 7000, 1000, 9000, 4000], "unclear"),
        ([INF] * 5, [3000] * 5, "hurts"),  # never reaching it, where DQN does
        ([3000] * 5, [INF] * 5, "helps"),
        ([INF] * 5, [INF] * 5, "unclear"),  # ∞ ÷ ∞: undefined
    ],
)
def test_help_and_hurt_read_the_ratio_interval_against_1(method, dqn, expected):
    entry = lambda steps: Entry(np.array(steps, float), np.full(5, 500.0))
    assert effect(entry(method), entry(dqn)) == expected


def test_escaping_a_teacher_needs_the_whole_interval_above_its_mean():
    cell = Cell("cartpole", "imperfect", 0.0, 5)
    assert cell.teacher_return == 198.06 and cell.name == "imperfect × 5" and cell.threshold == 475
    above = Entry(np.full(5, 1000.0), np.array([300.0, 320, 500, 450, 210]))
    straddling = Entry(np.full(5, 1000.0), np.array([150.0, 300, 190, 250, 180]))
    assert escapes(above, cell) and not escapes(straddling, cell)
    assert Cell("cartpole", "strong", 0.5, 1).teacher == "strong ε=0.5"
    assert (
        Cell("mountaincar", "strong", 0.5, 1).teacher_return == -189.23 < Cell("mountaincar", "strong", 0, 1).threshold
    )
    assert Cell("mountaincar", "strong", 0, 1).teacher_return == -106.39  # above −110: the escape rule skips it


def test_the_summary_line_counts_pairs_and_calls_a_grid_short_of_its_seeds_provisional(tmp_path, monkeypatch):
    """Two cells: DQN never reaches the threshold on one (ce helps there) and matches ce on the other (unclear)."""
    from dqfd_bc_keras.experiments import summary as summarising

    never, matched = Cell("mountaincar", "strong", 0, 1), Cell("mountaincar", "strong", 0, 5)

    def table(ce_seeds: int) -> dict:
        dqn = {never: Entry(np.full(5, INF), np.zeros(5)), matched: Entry(np.full(5, 7000.0), np.zeros(5))}
        ce = {
            never: Entry(np.full(ce_seeds, 1000.0), np.zeros(ce_seeds)),
            matched: Entry(np.full(1, 7000.0), np.zeros(1)),
        }
        return {DQN: dqn, "ce": ce}

    for ce_seeds, tail in (
        (2, " So far from 1–2 of the 5 planned seeds per pair: read these as provisional."),
        (5, " So far from 1–5 of the 5 planned seeds per pair: read these as provisional."),
    ):
        monkeypatch.setattr(
            summarising,
            "collect",
            lambda arms, directory, task, n=ce_seeds: (
                ([never, matched], table(n)) if task == "mountaincar" else ([], {})
            ),
        )
        line = (
            "Demonstration quality × quantity (mountaincar): a method with demonstrations is faster than DQN in 1 of 2 "
            "(cell, method) pairs, slower in 0, unclear in 1." + tail
        )
        assert summarising._grid([], tmp_path) == [line]
    full = {DQN: table(5)[DQN], "ce": {c: Entry(np.full(5, 1000.0), np.zeros(5)) for c in (never, matched)}}
    monkeypatch.setattr(
        summarising,
        "collect",
        lambda arms, directory, task: ([never, matched], full) if task == "mountaincar" else ([], {}),
    )
    assert summarising._grid([], tmp_path)[0].endswith("slower in 0, unclear in 0.")


@pytest.mark.slow
def test_grid_quick_runs_every_method_writes_the_tables_and_heatmaps_and_skips_finished_runs(tmp_path):
    done = lab("grid", "--quick", "--out", tmp_path)
    assert done.returncode == 0, done.stderr[-2000:]
    text = (tmp_path / GRID_FILE).read_text()
    rows = {line.split(" | ")[0].lstrip("| ") for line in text.splitlines() if line.startswith("| ")}
    assert {DQN, "margin", "ce", "bayes (mc_dropout)", "bayes (distance)", "SQIL", BC_ALONE} <= rows
    assert "| method | strong ε=0.5 × 1 |\n" in text and "### cartpole" in text and "mountaincar" not in text
    for name in ("grid-cartpole-interactions.png", "grid-cartpole-final.png"):
        assert (tmp_path / "figures" / name).stat().st_size > 10_000
    bc = json.loads(
        (tmp_path / IMITATION_DIR / "cartpole-bootstrap-bc-alone-strong-eps0.5-demos1-quick" / "seed0.json").read_text()
    )
    assert bc["config"]["demo_episodes"] == 1 and bc["episodes"] == 2 and bc["demo_transitions"] >= 1
    sqil = json.loads(
        (tmp_path / "cartpole-bootstrap-sqil-strong-eps0.5-demos1-quick" / "seed0" / "config.json").read_text()
    )
    assert (sqil["expert_loss"], sqil["expert"], sqil["expert_epsilon"], sqil["total_steps"]) == (
        "sqil",
        "strong",
        0.5,
        600,
    )
    again = lab("grid", "--quick", "--out", tmp_path)
    assert again.returncode == 0 and "6 already complete, 0 to run" in again.stdout


def summary(ratios: dict[str, tuple[float, float]]) -> dict:
    """A calibration summary whose estimators have these (random, far) off/on ratios on one task."""
    entries = {}
    for u, (random, far) in ratios.items():
        means = {
            "held-out demos": 0.01,
            "trained agent": 0.01,
            "random policy": 0.01 * random,
            "3–6 std away": 0.01 * far,
        }
        entries[u] = {
            "mean": means,
            "ratio": {n: means[n] / 0.01 for n in STATE_SETS[1:]},
            "share_of_max": {n: means[n] / 0.25 for n in STATE_SETS},
        }
    return {
        "goal_ratio": 5.0,
        "seeds": 3,
        "episodes": 5,
        "n_actions": {"cartpole": 2},
        "tasks": {"cartpole": entries},
        "best_other": "distance",
    }


def test_the_best_other_estimator_is_the_larger_geometric_mean_of_the_off_demo_ratios():
    assert OFF_DEMO == ("random policy", "3–6 std away")
    assert best_other(summary({"mc_dropout": (100, 100), "ensemble": (2, 50), "distance": (9, 9)})) == "ensemble"
    assert best_other(summary({"mc_dropout": (100, 100), "ensemble": (2, 30), "distance": (9, 9)})) == "distance"
    entries = summary({"mc_dropout": (5, 5), "ensemble": (4.9, 100), "distance": (9, 9)})["tasks"]["cartpole"]
    assert meets_goal(entries["mc_dropout"]) and not meets_goal(entries["ensemble"])


def test_estimators_section_reads_calibration_json_and_draws_the_figure(tmp_path):
    assert "Not run" in estimators_section([], tmp_path, tmp_path / "figures", tmp_path)[0]
    (tmp_path / CALIBRATION_FILE).write_text(
        json.dumps(summary({"mc_dropout": (0.8, 6), "ensemble": (0.5, 6.4), "distance": (9, 14.7)}))
    )
    text = "\n".join(estimators_section([], tmp_path, tmp_path / "figures", tmp_path))
    assert "| cartpole | distance | 0.01 | 0.01 | 0.09 | 0.15 | 9 | 14.7 | met |" in text
    assert "| cartpole | mc_dropout | 0.01 | 0.01 | 0.008 | 0.06 | 0.8 | 6 | not met |" in text
    assert "no estimator arms have run" in text and (tmp_path / "figures" / "calibration.png").is_file()


@pytest.mark.slow
def test_calibrate_quick_measures_every_estimator_on_every_kind_of_state(tmp_path):
    done = lab("calibrate", "--quick", "--out", tmp_path / "c.json", "--figure", tmp_path / "c.png")
    assert done.returncode == 0, done.stderr[-2000:]
    result = json.loads((tmp_path / "c.json").read_text())
    entries = result["tasks"]["cartpole"]
    assert set(entries) == {"mc_dropout", "ensemble", "distance"} and result["best_other"] in ("ensemble", "distance")
    for entry in entries.values():
        assert set(entry["mean"]) == set(STATE_SETS) and all(v >= 0 for v in entry["mean"].values())
        assert all(0 <= v <= 1 for v in entry["share_of_max"].values())
    assert (tmp_path / "c.png").stat().st_size > 10_000 and "best other estimator" in done.stdout


def test_grid_task_is_one_of_the_grids_tasks(tmp_path):
    done = lab("grid", "--task", "acrobot", "--out", tmp_path, timeout=60)
    assert done.returncode == 2 and "invalid choice: 'acrobot'" in done.stderr and "mountaincar" in done.stderr
    assert not any(tmp_path.iterdir())
