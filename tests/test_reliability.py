"""No run is ever lost, every failure is one line, one writer per run directory (issue F).

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

import pytest
import tensorflow as tf

from dqfd_bc_keras import cli, runs
from dqfd_bc_keras.config import QUICK, Config
from dqfd_bc_keras.errors import BrokenRunError, ConfigError, RunDirectoryError
from dqfd_bc_keras.files import DirectoryLock
from dqfd_bc_keras.experiments.suites import Arm
from dqfd_bc_keras.experiments.sweep import run_suite
from dqfd_bc_keras.training import TrainingState

REPO = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(REPO)}


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


@pytest.fixture(scope="module")
def finished(tmp_path_factory) -> Path:
    """A finished `train.py --quick` run."""
    out = tmp_path_factory.mktemp("finished") / "run"
    assert cli.run(train_main, ["--quick", "--quiet", "--out", str(out)]) == 0
    return out


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

    for module, name in [(runs, "write_text"), (runs, "sync_tree"), (runs.demo_io, "save"), (shutil, "rmtree"),
                         (tf.train.Checkpoint, "write")]:
        monkeypatch.setattr(module, name, watched(getattr(module, name)))
    run.save_checkpoint()
    monkeypatch.undo()
    assert len(snapshots) >= 10
    assert [p.name for p in (out / "checkpoints").iterdir() if p.is_dir()] == [
        json.loads((out / "checkpoints" / "latest.json").read_text())["dir"]]  # the old one is gone
    episodes = set()
    for snap in snapshots:
        reader = runs.RunDirectory(config, snap, run.learner, TrainingState(), quiet=True)
        reader.restore_checkpoint()
        episodes.add(reader.state.episode)
    assert episodes == {0, 7}  # some snapshots hold the old checkpoint, the later ones the new


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
    holder = subprocess.Popen([sys.executable, "-c", "import sys, time\nfrom pathlib import Path\n"
                               "from dqfd_bc_keras.files import DirectoryLock\n"
                               "with DirectoryLock(Path(sys.argv[1])):\n print('locked', flush=True)\n time.sleep(60)",
                               str(out)], stdout=subprocess.PIPE, text=True, cwd=REPO, env=ENV)
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
    assert capsys.readouterr().err == (f"warning: {out}: taking over the lock left by process {holder.pid}, "
                                       "which is no longer running\n")
    assert (out / ".lock").read_text() == ""  # released cleanly: nothing to take over next time
    with DirectoryLock(out):
        pass
    assert capsys.readouterr().err == ""


def test_a_lock_is_exclusive_within_a_process_too(tmp_path):
    with DirectoryLock(tmp_path / "run"):
        with pytest.raises(RunDirectoryError, match=f"is in use by process {os.getpid()}"):
            with DirectoryLock(tmp_path / "run"):
                pass


# --- corrupt or mismatched state -------------------------------------------------------------------

def _checkpoint(run: Path) -> Path:
    return run / "checkpoints" / json.loads((run / "checkpoints" / "latest.json").read_text())["dir"]


DAMAGE = {
    "truncated tf.index": (lambda run: os.truncate(_checkpoint(run) / "tf.index", 10), "too short", "ckpt-"),
    "truncated tf.data": (lambda run: os.truncate(next(_checkpoint(run).glob("tf.data-*")), 100), "", "ckpt-"),
    "truncated state.json": (lambda run: os.truncate(_checkpoint(run) / "state.json", 5), "JSONDecodeError", "ckpt-"),
    "empty latest.json": (lambda run: (run / "checkpoints" / "latest.json").write_text(""), "JSONDecodeError",
                          "latest.json"),
    "garbage config.json": (lambda run: (run / "config.json").write_text("garbage{"), "JSONDecodeError", "config.json"),
    "config.json of another task": (
        lambda run: (run / "config.json").write_text((run / "config.json").read_text().replace(
            '"task": "cartpole"', '"task": "mountaincar"')), "was recorded on task 'cartpole'", "demos_given.npz"),
}


@pytest.mark.parametrize("damage", DAMAGE)
def test_resuming_a_corrupt_or_mismatched_run_is_one_line_and_changes_nothing(finished, tmp_path, capsys, damage):
    apply, problem, where = DAMAGE[damage]
    run = tmp_path / "run"
    shutil.copytree(finished, run)
    apply(run)
    before = tree(run)
    err = one_line(capsys, cli.run(train_main, ["--quiet", "--out", str(run), "--resume"]),
                   "start the run over with --force")
    assert f"error: {run}/" in err and where in err and problem in err
    assert tree(run) == before


def test_the_runner_reports_a_broken_run_and_restarts_it_when_asked(finished, tmp_path):
    arm = Arm("cartpole", "bootstrap", "bayes", tuple(QUICK.items()), "quick", 1)
    run = tmp_path / "suite" / arm.name / "seed0"
    shutil.copytree(finished, run)
    (run / "eval.json").unlink()  # cut off before it finished …
    (run / "checkpoints" / "latest.json").write_text("")  # … and its checkpoint is damaged
    lines = []
    with pytest.raises(ConfigError, match="1 of 1 runs failed"):
        run_suite([arm], None, tmp_path / "suite", workers=1, progress=lines.append)
    assert "failed: BrokenRunError" in lines[-1] and "--restart-broken" in lines[-1]
    [outcome] = run_suite([arm], None, tmp_path / "suite", workers=1, progress=lines.append, restart_broken=True)
    assert not outcome.error and (run / "eval.json").is_file()


# --- full disks and other OS errors -----------------------------------------------------------------

def test_a_full_disk_at_the_first_checkpoint_is_one_line_and_leaves_no_debris(tmp_path, monkeypatch, capsys):
    def full(self, path, options=None):
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        (Path(path).parent / "tf_temp").mkdir()  # what TensorFlow leaves half written
        raise tf.errors.ResourceExhaustedError(None, None, "{{function_node SaveV2}} x.tempstate1; No space left "
                                               "on device [Op:SaveV2]")

    monkeypatch.setattr(tf.train.Checkpoint, "write", full)
    out = tmp_path / "run"
    err = one_line(capsys, cli.run(train_main, ["--quick", "--quiet", "--out", str(out)]),
                   f"error: {out}/checkpoints/ckpt-0: cannot write the checkpoint (ResourceExhaustedError: ")
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
    one_line(capsys, cli.run(train_main, ["--quick", "--quiet", "--out", str(out)]),
             f"error: {out}/metrics.csv: No space left on device")
    assert (_checkpoint(out) / "state.json").is_file()
    assert not [p for p in out.rglob(".*") if p.name != ".lock"]  # no temporary files left behind


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


@pytest.mark.parametrize("make, args, message", [
    (lambda p: p.write_text("x"), ["--quick", "--out", "{p}"], "{p} is a file, not a run directory"),
    (lambda p: p.write_text("x"), ["--quick", "--out", "{p}/run"], "{p}/run: Not a directory"),
    (lambda p: p.mkdir(), ["--quick", "--demos", "{p}"], "{p}: is a directory, not an .npz file"),
    (lambda p: (p.symlink_to(p.with_name("b")), p.with_name("b").symlink_to(p)), ["--quick", "--demos", "{p}"],
     "{p}: is a symbolic link loop"),
])
def test_bad_paths_are_named_in_one_line(tmp_path, capsys, monkeypatch, make, args, message):
    monkeypatch.chdir(tmp_path)
    path = tmp_path / "a"
    make(path)
    one_line(capsys, cli.run(train_main, [a.format(p=path) for a in args]), message.format(p=path))


def test_a_read_only_filesystem_is_one_line(tmp_path, monkeypatch, capsys):
    def read_only(self, *args, **kwargs):
        raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(self))

    monkeypatch.setattr(Path, "mkdir", read_only)
    one_line(capsys, cli.run(train_main, ["--quick", "--out", str(tmp_path / "run")]),
             f"error: {tmp_path / 'run'}: Read-only file system")
    monkeypatch.undo()
    ro = tmp_path / "ro"
    ro.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=100k", "tmpfs", str(ro)], capture_output=True).returncode:
        return  # a real read-only mount needs root; the injected case above runs everywhere
    try:
        one_line(capsys, cli.run(train_main, ["--quick", "--out", str(ro / "run")]),
                 f"error: {ro / 'run'}: Read-only file system")
    finally:
        subprocess.run(["umount", str(ro)], check=True)


def test_evaluate_into_a_directory_is_one_line(finished, tmp_path, capsys):
    code = cli.run(evaluate_main, [str(finished), "--episodes", "1", "--out", str(tmp_path)])
    one_line(capsys, code, f"error: {tmp_path}: is a directory, not a file")


# --- values out of range --------------------------------------------------------------------------

@pytest.mark.parametrize("main, args, message", [
    (train_main, ["--seed", "-1"], "argument --seed: must be in [0, 2147483647], got -1"),
    (train_main, ["--seed", "99999999999999999999"], "got 99999999999999999999"),
    (train_main, ["--set", "seed=-3"], "seed must be in [0, 2147483647], got -3"),
    (train_main, ["--set", "learning_rate=inf"], "learning_rate must be a finite number, got inf"),
    (train_main, ["--set", "sigma0_sq=nan"], "sigma0_sq must be a finite number, got nan"),
    (evaluate_main, ["models/cartpole", "--seed", "-1"], "argument --seed: must be in [0, 2147483647], got -1"),
])
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
    assert cli.run(train_main, ["--quick", "--quiet", "--seed", "2147483647", "--steps", "100",
                                "--out", str(tmp_path / "run")]) == 0


# --- divergence and signals -------------------------------------------------------------------------

def test_divergence_stops_at_the_first_non_finite_loss_and_keeps_the_last_good_checkpoint(tmp_path, capsys):
    out = tmp_path / "run"
    code = cli.run(train_main, ["--quick", "--quiet", "--set", "learning_rate=1e30", "--set", "pretrain_steps=0",
                                "--out", str(out)])
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
    args = [sys.executable, str(REPO / "train.py"), "--quick", "--quiet", "--set", "total_steps=3000",
            "--set", "checkpoint_every=300", "--out", str(out)]
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
    resumed = subprocess.run([*args, "--resume"], cwd=REPO, env=ENV, capture_output=True, text=True, timeout=300)
    assert resumed.returncode == 0, resumed.stderr
    assert (out / "eval.json").is_file()
