"""Issue W's study (PREREGISTRATION §14): the pilot's rule on made-up runs, the choice as the committed
pilot gives it, and the command as a user runs it (quick runs exported as they finish, the report
regenerated from the archive byte for byte)."""

import tarfile

import numpy as np
import pytest
from helpers import REPO
from helpers import python as run
from PIL import Image

from studies import past_teacher
from studies.minatar_study import QUICK_GAMES
from studies.past_teacher import CANDIDATES, CLOSE, NEW_ARM, PilotArm, agent_weight, choose, pilot_arms


def arm(method, score, weight):
    """A candidate whose four pilot runs all score `score` with weight `weight`."""
    runs = [(g, s) for g in past_teacher.PILOT_GAMES for s in past_teacher.PILOT_SEEDS]
    return PilotArm(method, dict.fromkeys(runs, score), dict.fromkeys(runs, weight))


def test_the_pilot_picks_the_best_score_and_breaks_a_near_tie_by_the_lower_weight_on_the_agents_states():
    assert choose([arm("qfilter", 1.0, 0.9), arm("ce_decay", 0.8, 0.1), arm("bayes_local", 0.5, 0.0)]) == "qfilter"
    near = 1.0 - CLOSE + 0.01  # within CLOSE of the best: the one that imitates less wins
    assert choose([arm("qfilter", 1.0, 0.9), arm("ce_decay", near, 0.1), arm("bayes_local", 0.5, 0.0)]) == "ce_decay"
    scores = {("minatar-breakout", 1): 0.2, ("minatar-freeway", 1): 1.0}
    assert PilotArm("x", scores, {k: np.nan for k in scores}).mean_score == pytest.approx(0.6)


class Run:
    """What `agent_weight` reads of a finished run: metrics.csv's columns."""

    def __init__(self, weights):
        self.weights = np.array(weights, float)

    def column(self, name):
        assert name == "imitation_weight_agent"
        return self.weights


def test_the_weight_on_the_agents_states_is_the_mean_over_the_last_tenth_of_episodes():
    assert agent_weight(Run([1.0] * 18 + [0.2, 0.4])) == pytest.approx(0.3)  # 20 episodes: the last 2
    assert agent_weight(Run([0.5, 0.7, 0.1])) == pytest.approx(0.1)  # at least one episode
    assert np.isnan(agent_weight(Run([np.nan] * 5)))  # a method that logs no weight


@pytest.mark.slow
def test_the_committed_pilot_gives_the_arm_the_study_runs():
    pilot = REPO / "docs" / "data" / "past-teacher-pilot.tar.xz"
    arms = pilot_arms(pilot)
    assert [a.method for a in arms] == list(CANDIDATES) and all(len(a.scores) == 4 for a in arms)
    assert choose(arms) == NEW_ARM
    done = run("-m", "studies.past_teacher", "--pilot", pilot)
    assert done.returncode == 0, done.stderr
    assert f"The new arm by §14's rule: **{NEW_ARM}**." in done.stdout


@pytest.mark.slow
def test_the_quick_study_exports_each_run_and_reports_byte_for_byte_from_its_archive(tmp_path):
    out, archive = tmp_path / "runs", tmp_path / "past-teacher.tar.xz"
    done = run("-m", "studies.past_teacher", "--out", out, "--archive", archive, "--quick")
    assert done.returncode == 0, done.stderr
    with tarfile.open(archive) as tar:
        names = tar.getnames()
    assert sum(name.endswith("/eval.json") for name in names) == len(QUICK_GAMES)  # the new arm on each game
    assert all(f"-{NEW_ARM}-" in name for name in names if name.endswith("/eval.json"))
    again = run(
        "-m", "studies.past_teacher", "--out", tmp_path / "new", "--archive", archive, "--quick",
        "--report", tmp_path / "a.md",
    )  # fmt: skip
    assert again.returncode == 0 and "2 already complete, 0 to run" in again.stdout, again.stdout + again.stderr
    done = run("-m", "studies.past_teacher", "--out", archive, "--no-run", "--quick", "--report", tmp_path / "b.md")
    assert done.returncode == 0, done.stderr  # the resumed run's report, and its archive's alone, byte for byte
    reports = [(tmp_path / name).read_bytes() for name in ("a.md", "b.md")]
    text = reports[0].decode()
    assert reports[0] == reports[1] and f"| minatar-breakout | 0.37 | 8.56 | {NEW_ARM} | 1 |" in text
    assert f"Holm over the {3 * 2 * len(QUICK_GAMES)} comparisons" in text and f"IQM({NEW_ARM}) − IQM(ce) =" in text


def test_the_command_refuses_what_it_cannot_do(tmp_path):
    done = run("-m", "studies.past_teacher", "--out", tmp_path / "x.tar.xz")
    assert done.returncode == 2 and "an archive is read, never run into: add --no-run" in done.stderr
    done = run("-m", "studies.past_teacher")
    assert done.returncode == 2 and "give --pilot PATH, or --out DIR" in done.stderr
    done = run("-m", "studies.past_teacher", "--pilot", tmp_path / "nothing")
    assert done.returncode != 0 and "nothing" in done.stderr


@pytest.mark.slow
def test_the_committed_report_is_what_the_committed_archive_gives(tmp_path):
    """docs/PAST_TEACHER.md regenerates byte for byte from docs/data/past-teacher.tar.xz and §13's archive,
    its figures drawn."""
    docs = REPO / "docs"
    done = run(
        "-m", "studies.past_teacher", "--out", docs / "data" / "past-teacher.tar.xz", "--no-run",
        "--report", tmp_path / "PAST_TEACHER.md", "--figures", tmp_path,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "PAST_TEACHER.md").read_bytes() == (docs / "PAST_TEACHER.md").read_bytes()
    for name in ("profile", "iqm", "games"):  # drawn, each arm a colour: not asserted byte for byte (CPU-bound fonts)
        pixels = np.asarray(Image.open(tmp_path / f"past_teacher_{name}.png").convert("RGB"))
        assert pixels.shape[0] > 100 and len(np.unique(pixels.reshape(-1, 3), axis=0)) > 20, name
