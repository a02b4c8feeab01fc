"""The files of a run directory that hold its records (`records.py`), and the learning curve
drawn from them. One writer for every run directory: `runs/directory.py` while a run trains, and the
lab's test fixture (tests/data/make_suite.py), so the lab reads what runs write.

    config.json          the run's `Config`, and under "observation" the env's observation space
                         and how it was flattened
    metrics.csv          one `EpisodeRow` per episode
    evals.csv            one `EvalRow` per grid point of interactions
    demonstrations.json  the `DemoSummary` of the D_demo the run started from
    dynamic_demos.json   one `DemoUpdate` per dynamic-demonstration update

Every file is written atomically; metrics.csv may also grow by one appended row. Which
directories hold a run, and what replacing one deletes (`check_dir`, `clear`: only what the run
wrote), is decided here too, without TensorFlow, so that `train.py` refuses a wrong `--out` in a second.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import re
import shutil
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import IO

import numpy as np

from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.envs.make import get_task, task_spaces
from dqfd_bc_keras.errors import ConfigError, OutputExistsError
from dqfd_bc_keras.files import DirectoryLock, atomic_path, naming, temporary_of, write_text
from dqfd_bc_keras.training.records import DemoSummary, DemoUpdate, EpisodeRow, EvalRow, Record

METRICS, EVALS = "metrics.csv", "evals.csv"
DEMONSTRATIONS, DYNAMIC_DEMOS = "demonstrations.json", "dynamic_demos.json"
COMPLETE = "complete.json"
"""Written last, atomically, by a finished run: a run without it is resumed, never taken as done."""
GIVEN_DEMOS = "demos_given.npz"
"""D_demo as the run was given it, kept beside its checkpoints: a resume starts from the same
demonstrations whatever their source (a file, a Minari dataset, a recording)."""
RUN_FILES = frozenset(
    {
        "config.json",
        METRICS,
        EVALS,
        DEMONSTRATIONS,
        DYNAMIC_DEMOS,
        "tb",
        "checkpoints",
        "q_network.keras",
        "bc_model.keras",
        "demos.npz",
        "eval.json",
        "learning_curve.png",
        "provenance.json",
        COMPLETE,
    }
)
"""The names a run writes in its directory (runs/directory.py's docstring): all that replacing a run deletes."""
NEW, RESUME, RESTART = "new", "resume", "restart"
"""What training into a directory does (`check_dir`): start a run, resume the one there, or start
over the one there that was stopped before its first checkpoint."""


def has_checkpoint(out: Path) -> bool:
    """Whether `out` holds a run with a checkpoint: what `--resume` continues."""
    return (out / "checkpoints" / "latest.json").is_file()


def is_run(out: Path) -> bool:
    """Whether `out` holds a run (the rule of runs/directory.py's docstring): what `--force` may replace."""
    if has_checkpoint(out) or (out / COMPLETE).is_file():
        return True
    try:
        config = json.loads((out / "config.json").read_text())
    except (OSError, ValueError):
        return False
    return isinstance(config, dict) and {"task", "expert_loss"} <= config.keys()


def check_dir(out: Path, resume: bool, force: bool) -> str:
    """NEW, RESUME or RESTART for training into `out`; refuses what would overwrite a run (unless
    `force`), or anything that is not a run, or resuming what has no checkpoint. Checked before
    TensorFlow loads, and again holding the lock before it writes anything (DirectoryLock's
    `check`): a refusal writes nothing."""
    contents = sorted(p.name for p in out.iterdir() if p.name != DirectoryLock.NAME) if out.is_dir() else []
    if resume and not (contents and is_run(out)):
        raise ConfigError(f"{out} has no checkpoint to resume from")
    if not contents:
        return NEW
    if not is_run(out):
        shown = ", ".join(contents[:3]) + (f" and {len(contents) - 3} more" if len(contents) > 3 else "")
        raise OutputExistsError(
            f"{out} is not a run directory (it holds {shown}), and only a run is ever replaced; "
            "choose a new or empty --out"
        )
    if has_checkpoint(out):
        if resume:
            return RESUME
        if force:
            return NEW
        raise OutputExistsError(f"{out} already holds a run; pass --resume to continue it or --force to replace it")
    if force:
        return NEW
    if not ((out / METRICS).exists() or (out / COMPLETE).exists()):
        return RESTART  # killed between its config.json and its first checkpoint: nothing to lose
    raise OutputExistsError(
        f"{out} holds a run without a checkpoint, which cannot be resumed; pass --force to replace it"
    )


CHECKPOINT = re.compile(r"ckpt-\d+(\.\d+)?")
"""The name of a checkpoint directory in RUN/checkpoints (`ckpt-{env step}`, `.k` when taken)."""
OWN_LAYOUT = {
    "checkpoints": lambda name: name in ("latest.json", GIVEN_DEMOS) or CHECKPOINT.fullmatch(name),
    "tb": lambda name: name.startswith("events.out.tfevents."),
}
"""What the run writes inside its two folders: all of them that `clear` deletes."""


def clear(out: Path) -> None:
    """Delete what a run wrote in `out`: the files of RUN_FILES, in checkpoints/ and tb/ only what
    the run writes there (OWN_LAYOUT), and the temporaries of its writes. Its lock and every other
    file or folder are kept: nothing a user put there is deleted."""
    for path in out.iterdir():
        if _folder(path) and path.name in OWN_LAYOUT:
            _clear(path, OWN_LAYOUT[path.name])
        elif not _folder(path) and (path.name in RUN_FILES or temporary_of(path.name) is not None):
            path.unlink()


def _clear(folder: Path, own: Callable[[str], object]) -> None:
    """What the run writes in its `folder` (`own`: files, and checkpoint folders, deleted whole) and
    the temporaries there; the folder too, once empty."""
    for path in folder.iterdir():
        if _folder(path) and own(path.name):
            shutil.rmtree(path)
        elif not _folder(path) and (own(path.name) or temporary_of(path.name) is not None):
            path.unlink()
    with contextlib.suppress(OSError):  # a user's file is left in it
        folder.rmdir()


def _folder(path: Path) -> bool:
    """A folder itself (a link to one is unlinked like a file: nothing it points to is deleted)."""
    return path.is_dir() and not path.is_symlink()


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
    """One more row at the end of the CSV file `path` (written by `write_rows` for its type); an
    OSError names `path` (a full disk's, raised by the write, names no file)."""
    with naming(path), open(path, "a", newline="") as file:
        _writer(file, type(row)).writerow(row.to_row())


def write_config(config: Config, out: Path) -> None:
    """config.json: every field, and under "observation" the env's observation space and its flattening."""
    observation = task_spaces(config.task, config.env_kwargs).layout.to_dict()
    write_text(out / "config.json", json.dumps({**config.to_dict(), "observation": observation}, indent=1))


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
        ax.plot(steps[window - 1 :], average, color="tab:blue", lw=2, label=f"moving average ({window})")
    if evals:
        ax.plot(
            [e.env_step for e in evals],
            [e.mean_return for e in evals],
            "o-",
            color="tab:orange",
            label="greedy evaluation",
        )
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
