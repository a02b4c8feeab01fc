"""A run's checkpoint is switched atomically, so a run stopped at any moment resumes: a kill (SIGKILL)
or an interrupt at each file operation of a save leaves the old checkpoint or the new one, complete; a
kill at any file operation of the final phase is resumed, never taken for a finished run; a run killed
before its first checkpoint starts over. The kill before the first checkpoint is a process of its own
(`command`); the others are snapshots of the run directory taken at each file operation."""

import json
import shutil
import signal
from pathlib import Path

import pytest
import tensorflow as tf
from helpers import TINY_RUN, command

from dqfd_bc_keras.commands import cli
from dqfd_bc_keras.commands.train import main as train_main
from dqfd_bc_keras.core.config import QUICK, Config
from dqfd_bc_keras.demos import record, save
from dqfd_bc_keras.experiments.suites import Arm
from dqfd_bc_keras.runs import checkpoints
from dqfd_bc_keras.runs import directory as runs
from dqfd_bc_keras.training.loop import TrainingState

pytestmark = pytest.mark.slow

# --- a save: the old checkpoint or the new one, never neither ---


@pytest.mark.parametrize("same_step", [False, True], ids=["new-step", "same-step"])
def test_a_kill_at_any_point_of_a_checkpoint_save_leaves_a_resumable_run(tmp_path, monkeypatch, same_step):
    """Snapshot the run directory before and after every file operation of a save (what a
    SIGKILL at that moment leaves on disk); every snapshot restores a complete checkpoint, the
    old one or the new one. `same_step` is the final save rewriting a checkpoint at its step."""
    config = Config.for_task("cartpole", **QUICK)
    out = tmp_path / "run"
    out.mkdir()
    run = runs._start(config, out, None, resume=False, quiet=True)
    run.state.episode = 7
    if not same_step:
        run.learner.interaction.env_steps.assign(300)
    snapshots = []

    def snapshot():
        shutil.copytree(out, tmp_path / f"snap{len(snapshots)}", symlinks=True)
        snapshots.append(tmp_path / f"snap{len(snapshots)}")

    def watched(function):
        def operation(*args, **kwargs):
            snapshot()
            result = function(*args, **kwargs)
            snapshot()
            return result

        return operation

    for module, name in [
        (checkpoints, "write_text"),
        (checkpoints, "sync_tree"),
        (checkpoints.demo_io, "save"),
        (shutil, "rmtree"),
        (tf.train.Checkpoint, "write"),
    ]:
        monkeypatch.setattr(module, name, watched(getattr(module, name)))
    run.save_checkpoint()
    monkeypatch.undo()
    assert len(snapshots) >= 10
    assert [p.name for p in (out / "checkpoints").iterdir() if p.is_dir()] == [
        json.loads((out / "checkpoints" / "latest.json").read_text())["dir"]
    ]  # the old one is gone
    episodes = set()
    for snap in snapshots:
        reader = runs.RunDirectory(config, snap, run.learner, TrainingState(), quiet=True)
        reader.restore_checkpoint()
        episodes.add(reader.state.episode)
    assert episodes == {0, 7}  # some snapshots hold the old checkpoint, the later ones the new


def test_an_interrupt_at_any_point_of_a_checkpoint_save_leaves_a_resumable_run(tmp_path, monkeypatch):
    """Ctrl-C or SIGTERM (a KeyboardInterrupt, which runs the save's clean-up, unlike a kill) after
    each file operation of a save: the run restores a complete checkpoint every time. (An
    interrupt just after the switch to the new checkpoint once deleted it, and the run could not
    be resumed.)"""
    config = Config.for_task("cartpole", **QUICK)
    out = tmp_path / "run"
    out.mkdir()
    run = runs._start(config, out, None, resume=False, quiet=True)
    operations = [
        (checkpoints, "write_text"),
        (checkpoints, "sync_tree"),
        (shutil, "rmtree"),
        (tf.train.Checkpoint, "write"),
    ]
    calls, interrupt_after = [0], [None]

    def watched(function):
        def operation(*args, **kwargs):
            result = function(*args, **kwargs)
            calls[0] += 1
            if calls[0] == interrupt_after[0]:
                raise cli.Terminated
            return result

        return operation

    for module, name in operations:
        monkeypatch.setattr(module, name, watched(getattr(module, name)))
    run.save_checkpoint()  # counts the operations of one save
    per_save, interrupted, current, switched = calls[0], 0, 0, set()
    assert per_save >= 6
    for k in range(1, per_save + 1):
        calls[0], interrupt_after[0] = 0, k
        run.state.episode = k
        run.learner.interaction.env_steps.assign(1000 * k)
        try:
            run.save_checkpoint()
        except cli.Terminated:
            interrupted += 1
        reader = runs.RunDirectory(config, out, run.learner, TrainingState(), quiet=True)
        reader.restore_checkpoint()
        assert reader.state.episode in (current, k), k  # the checkpoint current before, or this one
        current = reader.state.episode
        if current == k:
            switched.add(k)
    assert interrupted == per_save
    assert switched and min(switched) < per_save  # some interrupts came after the switch, before the save's end


def test_the_final_save_at_the_checkpoints_step_never_removes_the_current_one(finished, tmp_path):
    """Resuming a finished run saves again at the same step: a new directory, then the switch."""
    run = tmp_path / "run"
    shutil.copytree(finished, run)
    before = json.loads((run / "checkpoints" / "latest.json").read_text())["dir"]
    assert cli.run(train_main, ["--quiet", "--out", str(run), "--resume"]) == 0
    after = json.loads((run / "checkpoints" / "latest.json").read_text())["dir"]
    assert after == f"{before}.1" and [p.name for p in (run / "checkpoints").iterdir() if p.is_dir()] == [after]


# --- the final phase: nothing half-written counts as done ---


def test_a_kill_at_any_file_operation_of_the_final_phase_is_resumed_never_skipped(finished, tmp_path, monkeypatch):
    """Snapshot the run directory at every file operation of `finish` while its temporary exists
    (what a SIGKILL then leaves); no snapshot is complete, and each one resumes to a complete run
    with the same evaluation and no temporaries left."""
    import contextlib

    from dqfd_bc_keras import files
    from dqfd_bc_keras.demos import npz as demo_files
    from dqfd_bc_keras.experiments.sweep import Job
    from dqfd_bc_keras.runs import writers as run_files

    run = tmp_path / "run"
    shutil.copytree(finished, run)
    snapshots, original = [], files.atomic_path

    @contextlib.contextmanager
    def snapshotting(path, **options):
        with original(path, **options) as tmp:
            yield tmp
            if Path(tmp).exists():
                snapshots.append((Path(path).name, tmp_path / f"snap{len(snapshots)}"))
                shutil.copytree(run, snapshots[-1][1])

    for module in (files, runs, run_files, demo_files):
        monkeypatch.setattr(module, "atomic_path", snapshotting)
    assert cli.run(train_main, ["--quick", "--quiet", "--out", str(run), "--resume"]) == 0  # finishes again
    monkeypatch.undo()
    names = [name for name, _ in snapshots]
    assert {
        "q_network.keras",
        "bc_model.keras",
        "eval.json",
        "learning_curve.png",
        "state.json",
        "latest.json",
        "provenance.json",
        runs.COMPLETE,
    } <= set(names), names
    assert names[-1] == runs.COMPLETE
    final = json.loads((finished / "eval.json").read_text())
    arm = Arm("cartpole", "bootstrap", "bayes", tuple(QUICK.items()), "quick", 1)
    for name, snap in snapshots:
        job = Job(arm, 0, snap.parent)
        assert not (snap / runs.COMPLETE).is_file(), name
        assert not Job(arm, 0, tmp_path).complete
        assert cli.run(train_main, ["--quick", "--quiet", "--out", str(snap), "--resume"]) == 0, name
        assert (snap / runs.COMPLETE).is_file() and (snap / "provenance.json").is_file(), name
        assert json.loads((snap / "eval.json").read_text()) == final, name
        assert not [p for p in snap.rglob(".*") if p.name != ".lock"], name  # the temporaries are gone
        del job


# --- before the first checkpoint: the run starts over ---


KILL_AT_FIRST_CHECKPOINT = """
import os, signal, sys
from dqfd_bc_keras.commands import cli
from dqfd_bc_keras.commands.train import main
from dqfd_bc_keras.runs import directory as runs
runs.RunDirectory.save_checkpoint = lambda self: os.kill(os.getpid(), signal.SIGKILL)
sys.exit(cli.run(main, sys.argv[1:]))
"""


@pytest.fixture(scope="module")
def killed(tmp_path_factory) -> Path:
    """A run killed (SIGKILL) at its first checkpoint, given its demonstrations as a file."""
    root = tmp_path_factory.mktemp("killed")
    save(record("cartpole", "strong", 2), root / "demos.npz")
    out = root / "run"
    done = command(
        "-c",
        KILL_AT_FIRST_CHECKPOINT,
        *TINY_RUN,
        "--set",
        "learning_rate=0.002",
        "--demos",
        root / "demos.npz",
        "--out",
        out,
    )
    assert done.returncode == -signal.SIGKILL, done.stderr
    assert (out / "config.json").is_file() and not (out / "checkpoints" / "latest.json").exists()
    assert (out / "checkpoints" / runs.GIVEN_DEMOS).is_file()
    return out


@pytest.mark.parametrize("resume", [True, False], ids=["resume", "rerun"])
def test_a_run_killed_before_its_first_checkpoint_is_started_over(killed, tmp_path, capsys, resume):
    run = tmp_path / "run"
    shutil.copytree(killed, run)
    pid = (run / ".lock").read_text().strip()
    args = ["--quiet", "--resume"] if resume else [*TINY_RUN, "--set", "learning_rate=0.003"]
    assert cli.run(train_main, [*args, "--out", str(run)]) == 0
    assert capsys.readouterr().err.splitlines() == [
        f"warning: {run}: taking over the lock left by process {pid}, which is no longer running",
        f"warning: {run}: no checkpoint yet (the run was stopped before its first); starting it over",
    ]
    config = json.loads((run / "config.json").read_text())
    source = json.loads((run / "demonstrations.json").read_text())["source"]
    if resume:  # the run's own config and demonstrations
        assert (config["learning_rate"], config["total_steps"], source) == (0.002, 300, "file")
    else:  # a new run, as this command says
        assert (config["learning_rate"], source) == (0.003, "recorded")
    assert (run / runs.COMPLETE).is_file()
