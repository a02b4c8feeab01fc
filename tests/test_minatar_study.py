"""The five-game MinAtar study (PREREGISTRATION §13): its anchors as measured, its rules on runs
made up by hand, and the command as a user runs it: quick runs, the archive written as runs finish,
a resumed study that computes nothing twice, a report that regenerates byte for byte."""

import re
import tarfile

import pytest
from helpers import REPO
from helpers import python as run

from dqfd_bc_keras.demos.recording import expert_returns
from dqfd_bc_keras.experiments.efficiency import SB3_METHOD
from studies import minatar_study as study
from studies.minatar_study import ANCHORS, GAMES, METHODS, QUICK_GAMES, Study, normalised, report

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("game", GAMES)
def test_the_anchors_are_the_random_policys_and_the_teachers_100_episode_returns(game):
    random, teacher = ANCHORS[game]
    assert round(float(expert_returns(game, "imperfect", 100, 0, 1.0).mean()), 2) == random  # ε = 1: uniform
    assert round(float(expert_returns(game, "imperfect", 100, 0, 0.0).mean()), 2) == teacher


def test_a_normalised_score_puts_random_at_0_and_the_teacher_at_1():
    random, teacher = ANCHORS["minatar-breakout"]
    assert normalised("minatar-breakout", random) == 0.0 and normalised("minatar-breakout", teacher) == 1.0
    assert normalised("minatar-breakout", (random + teacher) / 2) == pytest.approx(0.5)


def made_up(finals: dict[str, list[float]], seeds: int, budget: int = study.BUDGET) -> Study:
    """Runs whose evaluations are 0 until the budget, where they score `finals[method][seed] × teacher`
    on every game (a normalised score of about that value)."""
    runs = {}
    for game in GAMES:
        random, teacher = ANCHORS[game]
        for method, values in finals.items():
            runs[game, method] = {
                seed: [(0.0, random), (budget / 2, random), (float(budget), random + value * (teacher - random))]
                for seed, value in enumerate(values)
            }
    return Study(runs, budget, seeds)


def test_an_incomplete_study_is_described_and_judges_nothing():
    partial = made_up({"bayes": [2.0, 2.0], "ce": [2.0, 2.0], "none": [0.0, 0.0], SB3_METHOD: [0.0, 0.0]}, 10)
    assert not partial.complete
    text = report(partial)
    assert "**Interim: 40 of 200 runs finished (seeds finished on all five games: bayes 2, ce 2" in text
    assert "| bayes | 2 | 2.00 [2.00, 2.00] | 2.00 | 100% | (beats its teachers; interim) |" in text
    assert "interim: beats its teacher" in text and "interim, not judged: equivalent" in text
    assert "Our runs' code: none yet" in text  # runs made up here have no provenance


def test_a_complete_study_gives_the_preregistered_verdicts():
    seeds = 10
    done = made_up(
        {
            "bayes": [1.5 + 0.01 * s for s in range(seeds)],
            "ce": [1.1 + 0.01 * s for s in range(seeds)],
            "none": [0.2] * seeds,
            SB3_METHOD: [0.1] * seeds,
        },
        seeds,
    )
    assert done.complete and done.scores("bayes").shape == (seeds, len(GAMES))
    text = report(done)
    assert "**Complete: 10 seeds of every arm on every game" in text
    # 5 copies of 1.50 … 1.59: the IQM keeps the middle 26 of 50 (1.52 ×3, 1.53–1.56 ×5, 1.57 ×3): 1.545
    assert "| bayes | 10 | 1.55 [1.53, 1.56] | 1.55 | 100% | beats its teachers |" in text
    assert "| minatar-asterix | 0.6 | 28.58 | none (DQN, no demonstrations) | 10 |" in text
    assert "(does not beat it; described, not judged)" in text
    # Q2: every DQfD run reaches its teacher at the budget, no DQN or SB3 run does: sooner, p Holm-adjusted.
    assert "| minatar-freeway | bayes | 10/10 | 100,000 [100,000, 100,000] | 0.000: sooner | 0.000: sooner |" in text
    # Q3: bayes is 0.4 above ce on every run: beyond the ±0.15 margin.
    assert "IQM(bayes) − IQM(ce) = +0.400" in text and "**bayes is better markedly**" in text


def test_q3_keeps_a_significant_difference_inside_the_margin_from_being_called_marked():
    base = [1.0 + 0.1 * (s % 2) for s in range(10)]  # 1.0 and 1.1 alternately
    straddles = made_up({"bayes": [b + 0.15 for b in base], "ce": base, "none": base, SB3_METHOD: base}, 10)
    assert "**bayes is better, not markedly (the 90% CI reaches inside ±0.15)**" in report(straddles)
    inside = made_up({"bayes": [b + 0.05 for b in base], "ce": base, "none": base, SB3_METHOD: base}, 10)
    assert "**equivalent (the 90% CI lies within ±0.15); bayes is higher by a significant amount" in report(inside)
    same = made_up({"bayes": base, "ce": base, "none": base, SB3_METHOD: base}, 10)
    assert "**equivalent (the 90% CI lies within ±0.15)**" in report(same)
    apart = made_up({"bayes": base, "ce": [b + 0.5 for b in base], "none": base, SB3_METHOD: base}, 10)
    assert "**ce is better markedly**" in report(apart)


def test_one_seed_gives_numbers_and_no_interval_or_verdict():
    text = report(made_up({"bayes": [2.0], "ce": [0.0], "none": [0.0], SB3_METHOD: [0.0]}, 10))
    assert "| bayes | 1 | 2.00 [2.00, 2.00] | 2.00 | 100% | (one seed: no interval; interim) |" in text
    assert "interim: one seed: no interval |" in text and "beats its teacher" not in text
    assert "**interim, not judged: one seed: no interval**" in text


def test_the_score_matrix_takes_only_seeds_finished_on_every_game():
    runs = made_up({"bayes": [1.0, 1.0, 1.0]}, 3).runs
    del runs["minatar-seaquest", "bayes"][1]
    partial = Study(runs, study.BUDGET, 3)
    assert partial.complete_seeds("bayes") == [0, 2] and partial.scores("bayes").shape == (2, len(GAMES))
    assert partial.scores("ce").shape == (0, len(GAMES))


def test_the_quick_study_exports_each_run_resumes_from_its_archive_and_reports_byte_for_byte(tmp_path):
    out, archive = tmp_path / "minatar", tmp_path / "minatar.tar.xz"
    done = run("-m", "studies.minatar_study", "--out", out, "--archive", archive, "--quick")
    assert done.returncode == 0, done.stderr
    assert "minatar: 6 runs, 0 already complete, 6 to run" in done.stdout  # 3 arms on --quick's 2 games
    assert "SB3 DQN: 2 runs, 0 current, 2 to run" in done.stdout
    with tarfile.open(archive) as tar:
        names = tar.getnames()
    assert sum(name.endswith("/eval.json") for name in names) == 6  # every run of ours, no checkpoint
    assert sum(name.startswith("sb3-dqn/") for name in names) == 2 and not any("checkpoints" in n for n in names)
    # A new machine: only the archive. Nothing runs twice, and its report is the archive's, byte for byte.
    for name in ("a", "b"):
        (tmp_path / name / "figures").mkdir(parents=True)
    report = [("--report", tmp_path / name / "MINATAR.md", "--figures", tmp_path / name / "figures") for name in "ab"]
    again = run("-m", "studies.minatar_study", "--out", tmp_path / "new", "--archive", archive, "--quick", *report[0])
    assert again.returncode == 0, again.stderr
    assert "6 already complete, 0 to run" in again.stdout and "2 current, 0 to run" in again.stdout
    done = run("-m", "studies.minatar_study", "--out", archive, "--no-run", "--quick", *report[1])
    assert done.returncode == 0, done.stderr
    reports = [
        [(tmp_path / name / "MINATAR.md").read_bytes()]
        + [p.read_bytes() for p in sorted((tmp_path / name / "figures").iterdir())]
        for name in "ab"
    ]
    assert reports[0] == reports[1] and len(reports[0]) == 4
    text = reports[0][0].decode()
    for game in QUICK_GAMES:
        for method in METHODS:
            assert f"| {game} |" in text and f"| {study.arm_label(method)} |" in text
    assert "minatar-asterix" not in text  # the report is of the games run, not "not run" rows for the others
    assert "**Interim" not in text  # --quick is one seed of every arm: complete on its own terms
    assert re.search(r"Our runs' code: [0-9a-f]{7}( \(dirty\))?(, |\s)", text)  # from their provenance.json


def test_an_archive_is_read_never_run_into(tmp_path):
    done = run("-m", "studies.minatar_study", "--out", tmp_path / "x.tar.xz")
    assert done.returncode == 2 and "an archive is read, never run into: add --no-run" in done.stderr
    done = run("-m", "studies.minatar_study", "--out", tmp_path / "x", "--archive", tmp_path / "a.zip")
    assert done.returncode == 2 and "--archive" in done.stderr and "expected a .tar.xz file" in done.stderr


def test_the_committed_report_is_what_the_committed_archive_gives(tmp_path):
    """docs/MINATAR.md and its figures regenerate byte for byte from docs/data/minatar.tar.xz (the study
    exports its runs elsewhere while it runs; the archive and the report are committed together)."""
    docs = REPO / "docs"
    done = run(
        "-m", "studies.minatar_study", "--out", docs / "data" / "minatar.tar.xz", "--no-run",
        "--report", tmp_path / "MINATAR.md", "--figures", tmp_path,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "MINATAR.md").read_bytes() == (docs / "MINATAR.md").read_bytes()
    for figure in ("minatar_profile.png", "minatar_iqm.png", "minatar_games.png"):
        assert (tmp_path / figure).read_bytes() == (docs / "figures" / figure).read_bytes(), figure
