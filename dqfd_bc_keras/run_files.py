"""The files of a run directory that hold its records (`records.py`), and the learning curve
drawn from them. One writer for every run directory: `runs.py` while a run trains, and the
lab's test fixture (tests/data/make_suite.py), so the lab reads what runs write.

    metrics.csv          one `EpisodeRow` per episode
    evals.csv            one `EvalRow` per grid point of interactions
    demonstrations.json  the `DemoSummary` of the D_demo the run started from
    dynamic_demos.json   one `DemoUpdate` per dynamic-demonstration update

Every file is written atomically; metrics.csv may also grow by one appended row.
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Sequence
from pathlib import Path
from typing import IO

import numpy as np

from .config import Config
from .envs import get_task
from .files import atomic_path, write_text
from .records import DemoSummary, DemoUpdate, EpisodeRow, EvalRow, Record

METRICS, EVALS = "metrics.csv", "evals.csv"
DEMONSTRATIONS, DYNAMIC_DEMOS = "demonstrations.json", "dynamic_demos.json"


def _writer(file: IO[str], record: type[Record]) -> csv.DictWriter:
    return csv.DictWriter(file, fieldnames=record.columns(), lineterminator="\n")


def write_rows(path: Path, record: type[Record], rows: Sequence[Record]) -> None:
    """The CSV file of `rows` (records of type `record`), its header the record's columns; None
    is an empty cell."""
    buffer = io.StringIO()
    writer = _writer(buffer, record)
    writer.writeheader()
    writer.writerows(row.to_row() for row in rows)
    write_text(path, buffer.getvalue())


def append_row(path: Path, row: Record) -> None:
    """One more row at the end of the CSV file `path` (written by `write_rows` for its type)."""
    with open(path, "a", newline="") as file:
        _writer(file, type(row)).writerow(row.to_row())


def write_metrics(out: Path, rows: Sequence[EpisodeRow]) -> None:
    write_rows(out / METRICS, EpisodeRow, rows)


def write_evals(out: Path, rows: Sequence[EvalRow]) -> None:
    write_rows(out / EVALS, EvalRow, rows)


def write_demonstrations(out: Path, summary: DemoSummary) -> None:
    write_text(out / DEMONSTRATIONS, json.dumps(summary.to_row(), indent=1))


def write_dynamic_demos(out: Path, updates: Sequence[DemoUpdate]) -> None:
    write_text(out / DYNAMIC_DEMOS, json.dumps([update.to_row() for update in updates], indent=1))


def plot_learning_curve(metrics: Sequence[EpisodeRow], evals: Sequence[EvalRow], config: Config, path: Path) -> None:
    """Training returns per episode (plain env's scale), their moving average, and the greedy
    evaluations, against environment steps, with the plain env's "solved" threshold."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    if metrics:
        steps = np.array([row.env_step for row in metrics])
        returns = np.array([row.plain_return for row in metrics], dtype=float)
        ax.plot(steps, returns, color="tab:blue", alpha=0.3, lw=1, label="training episode")
        window = min(config.dynamic_window, len(returns))
        average = np.convolve(returns, np.ones(window) / window, mode="valid")
        ax.plot(steps[window - 1:], average, color="tab:blue", lw=2, label=f"moving average ({window})")
    if evals:
        ax.plot([e.env_step for e in evals], [e.mean_return for e in evals], "o-", color="tab:orange",
                label="greedy evaluation")
    spec = get_task(config.task)
    if spec.solved_return is not None:
        ax.axhline(spec.solved_return, color="grey", ls="--", lw=1, label=f"solved ({spec.solved_return:g})")
    ax.set_xlabel("environment steps")
    ax.set_ylabel(f"return on {spec.env_id}")
    ax.set_title(f"{config.task} · {config.expert_loss} · timeout={config.timeout} · seed {config.seed}")
    ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=100)
    plt.close(fig)
