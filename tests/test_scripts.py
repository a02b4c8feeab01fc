"""train.py and evaluate.py as a user runs them: tiny budgets, exit codes, one-line errors. The
commands answer in this process (`helpers.call`), and the finished quick runs are the session's
(`quick_run`); `python train.py` itself runs where a process is killed and resumed."""

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from helpers import call

REPO = Path(__file__).resolve().parents[1]
LOSSES = ("bayes", "ce", "bc_margin", "margin", "none")
ENV = {**os.environ, "PYTHONPATH": str(REPO)}


def script(name, *args, **kwargs):
    return [sys.executable, str(REPO / name), *map(str, args)]


def run(name, *args, timeout=300):
    return subprocess.run(script(name, *args), capture_output=True, text=True, timeout=timeout, cwd=REPO, env=ENV)


@pytest.mark.slow
@pytest.mark.parametrize("loss", LOSSES)
def test_quick_training_writes_a_complete_run(quick_run, loss):
    run_dir, done = quick_run(loss).out, quick_run(loss).answer
    assert "cartpole (CartPole-v1), q policy, 2 greedy episodes" in done.stdout and "interactions in all" in done.stdout
    expected = {"config.json", "metrics.csv", "evals.csv", "q_network.keras", "eval.json", "learning_curve.png", "tb"}
    if loss != "none":
        expected.add("demonstrations.json")
    if loss != "margin" and loss != "none":
        expected |= {"bc_model.keras", "demos.npz"}
    assert expected <= {p.name for p in run_dir.iterdir()}
    assert json.loads((run_dir / "config.json").read_text())["expert_loss"] == loss
    rows = list(csv.DictReader((run_dir / "metrics.csv").open()))
    assert rows and int(rows[-1]["env_step"]) <= 600


@pytest.mark.slow
@pytest.mark.parametrize("loss", LOSSES)
def test_evaluate_reads_a_quick_run(quick_run, loss, tmp_path):
    done = call("evaluate.py", quick_run(loss).out, "--episodes", 3, "--json", "--out", tmp_path / "e.json")
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    assert result["task"] == "cartpole" and result["episodes"] == 3 and len(result["returns"]) == 3
    assert json.loads((tmp_path / "e.json").read_text())["returns"] == result["returns"]


@pytest.mark.slow
def test_resume_after_sigkill_reproduces_the_uninterrupted_run(tmp_path):
    """Same seed, op determinism: a run killed mid-way and resumed writes the same metrics."""
    args = ["--quick", "--set", "total_steps=2500", "--set", "checkpoint_every=500", "--quiet"]
    whole, cut = tmp_path / "whole", tmp_path / "cut"
    assert call("train.py", *args, "--out", whole).returncode == 0  # in this process: the same run
    process = subprocess.Popen(
        script("train.py", *args, "--out", cut), cwd=REPO, env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    latest = cut / "checkpoints" / "latest.json"
    deadline = time.time() + 240
    while time.time() < deadline and process.poll() is None:
        if latest.exists() and json.loads(latest.read_text())["dir"] != "ckpt-0":
            break
        time.sleep(0.05)
    process.send_signal(signal.SIGKILL)
    process.wait()
    checkpoint = json.loads(latest.read_text())["dir"]
    assert checkpoint != "ckpt-0" and int(checkpoint.split("-")[1]) < 2500, "killed too late to test resuming"
    resumed = run("train.py", *args, "--out", cut, "--resume")
    assert resumed.returncode == 0, resumed.stderr

    def table(path, drop="wall_time"):
        rows = list(csv.DictReader(path.open()))
        return [{k: v for k, v in row.items() if k != drop} for row in rows]

    assert table(cut / "metrics.csv") == table(whole / "metrics.csv")
    assert table(cut / "evals.csv") == table(whole / "evals.csv")
    assert json.loads((cut / "eval.json").read_text()) == json.loads((whole / "eval.json").read_text())


def one_line_error(done, message):
    assert done.returncode == 2, done.stdout + done.stderr
    assert message in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr


@pytest.mark.slow
def test_train_refuses_to_overwrite_a_run(quick_run):
    run_dir = quick_run("bayes").out
    before = (run_dir / "metrics.csv").read_bytes()
    one_line_error(call("train.py", "--quick", "--out", run_dir), "already holds a run; pass --resume")
    assert (run_dir / "metrics.csv").read_bytes() == before


@pytest.mark.parametrize(
    "args, message",
    [
        (["--task", "pong"], "invalid choice: 'pong'"),
        (["--expert-loss", "kl"], "expert_loss='kl' is not one of ('margin'"),
        (["--steps", "0"], "must be a positive integer, got 0"),
        (["--set", "gama=0.9"], "--set 'gama=0.9': unknown Config field 'gama'; did you mean gamma?"),
        (["--set", "gamma=abc"], "--set gamma='abc': expected float"),
        (["--set", "gamma=2"], "gamma must be in [0, 1], got 2.0"),
        (["--demos", "missing.npz"], "missing.npz: no such file"),
        (["--resume", "--out", "nowhere"], "nowhere has no checkpoint to resume from"),
    ],
)
def test_train_rejects_bad_input_in_one_line(args, message):
    one_line_error(call("train.py", "--quick", *args), message)


def test_train_rejects_demos_of_another_task(tmp_path):
    demos = tmp_path / "mc.npz"
    recorded = call(
        "dqfd_bc_keras.demos", "record", "--task", "mountaincar", "--expert", "strong", "--episodes", 1, "--out", demos
    )
    assert recorded.returncode == 0, recorded.stderr
    one_line_error(
        call("train.py", "--quick", "--demos", demos, "--out", tmp_path / "x"),
        "was recorded on task 'mountaincar', not on the requested 'cartpole'",
    )
    assert not (tmp_path / "x").exists()
