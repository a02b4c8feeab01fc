"""A run's checkpoints: `checkpoints/ckpt-N/` holds the learner's TensorFlow state (models, Adam,
replay, RNGs, counters), its Python state (state.json), the config it trained with and, with
dynamic demonstrations, its D_demo; `checkpoints/latest.json` names the current one.

A checkpoint is a new directory, fsynced, then made current by rewriting `latest.json`, then the
old one is deleted, so a run killed at any moment resumes from a complete one.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import tensorflow as tf

from dqfd_bc_keras import demos as demo_io
from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.errors import BrokenRunError, RunDirectoryError, one_line
from dqfd_bc_keras.files import sync_tree, write_text
from dqfd_bc_keras.runs.writers import CHECKPOINT
from dqfd_bc_keras.training.loop import Learner
from dqfd_bc_keras.training.state import TrainingState


def save_checkpoint(out: Path, learner: Learner, state: TrainingState, config: Config) -> None:
    """Write a complete new checkpoint of run `out`, fsync it, switch `latest.json` to it, then
    delete the old one: at every moment `latest.json` names a complete checkpoint, whether the
    save is killed or interrupted (Ctrl-C, SIGTERM) at any point of it."""
    root = out / "checkpoints"
    target = free_name(root / f"ckpt-{int(learner.interaction.env_steps.numpy())}")
    try:
        learner.checkpoint().write(str(target / "tf"))
        dynamic = learner.dynamic
        if dynamic is not None:
            demo_io.save(dynamic.dataset, target / "demos.npz", force=True)
            if dynamic.recent:
                demo_io.save(demo_io.concatenate(dynamic.recent, source="agent"), target / "recent.npz", force=True)
        state.interactions = learner.interactions
        write_text(target / "state.json", json.dumps(state.to_dict()))
        write_text(target / "config.json", json.dumps(config.to_dict(), indent=1))  # the run's own
        sync_tree(target)
    except BaseException as error:
        shutil.rmtree(target, ignore_errors=True)  # the debris of a save that did not finish
        if isinstance(error, tf.errors.OpError):  # e.g. the disk is full
            raise RunDirectoryError(f"{target}: cannot write the checkpoint ({one_line(error)})") from None
        raise
    # The switch, outside the clean-up above: once `latest.json` may name `target`, nothing
    # deletes it (an interrupt here leaves one complete checkpoint or the other, and the
    # next save deletes whichever is not current).
    write_text(root / "latest.json", json.dumps({"dir": target.name}), durable=True)
    for old in root.iterdir():  # the run's own (writers.CHECKPOINT): a folder a user put there is kept
        if old.is_dir() and old != target and CHECKPOINT.fullmatch(old.name):
            shutil.rmtree(old, ignore_errors=True)


def restore_checkpoint(out: Path, learner: Learner) -> TrainingState:
    """Load run `out`'s current checkpoint into `learner`; returns the Python state it kept. A
    `BrokenRunError` naming the file if any of it cannot be read."""
    root = out / "checkpoints"
    source = root / "latest.json"
    try:
        checkpoint = root / json.loads(source.read_text())["dir"]
        source = checkpoint / "state.json"  # first: the file a person may have edited is named
        state = TrainingState.from_dict(json.loads(source.read_text()))
        source = checkpoint
        learner.checkpoint().read(str(source / "tf")).assert_existing_objects_matched()
        dynamic = learner.dynamic
        if dynamic is not None:
            dynamic.episodes = demo_io.load(source / "demos.npz").episodes()
            recent = source / "recent.npz"
            dynamic.recent = demo_io.load(recent).episodes() if recent.is_file() else []
    # AssertionError: the checkpoint lacks a variable the learner has (a checkpoint of an earlier version).
    except (OSError, ValueError, LookupError, TypeError, AssertionError, tf.errors.OpError) as error:
        raise BrokenRunError(
            f"{source}: the checkpoint cannot be resumed ({one_line(error)}); start the run over with --force"
        ) from None
    return state


def free_name(path: Path) -> Path:
    """`path`, or `path.1`, `path.2`, … if taken: a checkpoint never overwrites the current one."""
    candidate, k = path, 0
    while candidate.exists():
        k += 1
        candidate = path.with_name(f"{path.name}.{k}")
    return candidate
