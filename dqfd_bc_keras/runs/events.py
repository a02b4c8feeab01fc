"""A run's TensorBoard events (tb/): each episode's row and each evaluation, against interactions."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path

import tensorflow as tf

from dqfd_bc_keras.errors import RunDirectoryError, one_line
from dqfd_bc_keras.training.records import EpisodeRow, EvalRow

SKIPPED = ("episode", "interactions", "wall_time")
"""Columns of an episode row that are not TensorBoard scalars (interactions is its x axis)."""


class EventLog:
    """tb/'s writer, opened at the first summary: a resume that fails to restore leaves no event
    file. TensorFlow's error writing it (a full disk) is one line naming tb/: the run stops there,
    resumable from its last checkpoint."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self._writer: tf.summary.SummaryWriter | None = None

    @contextlib.contextmanager
    def _writing(self) -> Iterator[tf.summary.SummaryWriter]:
        try:
            if self._writer is None:
                self._writer = tf.summary.create_file_writer(str(self.folder))
            yield self._writer
        except tf.errors.OpError as error:
            raise RunDirectoryError(f"{self.folder}: cannot write the TensorBoard events ({one_line(error)})") from None

    def episode(self, row: EpisodeRow) -> None:
        with self._writing() as writer, writer.as_default(step=row.interactions):
            for key, value in row.to_row().items():
                if key not in SKIPPED and value is not None:
                    tf.summary.scalar(f"train/{key}", value)

    def evaluations(self, rows: list[EvalRow]) -> None:
        """The evaluations of a grid point (or of several, one evaluation logged at each), flushed."""
        with self._writing() as writer:
            for row in rows:
                with writer.as_default(step=row.interactions):
                    tf.summary.scalar("eval/plain_return", row.mean_return)
                    tf.summary.scalar("eval/env_step", row.env_step)
                    if row.mean_goals is not None:
                        tf.summary.scalar("eval/goals", row.mean_goals)
            writer.flush()

    def close(self, create: bool = False) -> None:
        """Close the event file (the next summary opens a new one); `create`: open it first if no
        summary did, so that a finished run has its tb/ even when it logged nothing."""
        if self._writer is not None or create:
            with self._writing() as writer:
                writer.close()
        self._writer = None
