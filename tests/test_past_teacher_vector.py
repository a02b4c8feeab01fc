"""W's study on Acrobot, LunarLander and MiniGrid (PREREGISTRATION §15): the pilot's budget rule by hand,
the anchors as measured, and the command as a user runs it (quick runs exported as they finish, SB3 on
MiniGrid through rl-zoo3's wrapper, the report regenerated from the archive byte for byte)."""

import json
import tarfile

import numpy as np
import pytest
from helpers import REPO
from helpers import python as run
from PIL import Image

from dqfd_bc_keras.demos.recording import expert_returns
from studies import past_teacher_vector as study
from studies.minatar_study import Study
from studies.past_teacher_vector import ANCHORS, PILOT_SEEDS, pilot_budget

A, B = PILOT_SEEDS


def reach(none_a, none_b, sb3_a, sb3_b):
    return {("none", A): none_a, ("none", B): none_b, ("SB3 DQN (rl-zoo3)", A): sb3_a, ("SB3 DQN (rl-zoo3)", B): sb3_b}


def test_the_pilots_budget_is_the_smallest_by_which_one_arm_reached_the_teacher_in_both_runs():
    assert pilot_budget(reach(19_000, 24_000, np.inf, 3_000)) == 25_000  # DQN, both by 25k
    assert pilot_budget(reach(19_000, 26_000, np.inf, 3_000)) == 50_000  # neither in both by 25k; DQN by 50k
    assert pilot_budget(reach(60_000, 26_000, 40_000, 50_000)) == 50_000  # SB3 both by 50k
    assert pilot_budget(reach(60_000, 26_000, np.inf, 3_000)) == 100_000  # DQN both by 100k only
    assert pilot_budget(reach(np.inf, np.inf, np.inf, np.inf)) == 100_000  # never: 100k, which the study says


@pytest.mark.parametrize("task", list(ANCHORS))
def test_the_anchors_are_the_random_policys_and_the_teachers_mean_over_100_episodes(task):
    random, teacher = ANCHORS[task]
    assert np.mean(expert_returns(task, "imperfect", 100, 0, epsilon=1.0)) == pytest.approx(random, rel=1e-9)
    assert np.mean(expert_returns(task, "imperfect", 100, 0)) == pytest.approx(teacher, rel=1e-9)


def test_the_study_reuses_only_sevens_bayes_and_sb3_runs():
    assert set(study.REUSED_ARMS) == {
        (t, m) for t in ("acrobot", "lunarlander") for m in ("bayes", "SB3 DQN (rl-zoo3)")
    }
    new = study.new_runs()
    assert len(new) == 3 * 5 - 4 and not set(new) & set(study.REUSED_ARMS)
    # §7's bayes runs keep their names (the efficiency suite's arm): a reused run is found where it was made
    assert study.ours("acrobot", "bayes").name == "acrobot-bootstrap-bayes"


def curve(reached_at):
    """An Acrobot evaluation curve that first reaches −100 at `reached_at` (None: never) of 20,000."""
    return [(x, -90.0 if reached_at is not None and x >= reached_at else -400.0) for x in range(0, 20_001, 1000)]


def test_q5_divides_sb3s_median_interactions_to_the_threshold_by_each_arms():
    runs = {
        ("acrobot", "ce_decay"): {0: curve(1000), 1: curve(1000), 2: curve(2000)},  # median 1,000
        ("acrobot", "bayes"): {0: curve(4000), 1: curve(5000), 2: curve(None)},  # median 5,000
        ("acrobot", "SB3 DQN (rl-zoo3)"): {0: curve(9000), 1: curve(10_000), 2: curve(12_000)},  # median 10,000
    }
    found = Study(runs, 20_000, 3, (), study.METHODS, study.DQFD, {"acrobot": ANCHORS["acrobot"]}, unit="task")
    rows = {row.split(" | ")[2]: row for row in study.ratio_rows(found)[2:]}
    assert rows["ce_decay"].startswith("| acrobot | -100 | ce_decay | 3/3 | 1,000 | 10.0× [")
    assert rows["ce_decay"].endswith("| met |")  # 10,000 ÷ 1,000 = 10: §3's rule reads the point estimate
    assert "| 2/3 | 5,000 | 2.0× [" in rows["bayes"] and rows["bayes"].endswith("| not met: 2.0× |")
    assert rows["ce"] == "| acrobot | -100 | ce | not run | | | |"
    assert rows["SB3 DQN (rl-zoo3)"].endswith("| 3/3 | 10,000 | — | — |")


@pytest.mark.slow
def test_the_quick_study_runs_every_arm_exports_each_run_and_reports_from_its_archive(tmp_path):
    out, archive = tmp_path / "runs", tmp_path / "vector.tar.xz"
    done = run(
        "-m",
        "studies.past_teacher_vector",
        "--out",
        out,
        "--archive",
        archive,
        "--quick",
        "--report",
        tmp_path / "a.md",
    )
    assert done.returncode == 0, done.stderr
    with tarfile.open(archive) as tar:
        names = tar.getnames()
    # ours: the 4 arms on MiniGrid and the 3 new ones on Acrobot (§7's bayes and SB3 are not run again)
    assert sum(name.endswith("/eval.json") for name in names) == 4 + 3
    assert not (out / "sb3-dqn" / "acrobot").exists()
    sb3 = json.loads((out / "sb3-dqn" / "minigrid-empty" / "seed0-quick.json").read_text())
    assert sb3["hyperparameters"]["env_wrapper"] == "minigrid.wrappers:FlatObsWrapper"
    assert [x for x, _ in sb3["evals"]] == [0, 100, 200, 300]  # the grid, on SB3's own counter
    assert all(0.0 <= y <= 1.0 for _, y in sb3["evals"])  # MiniGrid's returns, played through the wrapper
    done = run(
        "-m", "studies.past_teacher_vector", "--out", archive, "--no-run", "--quick", "--report", tmp_path / "b.md"
    )
    assert done.returncode == 0, done.stderr  # the run's report, and its archive's on its own, byte for byte
    reports = [(tmp_path / name).read_bytes() for name in ("a.md", "b.md")]
    text = reports[0].decode()
    assert reports[0] == reports[1] and "| minigrid-empty | 0.0845547 | 0.915625 | ce_decay | 1 |" in text
    assert "Holm over the 12 comparisons" in text and "| acrobot | -100 | ce_decay | " in text


def test_the_command_refuses_what_it_cannot_do(tmp_path):
    done = run("-m", "studies.past_teacher_vector", "--out", tmp_path / "x.tar.xz", "--quick")
    assert done.returncode == 2 and "an archive is read, never run into: add --no-run" in done.stderr
    done = run("-m", "studies.past_teacher_vector")
    assert done.returncode == 2 and "give --pilot DIR for MiniGrid's budget, or --out DIR" in done.stderr
    done = run("-m", "studies.past_teacher_vector", "--pilot", tmp_path / "none", "--no-run")
    assert done.returncode == 2 and "none: no such suite directory or archive" in done.stderr
    (tmp_path / "empty").mkdir()
    done = run("-m", "studies.past_teacher_vector", "--pilot", tmp_path / "empty", "--no-run")
    assert done.returncode == 2 and "the pilot lacks 4 run(s)" in done.stderr


def test_the_committed_pilot_gives_the_budget_the_study_runs():
    pilot = REPO / "docs" / "data" / "past-teacher-vector-pilot.tar.xz"
    reach = study.pilot_reach(pilot)
    assert reach == {
        ("none", A): 16_000,
        ("none", B): 18_000,
        ("SB3 DQN (rl-zoo3)", A): 21_000,
        ("SB3 DQN (rl-zoo3)", B): np.inf,
    }
    assert pilot_budget(reach) == study.MINIGRID_BUDGET == 25_000
    done = run("-m", "studies.past_teacher_vector", "--pilot", pilot, "--no-run")
    assert done.returncode == 0 and "MiniGrid's budget by §15's rule: **25,000** interactions." in done.stdout


@pytest.mark.slow
def test_the_committed_report_is_what_the_committed_archives_give(tmp_path):
    """docs/PAST_TEACHER_VECTOR.md regenerates byte for byte from docs/data/past-teacher-vector.tar.xz and §7's
    archive, its figures drawn (not compared byte for byte: fonts and rounding are the machine's)."""
    docs = REPO / "docs"
    done = run(
        "-m", "studies.past_teacher_vector", "--out", docs / "data" / "past-teacher-vector.tar.xz", "--no-run",
        "--report", tmp_path / "PAST_TEACHER_VECTOR.md", "--figures", tmp_path,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "PAST_TEACHER_VECTOR.md").read_bytes() == (docs / "PAST_TEACHER_VECTOR.md").read_bytes()
    for name in ("profile", "iqm", "games"):
        pixels = np.asarray(Image.open(tmp_path / f"past_teacher_vector_{name}.png").convert("RGB"))
        assert pixels.shape[0] > 100 and len(np.unique(pixels.reshape(-1, 3), axis=0)) > 20, name
