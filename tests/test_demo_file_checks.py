"""A demonstration file is checked before it is trusted: a member whose header claims rows it does not
hold, or more bytes than its compression can give (a zip bomb's shape), is named before anything is
allocated; a file of another task, of other shapes, with a mistyped meta or with more transitions than
demo_capacity is refused before any training; and its size is read from its header alone."""

import io
import json
import struct
import zipfile

import numpy as np
import pytest
from helpers import DEMOS, assert_refused, command, one_line

from dqfd_bc_keras.commands import cli
from dqfd_bc_keras.commands.train import main as train_main
from dqfd_bc_keras.demos import record, save
from dqfd_bc_keras.errors import DemoFileError

# --- files whose headers lie ---


@pytest.fixture(scope="module")
def demos_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("demos") / "demos.npz"
    save(record("cartpole", "strong", episodes=1, seed=0), path)
    return path


def forge(source, target, member: str, shape: tuple[int, ...], data: bytes):
    """`source` with `member`'s .npy header claiming `shape` over `data`."""
    with zipfile.ZipFile(source) as zin, zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as zout:
        for info in zin.infolist():
            content = zin.read(info)
            if info.filename == member:
                header = io.BytesIO()
                np.lib.format.write_array_header_1_0(header, {"descr": "<f4", "fortran_order": False, "shape": shape})
                content = header.getvalue() + data
            zout.writestr(info.filename, content)
    return target


@pytest.mark.parametrize("rows", [10**12, 10**7])
def test_a_header_claiming_rows_its_member_does_not_hold_is_named_not_allocated(demos_file, tmp_path, rows):
    forged = forge(demos_file, tmp_path / "forged.npz", "obs.npy", (rows, 4), bytes(64))
    assert forged.stat().st_size < 20_000
    expected = (
        f"error: {forged}: member obs.npy claims shape ({rows}, 4) of float32 ({rows * 16} bytes), "
        "but holds 64 bytes of data"
    )
    assert_refused(command(*DEMOS, "inspect", forged), expected)
    if rows == 10**12:  # train.py reads the file through the same load
        assert_refused(command("train.py", "--quick", "--demos", forged, "--out", tmp_path / "run"), expected)
        assert not (tmp_path / "run").exists()


def test_a_member_claiming_more_than_its_compression_can_give_is_refused(demos_file, tmp_path):
    """A zip whose central directory claims 160 MB of obs from 64 stored bytes (a zip bomb's shape)."""
    forged = forge(demos_file, tmp_path / "forged.npz", "obs.npy", (10**7, 4), bytes(64))
    content = bytearray(forged.read_bytes())
    with zipfile.ZipFile(forged) as archive:
        info = archive.getinfo("obs.npy")
    entry = content.index(b"PK\x01\x02")  # the central directory's entries, until obs.npy's
    while content[entry + 46 : entry + 46 + len(b"obs.npy")] != b"obs.npy":
        entry = content.index(b"PK\x01\x02", entry + 4)
    header_size = info.file_size - 64
    struct.pack_into("<I", content, entry + 24, 10**7 * 16 + header_size)  # its uncompressed size
    forged.write_bytes(bytes(content))
    assert_refused(
        command(*DEMOS, "inspect", forged),
        f"error: {forged}: member obs.npy claims {10**7 * 16 + header_size} bytes from "
        f"{info.compress_size} compressed, which its compression cannot give (a damaged file)",
    )


# --- files checked against the task before any training ---


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
