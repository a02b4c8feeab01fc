"""Full disks and read-only places: a run or an evaluation that cannot write fails in one line naming
the file the user knows (never a temporary), leaves no debris, and keeps its last checkpoint, from
which the run resumes. The OS errors are raised where the OS would raise them; a real tmpfs is
mounted too where the machine allows it (as root)."""

import errno
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import keras
import pytest
import tensorflow as tf
from helpers import REPO, TINY_RUN, latest_checkpoint, one_line

from dqfd_bc_keras.commands import cli
from dqfd_bc_keras.commands.evaluate import main as evaluate_main
from dqfd_bc_keras.commands.train import main as train_main
from dqfd_bc_keras.files import temporary_of
from dqfd_bc_keras.runs import directory as runs

pytestmark = pytest.mark.slow

# --- full disks ---


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
    assert (latest_checkpoint(out) / "state.json").is_file()
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


def test_a_full_disk_writing_tensorboard_events_is_one_line_and_the_run_resumes(tmp_path, capsys, monkeypatch):
    out = tmp_path / "run"
    events = out / "tb" / "events.out.tfevents.1.vm.1.0.v2"
    real = tf.summary.scalar

    def full(name, data, step=None, description=None):
        if name.startswith("eval/"):  # the first evaluation, after the first checkpoint
            raise tf.errors.ResourceExhaustedError(
                None,
                None,
                f"{{{{function_node __wrapped__FlushSummaryWriter}}}} {events}; No space left on device"
                "\n\tFailed to flush 1 events [Op:FlushSummaryWriter]",
            )
        return real(name, data, step=step, description=description)

    monkeypatch.setattr(tf.summary, "scalar", full)
    one_line(
        capsys,
        cli.run(train_main, [*TINY_RUN, "--out", str(out)]),
        f"error: {out}/tb: cannot write the TensorBoard events (ResourceExhaustedError: {events}; No space left "
        "on device)\n",
    )
    monkeypatch.undo()
    assert (latest_checkpoint(out) / "state.json").is_file() and not (out / runs.COMPLETE).exists()
    assert cli.run(train_main, ["--quiet", "--resume", "--out", str(out)]) == 0
    assert (out / runs.COMPLETE).is_file()


@pytest.mark.parametrize("name", ["q_network.keras", "eval.json", "provenance.json", runs.COMPLETE])
def test_a_full_disk_in_the_final_phase_names_the_file(finished, tmp_path, capsys, monkeypatch, name):
    """What `write` raises on a full disk names no file, and the writer writes a temporary one."""
    run = tmp_path / "run"
    shutil.copytree(finished, run)
    (run / runs.COMPLETE).unlink()  # cut off in its final phase: a resume finishes it
    real_text, real_save = Path.write_text, keras.Model.save

    def full(path):
        if temporary_of(Path(path).name) == name:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(Path, "write_text", lambda self, *a, **k: full(self) or real_text(self, *a, **k))
    monkeypatch.setattr(keras.Model, "save", lambda self, path, *a, **k: full(path) or real_save(self, path, *a, **k))
    one_line(
        capsys,
        cli.run(train_main, ["--quiet", "--resume", "--out", str(run)]),
        f"error: {run / name}: No space left on device\n",
    )
    assert not (run / runs.COMPLETE).exists()
    assert not [p for p in run.rglob(".*") if p.name != ".lock"]  # no temporary left


# --- read-only places ---


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


def test_evaluate_out_on_a_read_only_place_names_the_file_asked_for(tmp_path, capsys, monkeypatch):
    place = tmp_path / "ro"
    place.mkdir()
    mounted = not subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "ro,size=100k", "tmpfs", str(place)], capture_output=True
    ).returncode
    if not mounted:  # a real read-only mount needs root: what mkstemp raises there

        def read_only(prefix, suffix, dir):
            raise OSError(errno.EROFS, os.strerror(errno.EROFS), f"{dir}/{prefix}abcd1234{suffix}")

        monkeypatch.setattr(tempfile, "mkstemp", read_only)
    try:
        one_line(
            capsys,
            cli.run(
                evaluate_main, [str(REPO / "models" / "cartpole"), "--episodes", "1", "--out", str(place / "eval.json")]
            ),
            f"error: {place / 'eval.json'}: Read-only file system\n",
        )
    finally:
        if mounted:
            subprocess.run(["umount", str(place)], check=True)
