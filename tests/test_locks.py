"""One writer per run directory: a second writer, in another process or in the same one, is refused
with the holder's PID and deletes nothing, and a lock its dead holder left is taken over; a sweep
leaves a run that another live runner holds to it, and two runners on one `--out` finish each run
once."""

import json
import os
import re
import shutil
import signal
import subprocess
import sys

import pytest
from helpers import ENV, LAB, REPO, TINY_SWEEP, one_line

from dqfd_bc_keras.commands import cli
from dqfd_bc_keras.commands.train import main as train_main
from dqfd_bc_keras.core.config import QUICK
from dqfd_bc_keras.errors import RunDirectoryError
from dqfd_bc_keras.experiments.suites import Arm
from dqfd_bc_keras.experiments.sweep import SweepOptions, run_suite
from dqfd_bc_keras.files import DirectoryLock
from dqfd_bc_keras.runs import directory as runs


@pytest.mark.slow
def test_a_second_writer_is_refused_with_the_holders_pid_and_force_deletes_nothing(tmp_path, capsys):
    out = tmp_path / "run"
    out.mkdir()
    (out / "keep.txt").write_text("the other writer's file")
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys, time\nfrom pathlib import Path\n"
            "from dqfd_bc_keras.files import DirectoryLock\n"
            "with DirectoryLock(Path(sys.argv[1])):\n print('locked', flush=True)\n time.sleep(60)",
            str(out),
        ],
        stdout=subprocess.PIPE,
        text=True,
        cwd=REPO,
        env=ENV,
    )
    try:
        assert holder.stdout.readline() == "locked\n"
        code = cli.run(train_main, ["--quick", "--quiet", "--force", "--out", str(out)])
        one_line(capsys, code, f"error: {out} is in use by process {holder.pid}; wait for it to finish or stop it")
        assert (out / "keep.txt").read_text() == "the other writer's file"
    finally:
        holder.kill()
        holder.wait()
    # The holder died without releasing: its PID is still in the file, and the lock is taken over.
    assert (out / ".lock").read_text() == f"{holder.pid}\n"
    with DirectoryLock(out):
        assert (out / ".lock").read_text() == f"{os.getpid()}\n"
    assert capsys.readouterr().err == (
        f"warning: {out}: taking over the lock left by process {holder.pid}, which is no longer running\n"
    )
    assert (out / ".lock").read_text() == ""  # released cleanly: nothing to take over next time
    with DirectoryLock(out):
        pass
    assert capsys.readouterr().err == ""


def test_a_lock_is_exclusive_within_a_process_too(tmp_path):
    with (
        DirectoryLock(tmp_path / "run"),
        pytest.raises(RunDirectoryError, match=f"is in use by process {os.getpid()}"),
        DirectoryLock(tmp_path / "run"),
    ):
        pass


# --- the lab's runners ---


@pytest.mark.slow
def test_a_run_held_by_another_live_runner_is_left_to_it_and_not_failed(finished, tmp_path):
    arm = Arm("cartpole", "bootstrap", "bayes", tuple(QUICK.items()), "quick", 1)
    run = tmp_path / "suite" / arm.name / "seed0"
    shutil.copytree(finished, run)
    (run / runs.COMPLETE).unlink()
    lines = []
    with DirectoryLock(run):  # this test process is the other runner
        [outcome] = run_suite([arm], None, tmp_path / "suite", SweepOptions(1, progress=lines.append))
    assert outcome.busy and not outcome.error
    assert "left to the runner that holds it" in lines[1] and f"in use by process {os.getpid()}" in lines[1]
    assert "1 run(s) left to another runner" in lines[-1]


DONE = re.compile(r"\[\d+/\d+\] (\S+) seed0: \d+ episodes, \d+ steps, eval ")


@pytest.mark.slow
def test_two_runners_on_one_out_finish_each_run_once(tmp_path):
    """The second runner lists both runs as to do, then is held (SIGSTOP) while the first finishes
    them: when it goes on, it finds them complete and skips them, instead of resuming each and
    finishing it a second time (a second checkpoint, event file and complete.json)."""
    out = tmp_path / "suite"
    args = [sys.executable, *LAB, "run", "quick", "--seeds", "1", "--workers", "1", *TINY_SWEEP, "--out", str(out)]
    first = subprocess.Popen(args, cwd=REPO, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    second = subprocess.Popen(
        args, cwd=REPO, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True
    )  # its own process group: its workers stop with it
    try:
        listed = second.stdout.readline()
        os.killpg(second.pid, signal.SIGSTOP)
        first_out, first_err = first.communicate(timeout=300)
        written = {
            path: (path.read_bytes(), path.stat().st_ino)
            for path in out.glob("*/seed0/**/*")
            if path.is_file() and path.name != ".lock"
        }
    finally:
        os.killpg(second.pid, signal.SIGCONT)
    second_out, second_err = second.communicate(timeout=300)
    assert listed == "quick: 2 runs, 0 already complete, 2 to run on 1 local worker(s)\n", (listed, first_out)
    assert first.returncode == 0 and second.returncode == 0, (first_err, second_err)
    seeds = sorted(out.glob("*/seed0"))
    assert len(seeds) == 2 and all((run / "complete.json").is_file() for run in seeds)
    assert sorted(DONE.match(line)[1] for line in first_out.splitlines() if DONE.match(line)) == sorted(
        run.parent.name for run in seeds
    )
    skipped = [line for line in second_out.splitlines() if line.startswith("[")]
    assert len(skipped) == 2 and all(
        line.split(": ", 1)[1].startswith("skipped: another runner completed it (") for line in skipped
    ), second_out
    for run in seeds:
        assert len([p for p in (run / "checkpoints").iterdir() if p.is_dir()]) == 1
        assert len(list((run / "tb").glob("events.out.tfevents.*"))) == 1
    assert {
        path: (path.read_bytes(), path.stat().st_ino)
        for path in out.glob("*/seed0/**/*")
        if path.is_file() and path.name != ".lock"
    } == written  # not a file rewritten, even to the same bytes
    assert [json.loads(line)["runs"] for line in (out / "sweeps.jsonl").read_text().splitlines()] == [2, 2]
