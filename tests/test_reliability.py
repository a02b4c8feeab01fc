"""No run is ever lost, every failure is one line, one writer per run directory.

Each test is one failure mode of the README's table: what breaks, and what the user sees.
"""

import errno
import importlib.util
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import tensorflow as tf
from helpers import call

from dqfd_bc_keras.commands import cli
from dqfd_bc_keras.core.config import QUICK, Config
from dqfd_bc_keras.errors import ConfigError, DemoFileError, RunDirectoryError
from dqfd_bc_keras.experiments.suites import Arm
from dqfd_bc_keras.experiments.sweep import SweepOptions, run_suite
from dqfd_bc_keras.files import DirectoryLock, temporary_of
from dqfd_bc_keras.runs import checkpoints
from dqfd_bc_keras.runs import directory as runs
from dqfd_bc_keras.training.loop import TrainingState

REPO = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(REPO)}


def ctrl_c_reaches() -> None:
    """A child's SIGINT back to the default: launched from a background job without job control
    (`nohup pytest … &`), the tests inherit SIGINT ignored, and Ctrl-C would then never reach the
    child: the behaviour Unix means for background jobs, not the one these tests check."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def script_main(name):
    spec = importlib.util.spec_from_file_location(name.removesuffix(".py"), REPO / name)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.main


train_main, evaluate_main = script_main("train.py"), script_main("evaluate.py")


def one_line(capsys, code, message, expected_code=2):
    err = capsys.readouterr().err
    assert code == expected_code, err
    assert message in err, err
    assert len(err.strip().splitlines()) == 1, err
    return err


def tree(path: Path) -> dict:
    """Every file under `path` and its bytes: to show that a failure damaged nothing."""
    return {str(p.relative_to(path)): p.read_bytes() for p in sorted(path.rglob("*")) if p.is_file()}


@pytest.fixture
def finished(quick_run) -> Path:
    """The session's finished `train.py --quick` run (read-only: a test copies it before it changes it)."""
    return quick_run().out


# --- checkpoints: an atomic switch ----------------------------------------------------------------


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


# --- one writer per run directory ----------------------------------------------------------------


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


# --- corrupt or mismatched state -------------------------------------------------------------------


def _checkpoint(run: Path) -> Path:
    return run / "checkpoints" / json.loads((run / "checkpoints" / "latest.json").read_text())["dir"]


DAMAGE = {
    "truncated tf.index": (lambda run: os.truncate(_checkpoint(run) / "tf.index", 10), "too short", "ckpt-"),
    "truncated tf.data": (lambda run: os.truncate(next(_checkpoint(run).glob("tf.data-*")), 100), "", "ckpt-"),
    "truncated state.json": (lambda run: os.truncate(_checkpoint(run) / "state.json", 5), "JSONDecodeError", "ckpt-"),
    "empty latest.json": (
        lambda run: (run / "checkpoints" / "latest.json").write_text(""),
        "JSONDecodeError",
        "latest.json",
    ),
    "garbage config.json": (lambda run: (run / "config.json").write_text("garbage{"), "JSONDecodeError", "config.json"),
    "config.json of another task": (
        lambda run: (run / "config.json").write_text(
            (run / "config.json").read_text().replace('"task": "cartpole"', '"task": "mountaincar"')
        ),
        "task: 'mountaincar' (was 'cartpole')",
        "config.json",
    ),
    "edited config.json": (
        lambda run: (run / "config.json").write_text(
            (run / "config.json")
            .read_text()
            .replace('"learning_rate": 0.001', '"learning_rate": 0.5')
            .replace('"expert_loss": "bayes"', '"expert_loss": "none"')
        ),
        "differs from the config the run was trained with",
        "expert_loss: 'none' (was 'bayes'); learning_rate: 0.5 (was 0.001)",
    ),
}


@pytest.mark.parametrize("damage", DAMAGE)
def test_resuming_a_corrupt_or_mismatched_run_is_one_line_and_changes_nothing(finished, tmp_path, capsys, damage):
    apply, problem, where = DAMAGE[damage]
    run = tmp_path / "run"
    shutil.copytree(finished, run)
    apply(run)
    before = tree(run)
    err = one_line(
        capsys, cli.run(train_main, ["--quiet", "--out", str(run), "--resume"]), "start the run over with --force"
    )
    assert f"error: {run}/" in err and where in err and problem in err
    assert tree(run) == before


def test_the_runner_reports_a_broken_run_and_restarts_it_when_asked(finished, tmp_path):
    arm = Arm("cartpole", "bootstrap", "bayes", tuple(QUICK.items()), "quick", 1)
    run = tmp_path / "suite" / arm.name / "seed0"
    shutil.copytree(finished, run)
    (run / "eval.json").unlink()  # cut off before it finished …
    (run / runs.COMPLETE).unlink()
    (run / "checkpoints" / "latest.json").write_text("")  # … and its checkpoint is damaged
    lines = []
    with pytest.raises(ConfigError, match="1 of 1 runs failed"):
        run_suite([arm], None, tmp_path / "suite", SweepOptions(1, progress=lines.append))
    assert "failed: BrokenRunError" in lines[-1] and "--restart-broken" in lines[-1]
    [outcome] = run_suite([arm], None, tmp_path / "suite", SweepOptions(1, progress=lines.append), restart_broken=True)
    assert not outcome.error and (run / "eval.json").is_file()


# --- full disks and other OS errors -----------------------------------------------------------------


def test_a_full_disk_at_the_first_checkpoint_is_one_line_and_leaves_no_debris(tmp_path, monkeypatch, capsys):
    def full(self, path, options=None):
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        (Path(path).parent / "tf_temp").mkdir()  # what TensorFlow leaves half written
        raise tf.errors.ResourceExhaustedError(
            None, None, "{{function_node SaveV2}} x.tempstate1; No space left on device [Op:SaveV2]"
        )

    monkeypatch.setattr(tf.train.Checkpoint, "write", full)
    out = tmp_path / "run"
    err = one_line(
        capsys,
        cli.run(train_main, ["--quick", "--quiet", "--out", str(out)]),
        f"error: {out}/checkpoints/ckpt-0: cannot write the checkpoint (ResourceExhaustedError: ",
    )
    assert err.endswith("x.tempstate1; No space left on device)\n")
    assert not out.exists()  # nothing of value was written: a rerun starts clean


def test_a_full_disk_mid_run_is_one_line_and_keeps_a_resumable_checkpoint(tmp_path, monkeypatch, capsys):
    writes = []
    real = runs.RunDirectory.write_metrics

    def fills_up(self):
        writes.append(1)
        if len(writes) == 3:  # the third episode's row of metrics.csv (an append)
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(self.out / "metrics.csv"))
        real(self)

    monkeypatch.setattr(runs.RunDirectory, "write_metrics", fills_up)
    out = tmp_path / "run"
    one_line(
        capsys,
        cli.run(train_main, ["--quick", "--quiet", "--out", str(out)]),
        f"error: {out}/metrics.csv: No space left on device",
    )
    assert (_checkpoint(out) / "state.json").is_file()
    assert not [p for p in out.rglob(".*") if p.name != ".lock"]  # no temporary files left behind


def _full_disk(*args, **kwargs):
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))  # as `write` raises it: naming no file


@pytest.mark.parametrize("existing", [False, True], ids=["new", "empty"])
@pytest.mark.parametrize("write", [".lock", "config.json"])
def test_a_full_disk_before_the_first_checkpoint_names_the_file_and_leaves_no_directory(
    tmp_path, monkeypatch, capsys, write, existing
):
    """The first bytes a run writes (the PID in its lock, then its config.json) fail on a full disk:
    one line naming the file, and nothing left of the run, not even the directories made for it."""
    out = tmp_path / "runs" / "run"
    if existing:
        out.mkdir(parents=True)
    if write == ".lock":
        monkeypatch.setattr(os, "pwrite", _full_disk)
    else:
        real = Path.write_text
        monkeypatch.setattr(
            Path,
            "write_text",
            lambda self, *a, **k: (_full_disk if temporary_of(self.name) == write else real)(self, *a, **k),
        )
    one_line(
        capsys,
        cli.run(train_main, ["--quick", "--quiet", "--out", str(out)]),
        f"error: {out / write}: No space left on device\n",
    )
    assert list(tmp_path.iterdir()) == ([tmp_path / "runs"] if existing else [])
    assert not existing or list(out.iterdir()) == []


def test_a_real_full_disk_where_the_machine_allows_mounting_one(tmp_path, capsys):
    """The same on a 500 kB tmpfs (needs root; the injected cases above run everywhere)."""
    disk = tmp_path / "disk"
    disk.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=500k", "tmpfs", str(disk)], capture_output=True).returncode:
        pytest.skip("cannot mount a tmpfs here; the injected ENOSPC tests cover this case")
    try:
        code = cli.run(train_main, ["--quick", "--quiet", "--out", str(disk / "run")])
        one_line(capsys, code, "No space left on device")
        assert list(disk.iterdir()) == []
    finally:
        subprocess.run(["umount", str(disk)], check=True)


@pytest.mark.parametrize(
    "make, args, message",
    [
        (lambda p: p.write_text("x"), ["--quick", "--out", "{p}"], "{p} is a file, not a run directory"),
        (lambda p: p.write_text("x"), ["--quick", "--out", "{p}/run"], "{p}/run: Not a directory"),
        (lambda p: p.mkdir(), ["--quick", "--demos", "{p}"], "{p}: is a directory, not an .npz file"),
        (
            lambda p: (p.symlink_to(p.with_name("b")), p.with_name("b").symlink_to(p)),
            ["--quick", "--demos", "{p}"],
            "{p}: is a symbolic link loop",
        ),
    ],
)
def test_bad_paths_are_named_in_one_line(tmp_path, capsys, monkeypatch, make, args, message):
    monkeypatch.chdir(tmp_path)
    path = tmp_path / "a"
    make(path)
    one_line(capsys, cli.run(train_main, [a.format(p=path) for a in args]), message.format(p=path))


def test_a_read_only_filesystem_is_one_line(tmp_path, monkeypatch, capsys):
    def read_only(self, *args, **kwargs):
        raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(self))

    monkeypatch.setattr(Path, "mkdir", read_only)
    one_line(
        capsys,
        cli.run(train_main, ["--quick", "--out", str(tmp_path / "run")]),
        f"error: {tmp_path / 'run'}: Read-only file system",
    )
    monkeypatch.undo()
    ro = tmp_path / "ro"
    ro.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=100k", "tmpfs", str(ro)], capture_output=True).returncode:
        return  # a real read-only mount needs root; the injected case above runs everywhere
    try:
        one_line(
            capsys,
            cli.run(train_main, ["--quick", "--out", str(ro / "run")]),
            f"error: {ro / 'run'}: Read-only file system",
        )
    finally:
        subprocess.run(["umount", str(ro)], check=True)


def test_evaluate_into_a_directory_is_one_line(finished, tmp_path, capsys):
    code = cli.run(evaluate_main, [str(finished), "--episodes", "1", "--out", str(tmp_path)])
    one_line(capsys, code, f"error: {tmp_path}: is a directory, not a file")


# --- values out of range --------------------------------------------------------------------------


@pytest.mark.parametrize(
    "main, args, message",
    [
        (train_main, ["--seed", "-1"], "argument --seed: must be in [0, 2147483647], got -1"),
        (train_main, ["--seed", "99999999999999999999"], "got 99999999999999999999"),
        (train_main, ["--set", "seed=-3"], "seed must be in [0, 2147483647], got -3"),
        (train_main, ["--set", "learning_rate=inf"], "learning_rate must be a finite number, got inf"),
        (train_main, ["--set", "sigma0_sq=nan"], "sigma0_sq must be a finite number, got nan"),
        (evaluate_main, ["models/cartpole", "--seed", "-1"], "argument --seed: must be in [0, 2147483647], got -1"),
    ],
)
def test_out_of_range_values_are_one_line_and_write_nothing(tmp_path, capsys, monkeypatch, main, args, message):
    monkeypatch.chdir(REPO)
    out = tmp_path / "run"
    extra = ["--quick", "--out", str(out)] if main is train_main else []
    try:
        code = cli.run(main, [*args, *extra])
    except SystemExit as exit_:  # argparse exits itself
        code = exit_.code
    one_line(capsys, code, message)
    assert not out.exists()


@pytest.mark.parametrize("field", [f for f, v in Config.for_task("cartpole").to_dict().items() if isinstance(v, float)])
def test_every_float_field_must_be_finite(field):
    for value in (float("inf"), float("-inf"), float("nan")):
        with pytest.raises(ConfigError, match=f"{field} must be a finite number"):
            Config.for_task("cartpole", **{field: value})


def test_the_largest_seed_runs(tmp_path):
    assert (
        cli.run(
            train_main, ["--quick", "--quiet", "--seed", "2147483647", "--steps", "100", "--out", str(tmp_path / "run")]
        )
        == 0
    )


# --- divergence and signals -------------------------------------------------------------------------


def test_divergence_stops_at_the_first_non_finite_loss_and_keeps_the_last_good_checkpoint(tmp_path, capsys):
    out = tmp_path / "run"
    code = cli.run(
        train_main,
        ["--quick", "--quiet", "--set", "learning_rate=1e30", "--set", "pretrain_steps=0", "--out", str(out)],
    )
    one_line(capsys, code, f"error: {out}: training diverged in episode 1 (env step ")
    assert json.loads((out / "checkpoints" / "latest.json").read_text())["dir"] == "ckpt-0"
    assert not (out / "eval.json").exists()


def test_divergence_in_pre_training_keeps_nothing(tmp_path, capsys):
    out = tmp_path / "run"
    code = cli.run(train_main, ["--quick", "--quiet", "--set", "learning_rate=1e30", "--out", str(out)])
    one_line(capsys, code, f"error: {out}: training diverged in pre-training: loss = nan")
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


# --- round 2: a resumed run is the run it says it is --------------------------------------------


def test_resume_refuses_flags_that_would_change_the_run(finished, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(finished, run)
    before = tree(run)
    one_line(
        capsys,
        cli.run(
            train_main, ["--quiet", "--out", str(run), "--resume", "--set", "learning_rate=0.5", "--expert-loss", "ce"]
        ),
        "--resume continues the run in its own config, but the command changes expert_loss='ce' (the run has "
        "'bayes'), learning_rate=0.5 (the run has 0.001)",
    )
    one_line(
        capsys,
        cli.run(train_main, ["--quiet", "--out", str(run), "--resume", "--demos", "x.npz"]),
        "--demos (the run keeps the demonstrations it started with)",
    )
    assert tree(run) == before
    assert cli.run(train_main, ["--quick", "--quiet", "--out", str(run), "--resume"]) == 0  # the same values: fine


def test_the_runner_resumes_a_run_only_if_its_config_is_the_arms(finished, tmp_path):
    arm = Arm("cartpole", "bootstrap", "bayes", tuple({**QUICK, "learning_rate": 0.002}.items()), "quick", 1)
    run = tmp_path / "suite" / arm.name / "seed0"
    shutil.copytree(finished, run)  # trained with learning_rate 0.001, and cut off before its end
    (run / runs.COMPLETE).unlink()
    lines = []
    with pytest.raises(ConfigError, match="1 of 1 runs failed"):
        run_suite([arm], None, tmp_path / "suite", SweepOptions(1, progress=lines.append))
    assert "not the arm's config (learning_rate: 0.001 (was 0.002))" in lines[-1] and "--restart-broken" in lines[-1]
    [outcome] = run_suite([arm], None, tmp_path / "suite", SweepOptions(1, progress=lines.append), restart_broken=True)
    assert not outcome.error and json.loads((run / "config.json").read_text())["learning_rate"] == 0.002


# --- round 2: nothing half-written counts as done ---------------------------------------------------


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


# --- round 2: Ctrl-C on a sweep ----------------------------------------------------------------------


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


# --- round 2: demonstrations checked before any TensorFlow work --------------------------------------


def test_demonstrations_are_checked_against_the_task_before_any_training(tmp_path, capsys):
    from dqfd_bc_keras import demos as demo_io

    data = demo_io.record("mountaincar", "imperfect", 1)  # 2 features, 3 actions; its own meta consistent
    demo_io.save(data, tmp_path / "mc.npz")
    out = tmp_path / "run"
    one_line(
        capsys,
        cli.run(train_main, ["--quick", "--demos", str(tmp_path / "mc.npz"), "--out", str(out)]),
        "was recorded on task 'mountaincar', not on the requested 'cartpole'",
    )
    meta = json.loads(str(np.load(tmp_path / "mc.npz")["meta"]))
    arrays = dict(np.load(tmp_path / "mc.npz"))
    np.savez(tmp_path / "renamed.npz", **{**arrays, "meta": np.array(json.dumps({**meta, "task": "cartpole"}))})
    one_line(
        capsys,
        cli.run(train_main, ["--quick", "--demos", str(tmp_path / "renamed.npz"), "--out", str(out)]),
        "holds observations of 2 features and 3 actions, but task cartpole has 4 features and 2 actions",
    )
    np.savez(tmp_path / "typed.npz", **{**arrays, "meta": np.array(json.dumps({**meta, "obs_dim": "2"}))})
    one_line(
        capsys,
        cli.run(
            train_main, ["--quick", "--task", "mountaincar", "--demos", str(tmp_path / "typed.npz"), "--out", str(out)]
        ),
        "meta's obs_dim must be int, got '2'",
    )
    one_line(
        capsys,
        cli.run(
            train_main,
            [
                "--quick",
                "--task",
                "mountaincar",
                "--demos",
                str(tmp_path / "mc.npz"),
                "--set",
                "demo_capacity=100",
                "--set",
                "max_steps=100",
                "--out",
                str(out),
            ],
        ),
        f"holds {len(data)} transitions, more than demo_capacity=100",
    )
    assert not out.exists()


def test_the_size_is_read_from_the_header_without_the_arrays(tmp_path, monkeypatch):
    from dqfd_bc_keras import demos as demo_io

    demo_io.save(demo_io.record("cartpole", "imperfect", 2), tmp_path / "d.npz")
    monkeypatch.setattr(np, "load", lambda *a, **k: pytest.fail("the arrays were read"))
    with pytest.raises(DemoFileError, match="more than demo_capacity=10"):
        demo_io.load(tmp_path / "d.npz", max_transitions=10)


# --- round 2: long evaluations, tiny budgets, provenance ---------------------------------------------


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


def test_budgets_too_small_to_learn_are_refused_or_warned():
    with pytest.raises(ConfigError, match="total_steps=10 is below batch_size=64: without demonstrations"):
        Config.for_task("cartpole", expert_loss="none", total_steps=10)
    with pytest.warns(UserWarning, match="the episode limit 1 is shorter than the n-step window n_step=10"):
        Config.for_task("cartpole", max_steps=1, demo_capacity=500)


def test_provenance_records_the_machine_and_tensorflows_build(finished):
    record = json.loads((finished / "provenance.json").read_text())
    assert record["machine"]["cpu"] and record["machine"]["cores"] == os.cpu_count()
    assert set(record["machine"]["isa"]) <= {"sse4_2", "avx", "avx2", "fma", "avx512f", "avx512_vnni", "amx_tile"}
    assert record["tensorflow"]["version"] == tf.__version__ and record["tensorflow"]["onednn"] == "0"
    assert record["tensorflow"]["intra_op_threads"] == 1 and "is_cuda_build" in record["tensorflow"]["build"]
    assert record["code_commit"] is None or len(record["code_commit"]) == 40
