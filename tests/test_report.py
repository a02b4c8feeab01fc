"""The report from an archive: byte-identical to a golden file and to itself, written where it was
asked (never into docs/ by default), damaged or unfinished runs named and skipped, and arms of one
seed reported as too few for a comparison."""

import contextlib
import csv
import os
import shutil
import struct
import subprocess
import sys
import tarfile
from pathlib import Path

import numpy as np
import pytest
from helpers import REPO, call, tree

from dqfd_bc_keras.commands.cli import run
from dqfd_bc_keras.demos import record, save
from dqfd_bc_keras.experiments import figures
from dqfd_bc_keras.experiments.__main__ import main
from dqfd_bc_keras.experiments.baselines_table import demo_source
from dqfd_bc_keras.experiments.data import load_runs, open_suite
from dqfd_bc_keras.experiments.metrics import PER_RUN
from dqfd_bc_keras.experiments.report import NOTES, PER_SEED
from dqfd_bc_keras.training.records import DemoSummary

DATA = Path(__file__).with_name("data")
FIXTURE = DATA / "suite.tar.xz"
"""12 synthetic runs in 5 arms, built by tests/data/make_suite.py."""
GOLDEN = DATA / "suite-RESULTS.md"
REGENERATE_GOLDEN = "UPDATE_GOLDEN=1 .venv/bin/python -m pytest -q tests/test_report.py -k golden"
"""The report changed on purpose (claims, rules, layout)? This rewrites GOLDEN; review its diff."""
PROJECT = "# the project's committed results\n"


def outputs(directory: Path) -> dict[str, bytes]:
    return {p.relative_to(directory).as_posix(): p.read_bytes() for p in sorted(directory.rglob("*")) if p.is_file()}


def unpack(destination: Path) -> Path:
    with open_suite(FIXTURE) as directory:
        shutil.copytree(directory, destination)
    return destination


@pytest.fixture(scope="module")
def work(tmp_path_factory) -> dict:
    """In a directory holding a project's docs/: the fixture unpacked as `suite/`, exported to
    suite.tar.xz, and `report` run with default outputs on the archive (twice) and on the directory."""
    root = tmp_path_factory.mktemp("work")
    (root / "docs").mkdir()
    (root / "docs" / "RESULTS.md").write_text(PROJECT)
    unpack(root / "suite")
    with contextlib.chdir(root):
        assert main(["export", "suite", "--out", "suite.tar.xz"]) == 0
        assert main(["report", "suite.tar.xz"]) == 0
        first = outputs(root / "suite-report")
        assert main(["report", "suite.tar.xz"]) == 0
        assert main(["report", "suite"]) == 0
    return {"root": root, "first": first, "second": outputs(root / "suite-report")}


def test_report_from_the_archive_matches_the_golden_file(work):
    text = (work["root"] / "suite-report" / "RESULTS.md").read_text()
    if os.environ.get("UPDATE_GOLDEN") == "1":
        GOLDEN.write_text(text)
    assert text == GOLDEN.read_text(), (
        f"RESULTS.md of {FIXTURE.name} differs from {GOLDEN.relative_to(DATA.parents[1])}; "
        f"if the report changed on purpose, regenerate it: {REGENERATE_GOLDEN}"
    )


def test_a_second_report_is_byte_identical(work):
    first, second = work["first"], work["second"]
    assert sorted(first) == [
        "RESULTS.md",
        "figures/cartpole-naive-cases.png",
        "figures/cartpole-naive-curves.png",
        "figures/mountaincar-goals-bootstrap-cases.png",
        "figures/mountaincar-goals-bootstrap-curves.png",
        PER_SEED,
    ]
    assert first == second
    assert b"Software" not in first["figures/cartpole-naive-curves.png"]


def test_reports_land_beside_their_source_and_leave_docs_alone(work):
    root = work["root"]
    assert (root / "docs" / "RESULTS.md").read_text() == PROJECT and sorted(os.listdir(root / "docs")) == ["RESULTS.md"]
    in_dir = root / "suite" / "RESULTS.md"
    assert (root / "suite" / PER_SEED).is_file() and len(list((root / "suite" / "figures").glob("*.png"))) == 4
    from_archive = (root / "suite-report" / "RESULTS.md").read_text()
    assert in_dir.read_text() == from_archive.replace("suite.tar.xz", "suite")  # the archive lost nothing
    assert str(root) not in from_archive and "/tmp" not in from_archive


def test_the_markdown_states_provenance_demonstrations_and_seeds(work):
    text = (work["root"] / "suite-report" / "RESULTS.md").read_text()
    assert "code `1f0c2a9e8d7b` (10 runs), `2b3c4d5e6f70` (1 run), unknown (1 run)" in text
    assert "**1 run(s) trained from uncommitted changes**" in text and "cartpole/naive · ce seed 2" in text
    assert "| cartpole/naive | none | 2 | — | 0 | — |" in text
    assert "| cartpole/naive | bayes | 3 | 5 × imperfect | 881–1,087 | 1,000 |" in text
    assert f"[{PER_SEED}]({PER_SEED})" in text


def test_per_seed_table_has_every_per_run_metric(work):
    with (work["root"] / "suite-report" / PER_SEED).open(newline="") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == ["arm", "setting", "seed", *PER_RUN, "demo_transitions", "dynamic_demo_updates"]
    assert len(rows) == 12
    runs = {(r.config.task, r.config.expert_loss, r.config.seed): r for r in load_runs(FIXTURE)}
    row = next(r for r in rows if (r["arm"], r["setting"], r["seed"]) == ("ce", "cartpole/naive", "1"))
    run_ = runs["cartpole", "ce", 1]
    assert {m: float(row[m]) for m in PER_RUN} == pytest.approx({m: PER_RUN[m](run_) for m in PER_RUN})
    assert row["episodes_to_solve"] == "inf" and int(row["demo_transitions"]) == run_.demo_transitions
    assert [r["dynamic_demo_updates"] for r in rows if r["arm"] == "bayes"][0] == "2"


def test_the_goal_count_setting_gets_a_zoomed_panel(work):
    def width(png: bytes) -> int:
        return struct.unpack(">I", png[16:20])[0]

    first = work["first"]
    assert width(first["figures/mountaincar-goals-bootstrap-curves.png"]) > width(
        first["figures/cartpole-naive-curves.png"]
    )


def test_docs_only_when_asked_and_the_notes_survive(tmp_path, monkeypatch, capsys):
    notes = f"{NOTES[0]}\nC4 does not hold: see below.\n{NOTES[1]}"
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "RESULTS.md").write_text(f"# old\n\n{notes}\n\n| stale |\n")
    monkeypatch.chdir(tmp_path)
    assert main(["report", str(FIXTURE), "--docs"]) == 0
    text = (tmp_path / "docs" / "RESULTS.md").read_text()
    assert text.count(notes) == 1 and "stale" not in text and text.index(notes) < text.index("## Claims")
    assert (tmp_path / "docs" / PER_SEED).is_file() and len(list((tmp_path / "docs" / "figures").glob("*.png"))) == 4
    assert capsys.readouterr().out == "wrote docs/RESULTS.md, docs/per_seed.csv and figures in docs/figures\n"


def test_a_truncated_metrics_csv_is_skipped_with_a_warning(tmp_path, capsys):
    suite = unpack(tmp_path / "suite")
    metrics = suite / "cartpole-naive-ce" / "seed1" / "metrics.csv"
    metrics.write_bytes(metrics.read_bytes()[:-7])
    assert run(main, ["report", str(suite), "--results", str(tmp_path / "out" / "RESULTS.md")]) == 0
    assert capsys.readouterr().err == f"warning: {metrics}: ends in the middle of a line (truncated?); run skipped\n"
    text = (tmp_path / "out" / "RESULTS.md").read_text()
    assert "11 complete runs" in text
    assert "- `cartpole-naive-ce/seed1/metrics.csv`: ends in the middle of a line (truncated?)" in text
    assert run(main, ["report", str(suite), "--results", str(tmp_path / "out" / "RESULTS.md"), "--strict"]) == 1
    assert "run skipped" in capsys.readouterr().err


def test_what_is_not_a_suite_exits_2_in_one_line(tmp_path, capsys):
    (tmp_path / "notes.txt").write_text("hello")
    assert run(main, ["report", str(tmp_path / "notes.txt")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {tmp_path / 'notes.txt'}: not a suite directory") and err.count("\n") == 1
    assert not (tmp_path / "notes-report").exists()


def test_a_run_that_stopped_early_holds_its_last_value():
    stopped = figures.Trace("seed 0", np.array([1.0, 3.0]), 0.0, stopped=True)
    np.testing.assert_allclose(figures.held(stopped, 1, 4), [1.0, 3.0, 3.0, 3.0])
    np.testing.assert_allclose(figures.held(stopped, 2, 3), [1.0, 2.0, 2.0])  # the trailing mean is held
    budget = figures.Trace("seed 1", np.array([1.0, 3.0]), 0.0)
    np.testing.assert_allclose(figures.held(budget, 1, 4), [1.0, 3.0])  # ended at its budget: drops out
    mean, _, _, running = figures.mean_band([figures.held(stopped, 1, 3), np.array([5.0, 5.0, 5.0])])
    np.testing.assert_allclose(mean, [3.0, 4.0, 4.0])
    np.testing.assert_allclose(running, [2, 2, 2])


@pytest.mark.slow
def test_a_run_given_demonstrations_in_a_file_is_reported_as_such(tmp_path):
    """train.py --demos FILE, as a user runs it: the lab reads where the demonstrations came from
    out of the run's own demonstrations.json, not the file's demonstrator."""
    save(record("cartpole", "strong", 2, seed=7), tmp_path / "given.npz")
    out = tmp_path / "run"
    done = subprocess.run(
        [sys.executable, "train.py", "--quick", "--quiet", "--demos", str(tmp_path / "given.npz"), "--out", str(out)],
        cwd=DATA.parents[1],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    [run_] = load_runs(out)
    assert (run_.demonstrations.source, run_.demonstrations.expert, run_.demonstrations.episodes) == (
        "file",
        "strong",
        2,
    )
    assert demo_source(run_.demonstrations) == "2 episodes from a file"


def test_the_demonstrations_column_names_their_source():
    def summary(source, expert="imperfect"):
        return DemoSummary(
            transitions=100,
            episodes=2,
            expert=expert,
            episode_returns=[50.0, 50.0],
            plain_returns=[50.0, 50.0],
            pretrain_steps=10,
            source=source,
        )

    assert demo_source(summary("recorded")) == "2 × imperfect"
    assert demo_source(summary("file")) == "2 episodes from a file"
    assert demo_source(summary("minari", "minari:cartpole/expert-v0")) == "2 episodes from minari:cartpole/expert-v0"
    for unknown in ("disk", None):
        with pytest.raises(ValueError, match=f"source {unknown!r} is not one of"):
            summary(unknown)


ONE_SEED = ("cartpole-bootstrap-bayes", "cartpole-bootstrap-ce", "cartpole-bootstrap-bayes-priorFalse")
"""C3's pair and an ablation of it: arms whose comparisons need two seeds."""


@pytest.mark.slow
def test_a_report_on_arms_of_one_seed_says_they_have_too_few_and_is_written(tmp_path):
    suite = tmp_path / "suite"
    with tarfile.open(REPO / "docs" / "data" / "results.tar.xz") as archive:
        archive.extractall(
            suite, [m for m in archive if m.name.split("/")[0] in ONE_SEED and "/seed0/" in m.name], filter="data"
        )
    before = tree(suite)
    results = tmp_path / "report" / "RESULTS.md"
    done = call("dqfd_bc_keras.experiments", "report", suite, "--results", results)
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
    assert done.stdout.startswith(f"wrote {results}, ")
    text = results.read_text()
    assert "- C3 on cartpole/bootstrap: **inconclusive**: n = 1: too few seeds for a comparison.\n" in text
    assert (
        "| C3 | cartpole/bootstrap | with the time-limit bootstrap fix bayes and ce give the same average reward | "
        "n = 1: too few seeds for a comparison | — | — | 1, 1 · — | **inconclusive (n < 2)** |"
    ) in text
    assert (
        "| cartpole/bootstrap bayes | bayes_prior = False | 1, 1 | n = 1: too few seeds for a comparison | — | — | "
        "— | **inconclusive (n < 2)** |"
    ) in text
    assert tree(suite) == before


@pytest.mark.slow
def test_the_report_names_every_run_it_leaves_out(finished, tmp_path):
    from dqfd_bc_keras.experiments.report import report

    suite = tmp_path / "suite"
    shutil.copytree(finished, suite / "cartpole-bootstrap-bayes-quick" / "seed0")
    cut = suite / "cartpole-bootstrap-bayes-quick" / "seed1"
    shutil.copytree(finished, cut)
    (cut / "eval.json").unlink()
    warned = []
    report(suite, tmp_path / "RESULTS.md", tmp_path / "figures", warn=warned.append)
    assert warned == [
        f"{suite}/cartpole-bootstrap-bayes-quick/seed1/eval.json: missing: the run has not finished "
        "(still running, or cut off: run the suite again to resume it); run skipped"
    ]
