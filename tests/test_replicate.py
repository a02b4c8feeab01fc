"""`experiments replicate`: an archived arm rerun at fresh seeds, its distributions compared."""

import json
import os
import subprocess
import sys
import tarfile
from pathlib import Path

import pytest

from dqfd_bc_keras.core.config import QUICK
from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.experiments.arms import group_arms
from dqfd_bc_keras.experiments.data import REPLICATIONS, export_archive, load_runs
from dqfd_bc_keras.experiments.replicate import Comparison, parse_seeds, replicate, replication_section
from dqfd_bc_keras.experiments.suites import arm
from dqfd_bc_keras.experiments.summary import summary
from dqfd_bc_keras.runs.directory import train

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[1]
ARM = arm("cartpole", "bootstrap", "ce", 1, **QUICK)


@pytest.fixture(scope="module")
def archive(tmp_path_factory) -> Path:
    """An archive of one quick arm at seed 0, as `export` writes it."""
    root = tmp_path_factory.mktemp("archived")
    train(ARM.config(0), root / "suite" / ARM.name / "seed0", quiet=True)
    export_archive(root / "suite", root / "results.tar.xz")
    return root / "results.tar.xz"


def test_a_replication_reruns_the_arm_at_fresh_seeds_and_compares(archive, tmp_path):
    suite = tmp_path / "suite"
    with tarfile.open(archive) as tar:
        tar.extractall(suite, filter="data")
    out = suite / REPLICATIONS  # the reruns travel with the suite
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "dqfd_bc_keras.experiments",
            "replicate",
            ARM.name,
            "--seeds",
            "0-0",
            "--archive",
            str(archive),
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
        cwd=REPO,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        timeout=300,
    )
    assert done.returncode == 2 and "the archive already has seed(s) [0]" in done.stderr
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "dqfd_bc_keras.experiments",
            "replicate",
            ARM.name,
            "--seeds",
            "7-7",
            "--archive",
            str(archive),
            "--out",
            str(out),
            "--workers",
            "1",
        ],
        capture_output=True,
        text=True,
        cwd=REPO,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        timeout=300,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    config = json.loads((out / ARM.name / "seed7" / "config.json").read_text())
    archived = json.loads(json.dumps({**ARM.config(0).to_dict(), "seed": 7}))
    assert {k: v for k, v in config.items() if k != "observation"} == archived  # only the seed differs
    report = (out / "REPLICATE.md").read_text()
    assert "| final return | 1 |" in report and "| mean training return | 1 |" in report
    assert report in done.stdout
    # Read apart from the suite's own runs (same config: they would join its arm), exported with them,
    # and compared in the report and its summary.
    assert [r.config.seed for r in load_runs(suite)] == [0]
    export_archive(suite, tmp_path / "again.tar.xz")
    with tarfile.open(tmp_path / "again.tar.xz") as tar:
        assert f"{REPLICATIONS}/{ARM.name}/seed7/eval.json" in tar.getnames()
    arms = group_arms(load_runs(tmp_path / "again.tar.xz"))
    assert len(arms) == 1 and len(arms[0].runs) == 1
    rows = [line for line in replication_section(arms, suite) if line.startswith("| cartpole")]
    assert len(rows) == 3 and all("| seeds 7–7 | " in row for row in rows)
    line = "- Replications at fresh seeds: 1 arms, 3 rank tests, 0 with p < 0.05 (uncorrected; 0.2 expected by chance"
    assert any(text.startswith(line) for text in summary(arms, suite))


def test_unknown_arms_and_bad_seeds_are_one_line(archive, tmp_path):
    with pytest.raises(ConfigError, match=f"has no arm '{ARM.name}x'; did you mean '{ARM.name}'"):
        replicate(ARM.name + "x", range(3, 4), tmp_path, archive)
    with pytest.raises(ConfigError, match="expected A-B"):
        parse_seeds("3..5")
    assert parse_seeds("100-107") == range(100, 108) and parse_seeds("4") == range(4, 5)


def test_the_comparison_is_the_rank_test_and_medians():
    same = Comparison("final return", [1.0, 2.0, 3.0], [1.0, 2.0, 3.0])
    assert same.p == 1.0 and same.row() == "| final return | 3 | 2 | 3 | 2 | 1.00 |"
    apart = Comparison("x", [1.0, 2.0, 3.0, 4.0, 5.0], [10.0, 11.0, 12.0, 13.0, float("inf")])
    assert apart.p < 0.05 and apart.row().endswith("| 5 | 3 | 5 | 12 | 0.01 |")
