"""A user's files are never touched: `train.py` writes, replaces (`--force`) and resumes (`--resume`)
only what the program itself wrote. A `.lock` of the user's is never written, a dotfile that looks
like a temporary is never deleted, and a folder a user put in a run (beside it, or a checkpoint copied
into checkpoints/) is kept. `--force` replaces a run only, never a folder of the user's, and an empty
folder is trained into."""

import json
import os
import shutil
from pathlib import Path

import pytest
from helpers import TINY_RUN, call, left_in, one_line, tree
from test_python_api import TINY

from dqfd_bc_keras import DQfD
from dqfd_bc_keras.commands import cli
from dqfd_bc_keras.commands.train import main as train_main
from dqfd_bc_keras.errors import OutputExistsError
from dqfd_bc_keras.runs import directory as runs


def files(directory: Path) -> dict[str, bytes | None]:
    """Every file (its bytes) and folder (None) under `directory`, by relative path, links unfollowed."""
    return {
        str(path.relative_to(directory)): None if path.is_dir() else path.read_bytes()
        for path in sorted(directory.rglob("*"))
    }


def refused(done, message: str) -> None:
    assert (done.returncode, done.stderr) == (2, f"error: {message}\n"), done.stderr


# --- a .lock of the user's ----------------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("text", ["bob is editing\n", "4242\n", ""], ids=["text", "a pid", "empty"])
@pytest.mark.parametrize("force", [False, True], ids=["plain", "force"])
def test_a_users_lock_file_in_a_folder_that_is_not_a_run_is_left_as_it_was(tmp_path, text, force):
    """Whatever it holds, even what the program's own lock holds: the folder is refused before the
    lock file is opened for writing."""
    out = tmp_path / "work"
    out.mkdir()
    (out / ".lock").write_text(text)
    os.utime(out / ".lock", ns=(0, 0))  # an empty one written and emptied again would show it here
    (out / "thesis.tex").write_text("t")
    before = files(out)
    done = call("train.py", *TINY_RUN, *(["--force"] if force else []), "--out", out)
    refused(
        done,
        f"{out} is not a run directory (it holds thesis.tex), and only a run is ever replaced; "
        "choose a new or empty --out",
    )
    assert files(out) == before and (out / ".lock").stat().st_mtime_ns == 0


def test_a_lock_file_that_is_not_the_programs_is_refused_untouched_even_alone(tmp_path):
    out = tmp_path / "work"
    out.mkdir()
    (out / ".lock").write_text("bob is editing\n")
    done = call("train.py", *TINY_RUN, "--out", out)
    refused(
        done,
        f"{out / '.lock'} is not this program's lock file (it holds other text), and a file the program did "
        "not write is never written; move it away, or choose another directory",
    )
    assert files(out) == {".lock": b"bob is editing\n"}


def test_a_lock_that_is_a_symbolic_link_is_refused_and_its_target_untouched(tmp_path):
    out, target = tmp_path / "work", tmp_path / "elsewhere.txt"
    out.mkdir()
    target.write_text("precious")
    (out / ".lock").symlink_to(target)
    done = call("train.py", *TINY_RUN, "--out", out)
    refused(
        done,
        f"{out / '.lock'} is not this program's lock file (not a regular file); move it away, or choose "
        "another directory",
    )
    assert target.read_text() == "precious" and (out / ".lock").is_symlink()


def test_saving_into_a_folder_that_is_not_a_run_is_refused_and_leaves_no_lock_file(tmp_path):
    """`DQfD.save` takes the lock to look at the folder: the lock file it made for that goes with the
    refusal."""
    out = tmp_path / "work"
    out.mkdir()
    (out / "thesis.tex").write_text("t")
    model = DQfD("cartpole", seed=0, **TINY).learn(100)
    with pytest.raises(OutputExistsError, match="is not a run directory"):
        model.save(out)
    assert files(out) == {"thesis.tex": b"t"}


# --- --resume and --force delete only what the run wrote ----------------------------------------

USERS = {
    ".thesis.20261206.tex": b"chapter 1",  # the old temporaries' pattern matched these
    ".vimrc.original": b"set number",
    ".metrics.abcd1234.csv": b"my own metrics",
    "notes/.draft.12345678.md": b"draft",
    "notes/todo.txt": b"todo",
    ".settings.20261206/colors.json": b"{}",  # a folder the old pattern deleted, recursively
    "checkpoints/ckpt-0-kept-by-me/tf.index": b"a checkpoint I copied",
    "checkpoints/README.txt": b"which checkpoint is which",
    "tb/my-notes.txt": b"notes on the curves",
}
"""Files a user put in a run directory, some of them named as nothing the program writes is now."""


def put(run: Path, contents: dict[str, bytes]) -> None:
    for name, data in contents.items():
        (run / name).parent.mkdir(parents=True, exist_ok=True)
        (run / name).write_bytes(data)


def users_files_in(run: Path) -> dict[str, bytes]:
    return {name: (run / name).read_bytes() for name in USERS if (run / name).is_file()}


@pytest.fixture
def run_with_users_files(quick_run, tmp_path) -> Path:
    """The session's quick run, copied, with the user's files in it, and a temporary a kill left."""
    run = tmp_path / "run"
    shutil.copytree(quick_run().out, run)
    put(run, USERS)
    (run / f".dqfd-tmp-{os.getpid()}-abcd1234-eval.json").write_text("{")  # the program's own
    return run


@pytest.mark.slow
def test_resume_deletes_its_own_temporaries_and_keeps_every_file_of_the_users(run_with_users_files):
    run = run_with_users_files
    (run / runs.COMPLETE).unlink()  # cut off in its final phase: the resume finishes it, with a new checkpoint
    before = json.loads((run / "checkpoints" / "latest.json").read_text())["dir"]
    done = call("train.py", "--quiet", "--resume", "--out", run)
    assert (done.returncode, done.stderr) == (0, "")
    assert users_files_in(run) == USERS
    assert not list(run.glob(".dqfd-tmp-*"))
    now = json.loads((run / "checkpoints" / "latest.json").read_text())["dir"]
    assert now != before and not (run / "checkpoints" / before).exists()  # its own old checkpoint went
    assert sorted(p.name for p in (run / "checkpoints").iterdir()) == sorted(
        ["README.txt", "ckpt-0-kept-by-me", runs.GIVEN_DEMOS, "latest.json", now]
    )


@pytest.mark.slow
def test_force_replaces_the_run_and_keeps_every_file_of_the_users(run_with_users_files):
    run = run_with_users_files
    old_metrics = (run / "metrics.csv").read_bytes()
    done = call("train.py", *TINY_RUN, "--set", "seed=1", "--force", "--out", run)
    assert (done.returncode, done.stderr) == (0, "")
    assert users_files_in(run) == USERS
    assert not list(run.glob(".dqfd-tmp-*"))
    assert (
        json.loads((run / "config.json").read_text())["seed"] == 1 and (run / "metrics.csv").read_bytes() != old_metrics
    )
    assert len(list((run / "tb").glob("events.out.tfevents.*"))) == 1  # the old run's events went


# --- --force replaces only a run, and only what the run wrote ---


@pytest.mark.parametrize("force", [True, False], ids=["force", "plain"])
def test_force_refuses_a_directory_that_is_not_a_run(tmp_path, capsys, force):
    out = tmp_path / "x"
    (out / "photos").mkdir(parents=True)
    (out / "photos" / "a.jpg").write_bytes(b"jpeg")
    (out / "thesis.tex").write_text("t")
    before = tree(out)
    err = one_line(
        capsys,
        cli.run(train_main, [*TINY_RUN, *(["--force"] if force else []), "--out", str(out)]),
        f"error: {out} is not a run directory (it holds photos, thesis.tex), and only a run is ever "
        "replaced; choose a new or empty --out",
    )
    assert "--force" not in err
    assert tree(out) == before and left_in(out) == ["photos", "thesis.tex"]


@pytest.mark.slow
def test_force_replaces_a_run_but_keeps_a_file_the_user_put_in_it(finished, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(finished, run)
    (run / "notes.txt").write_text("my notes")
    (run / ".dqfd-tmp-4242-abcd1234-eval.json").write_text("{")  # a temporary a killed run left
    one_line(
        capsys,
        cli.run(train_main, [*TINY_RUN, "--out", str(run)]),
        f"error: {run} already holds a run; pass --resume to continue it or --force to replace it",
    )
    old_metrics = (run / "metrics.csv").read_bytes()
    assert cli.run(train_main, [*TINY_RUN, "--set", "seed=1", "--force", "--out", str(run)]) == 0
    assert (run / "notes.txt").read_text() == "my notes"
    assert not (run / ".dqfd-tmp-4242-abcd1234-eval.json").exists()
    assert json.loads((run / "config.json").read_text())["seed"] == 1 and (run / runs.COMPLETE).is_file()
    assert (run / "metrics.csv").read_bytes() != old_metrics


@pytest.mark.slow
def test_an_empty_existing_directory_is_trained_into(tmp_path, capsys):
    out = tmp_path / "empty"
    out.mkdir()
    (out / ".lock").write_text("")  # what a released lock leaves: still empty
    assert cli.run(train_main, [*TINY_RUN, "--out", str(out)]) == 0
    assert capsys.readouterr().err == "" and (out / runs.COMPLETE).is_file()
