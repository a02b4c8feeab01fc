"""Paths that cannot work are named in one line before anything is written: an `--out` that is a
file, lies under a file, is empty or is not UTF-8; an `evaluate.py --out` that is a directory; a
`--demos` that is a directory or a loop of symbolic links."""

import os
import shutil

import pytest
from helpers import REPO, assert_refused, command, left_in, one_line

from dqfd_bc_keras.commands import cli
from dqfd_bc_keras.commands.evaluate import main as evaluate_main
from dqfd_bc_keras.commands.train import main as train_main


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


@pytest.mark.slow
def test_evaluate_into_a_directory_is_one_line(finished, tmp_path, capsys):
    code = cli.run(evaluate_main, [str(finished), "--episodes", "1", "--out", str(tmp_path)])
    one_line(capsys, code, f"error: {tmp_path}: is a directory, not a file")


@pytest.mark.parametrize(
    "script, args, message",
    [
        ("train.py", ["--quick", "--out", ""], "error: --out must not be empty"),
        (
            "train.py",
            ["--quick", "--out", os.fsdecode(b"run\xff")],
            "error: --out b'run\\xff' is not a UTF-8 path, and TensorFlow writes only to those; choose another name",
        ),
        ("evaluate.py", ["models/cartpole", "--out", ""], "error: --out must not be empty"),
    ],
)
def test_an_out_that_cannot_work_is_refused_in_one_line_before_anything_is_written(tmp_path, script, args, message):
    work = tmp_path / "work"
    shutil.copytree(REPO / "models" / "cartpole", work / "models" / "cartpole")
    assert_refused(command(script, *args, cwd=work), message)
    assert left_in(work) == ["models"]  # no runs/, no run\xff
