"""Training that diverges stops at the first non-finite loss, in one line, and keeps the last good
checkpoint; diverged in pre-training, before any checkpoint, it keeps nothing."""

import json

import pytest
from helpers import one_line

from dqfd_bc_keras.commands import cli
from dqfd_bc_keras.commands.train import main as train_main

pytestmark = pytest.mark.slow


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
