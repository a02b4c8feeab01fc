"""`train.py --resume` continues only the run it says it is: a damaged checkpoint, a config.json that
is garbled, edited or of another task, a checkpoint without a variable the learner has, and flags that
would change the run are each refused in one line naming the file, and the run is left byte for byte
as it was. (A wrong value in config.json or state.json: tests/test_config_checks.py.)"""

import os
import shutil

import pytest
from helpers import latest_checkpoint, one_line, tree

from dqfd_bc_keras.commands import cli
from dqfd_bc_keras.commands.train import main as train_main

DAMAGE = {
    "truncated tf.index": (lambda run: os.truncate(latest_checkpoint(run) / "tf.index", 10), "too short", "ckpt-"),
    "truncated tf.data": (
        lambda run: os.truncate(next(latest_checkpoint(run).glob("tf.data-*")), 100),
        "",
        "ckpt-",
    ),
    "truncated state.json": (
        lambda run: os.truncate(latest_checkpoint(run) / "state.json", 5),
        "JSONDecodeError",
        "ckpt-",
    ),
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


@pytest.mark.slow
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


@pytest.mark.slow
def test_a_checkpoint_without_a_variable_the_learner_has_is_one_line(finished, tmp_path, capsys):
    """As a checkpoint of an earlier version is (e.g. before the replay counted its unsettled rows):
    here one that holds only the Q-network."""
    import keras
    import tensorflow as tf

    run = tmp_path / "run"
    shutil.copytree(finished, run)
    prefix = latest_checkpoint(run) / "tf"
    for old in prefix.parent.glob("tf.*"):
        old.unlink()
    q_network = keras.saving.load_model(run / "q_network.keras")
    tf.train.Checkpoint(q_network=q_network).write(str(prefix))
    before = tree(run)
    code = cli.run(train_main, ["--quiet", "--resume", "--out", str(run)])
    error = capsys.readouterr().err
    assert code == 2 and error.count("\n") == 1, error
    assert error.startswith(f"error: {latest_checkpoint(run)}: the checkpoint cannot be resumed (")
    assert error.endswith("; start the run over with --force\n")
    assert tree(run) == before


@pytest.mark.slow
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
