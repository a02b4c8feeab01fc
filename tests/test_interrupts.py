"""Ctrl-C and SIGTERM on a run, a sweep or an evaluation: each stops within seconds and says in one
line what was kept (the last checkpoint, every finished run, or nothing) and how to go on; a stopped
run resumes, and a sweep starts no new run. The signal goes to a process of its own where the process
is what is checked."""

import importlib.util
import json
import signal
import subprocess
import sys
import time

import pytest
from helpers import ENV, REPO, TINY_RUN, call, one_line

from dqfd_bc_keras.commands import cli
from dqfd_bc_keras.commands.train import main as train_main
from dqfd_bc_keras.core.config import QUICK
from dqfd_bc_keras.experiments.suites import Arm
from dqfd_bc_keras.runs import directory as runs

pytestmark = pytest.mark.slow


def ctrl_c_reaches() -> None:
    """A child's SIGINT back to the default: launched from a background job without job control
    (`nohup pytest … &`), the tests inherit SIGINT ignored, and Ctrl-C would then never reach the
    child: the behaviour Unix means for background jobs, not the one these tests check."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


# --- a run ---


@pytest.mark.parametrize(
    "interrupt, name, code", [(KeyboardInterrupt, "Ctrl-C", 130), (cli.Terminated, "SIGTERM", 143)]
)
def test_an_interrupt_before_the_first_checkpoint_says_nothing_was_kept(
    tmp_path, capsys, monkeypatch, interrupt, name, code
):
    def interrupted(self):
        raise interrupt

    monkeypatch.setattr(runs.RunDirectory, "save_checkpoint", interrupted)
    out = tmp_path / "run"
    err = one_line(capsys, cli.run(train_main, [*TINY_RUN, "--out", str(out)]), "", expected_code=code)
    assert err == f"interrupted ({name}); {out}: nothing was kept (the run had not reached its first checkpoint)\n"
    assert not out.exists()


def test_sigterm_stops_a_run_like_ctrl_c_and_it_resumes(tmp_path):
    out = tmp_path / "run"
    args = [
        sys.executable,
        str(REPO / "train.py"),
        "--quick",
        "--quiet",
        "--set",
        "total_steps=3000",
        "--set",
        "checkpoint_every=300",
        "--out",
        str(out),
    ]
    process = subprocess.Popen(args, cwd=REPO, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    latest, deadline = out / "checkpoints" / "latest.json", time.time() + 240
    while time.time() < deadline and process.poll() is None:
        if latest.exists() and json.loads(latest.read_text())["dir"] != "ckpt-0":
            break
        time.sleep(0.05)
    process.send_signal(signal.SIGTERM)
    _, err = process.communicate(timeout=120)
    assert process.returncode == 143, err
    assert err == "interrupted (SIGTERM); a training run continues from its last checkpoint with --resume\n"
    assert (out / ".lock").read_text() == ""  # released on the way out
    resumed = call("train.py", *args[2:], "--resume")  # the resume itself needs no process of its own
    assert resumed.returncode == 0, resumed.stderr
    assert (out / "eval.json").is_file()


SIGTERM_BEFORE_THE_RUN = """
import os, signal, sys
from dqfd_bc_keras.commands import cli, train
# The signal lands while the command is still checking its arguments: the run directory does not exist yet.
train.try_demonstrator = lambda config: os.kill(os.getpid(), signal.SIGTERM)
sys.exit(cli.run(train.main, sys.argv[1:]))
"""


def test_sigterm_before_the_run_directory_exists_says_nothing_was_written(tmp_path):
    out = tmp_path / "run"
    done = subprocess.run(
        [sys.executable, "-c", SIGTERM_BEFORE_THE_RUN, "--quick", "--quiet", "--out", str(out)],
        cwd=REPO,
        env=ENV,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert (done.returncode, done.stderr) == (
        143,
        "interrupted (SIGTERM); nothing was written; run the same command again\n",
    )
    assert not out.exists()


# --- a sweep ---


def _deaf_to_sigterm(ready) -> None:
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    ready.set()
    time.sleep(120)


def test_runs_that_do_not_stop_are_killed_together_after_one_grace_and_named(tmp_path, monkeypatch, capsys):
    import multiprocessing

    from dqfd_bc_keras.experiments import sweep

    monkeypatch.setattr(sweep, "STOP_GRACE", 2.0)
    arm = Arm("cartpole", "bootstrap", "bayes", tuple(QUICK.items()), "quick", 2)
    context, workers = multiprocessing.get_context("fork"), []
    for seed in (0, 1):
        ready = context.Event()
        process = context.Process(target=_deaf_to_sigterm, args=(ready,), daemon=True)
        process.start()
        assert ready.wait(30)
        workers.append(sweep._Worker(process, None, None, job=sweep.Job(arm, seed, tmp_path)))
    started = time.monotonic()
    sweep._stop_all(workers)
    seconds = time.monotonic() - started
    assert [w.process.exitcode for w in workers] == [-signal.SIGKILL] * 2
    assert 2.0 <= seconds < 4.0, seconds  # one grace for both: one each would be 4 s
    assert capsys.readouterr().err.splitlines() == [
        f"warning: {tmp_path / arm.name}/seed{seed}: the run had not stopped 2 s after SIGTERM; killed (its last "
        "checkpoint is kept, and the next sweep resumes from it)"
        for seed in (0, 1)
    ]


def test_ctrl_c_on_a_sweep_starts_no_new_run_and_exits_within_seconds(tmp_path):
    out = tmp_path / "sweep"
    args = [
        sys.executable,
        "-m",
        "dqfd_bc_keras.experiments",
        "run",
        "quick",
        "--seeds",
        "2",
        "--workers",
        "2",
        "--set",
        "total_steps=5000",
        "--set",
        "checkpoint_every=300",
        "--out",
        str(out),
    ]
    process = subprocess.Popen(
        args, cwd=REPO, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=ctrl_c_reaches
    )
    deadline = time.time() + 240
    while time.time() < deadline and process.poll() is None:
        latest = [
            json.loads(p.read_text())["dir"]
            for p in out.glob("*/seed0/checkpoints/latest.json")
            if p.read_text().strip()
        ]
        if len([d for d in latest if d != "ckpt-0"]) == 2:  # both runs have checkpointed during learning
            break
        time.sleep(0.1)
    signal_sent = time.time()
    process.send_signal(signal.SIGINT)
    stdout, err = process.communicate(timeout=120)
    seconds = time.time() - signal_sent
    print(f"the sweep exited {seconds:.1f} s after Ctrl-C")
    assert process.returncode == 130, err
    assert seconds < 30, (seconds, err)  # a liveness bound: the runs stop at their next step, not at their end
    assert "interrupted after 0 of 4 runs; no run was started after it" in stdout
    assert err.strip().splitlines()[-1] == (
        "interrupted (Ctrl-C); every finished run is kept; run the same command again to go on"
    )
    assert sorted(p.name for p in out.glob("*/seed*")) == ["seed0", "seed0"]  # seed 1 never started
    for run in out.glob("*/seed0"):
        assert (run / ".lock").read_text() == "" and not (run / runs.COMPLETE).exists()
        assert (run / "checkpoints" / "latest.json").is_file()
    [logged] = [json.loads(line) for line in (out / "sweeps.jsonl").read_text().splitlines()]
    assert logged["interrupted"] is True and logged["runs"] == 0


# --- an evaluation ---


def test_a_long_evaluation_shows_progress_and_an_interrupt_says_so(tmp_path, monkeypatch, capsys):
    evaluate = importlib.util.module_from_spec(importlib.util.spec_from_file_location("evaluate", REPO / "evaluate.py"))
    evaluate.__spec__.loader.exec_module(evaluate)
    clock = iter([0.0, 3.0, 11.0, 12.0, 25.0])
    monkeypatch.setattr(evaluate.time, "monotonic", lambda: next(clock))
    report = evaluate.progress_lines(100)
    for done in (1, 2, 3, 4):
        report(done)
    assert capsys.readouterr().err.splitlines() == [
        "evaluated 2 of 100 episodes (11 s)",
        "evaluated 4 of 100 episodes (25 s)",
    ]
    process = subprocess.Popen(
        [sys.executable, "evaluate.py", "models/cartpole", "--episodes", "100000000"],
        cwd=REPO,
        env=ENV,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=ctrl_c_reaches,
    )
    time.sleep(15)  # TensorFlow's import, then episodes
    process.send_signal(signal.SIGINT)
    _, err = process.communicate(timeout=60)
    assert process.returncode == 130
    assert err.strip().splitlines()[-1] == "interrupted (Ctrl-C); evaluation interrupted: nothing was written"
