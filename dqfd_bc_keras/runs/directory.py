"""A training run on disk: what `train.py` writes, checkpoints, and resuming.

    RUN_DIR/config.json        every hyperparameter (written once, at the start), and under
                               "observation" the env's observation space and how it was flattened
            metrics.csv        one row per episode (records.EpisodeRow)
            evals.csv          greedy evaluations on the plain env at exactly every eval_every interactions
                               (records.EvalRow)
            demonstrations.json  the initial D_demo: size, returns and source (records.DemoSummary;
                               runs with demonstrations)
            dynamic_demos.json every dynamic-demonstration update (records.DemoUpdate)
            tb/                TensorBoard events: returns, evaluations, each loss term
            checkpoints/       latest checkpoint (models, Adam, replay, RNGs, counters, Python state), and
                               demos_given.npz, D_demo as given before any interaction
            q_network.keras  bc_model.keras  demos.npz  eval.json  learning_curve.png   (at the end)
            provenance.json    the code, libraries and machine the run ran on (at the end)
            complete.json      written last: the run is complete only when it exists

Every file is written atomically. One process writes a run directory (`.lock` holds its PID).
The files of records are written by `runs/writers.py`, the checkpoints by `runs/checkpoints.py`
(a run killed at any moment resumes from a complete one), the TensorBoard events by
`runs/events.py`; what a resume reads back first is `runs/resume.py`'s.

A directory is a run directory when it holds `checkpoints/latest.json` or `complete.json`, or a
`config.json` that train.py wrote (a JSON object with a `task` and an `expert_loss`: a run's first
file). Only such a directory is replaced (`--force`), and replacing it deletes only the names above,
in tb/ and checkpoints/ only the run's own files (and the temporaries of its writes): any other file
or folder a user put there is kept. Any other directory that is not empty (its lock aside) is
refused. A run killed before its first checkpoint holds its config.json but no checkpoint: a rerun,
or `--resume`, starts it over, with a warning.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from dqfd_bc_keras import demos as demo_io
from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.core.memory import check_memory
from dqfd_bc_keras.envs.episodes import EvalResult
from dqfd_bc_keras.envs.make import checked_spaces
from dqfd_bc_keras.errors import DivergedError
from dqfd_bc_keras.files import DirectoryLock, atomic_path, remove_temporaries, write_text
from dqfd_bc_keras.runs.checkpoints import restore_checkpoint, save_checkpoint
from dqfd_bc_keras.runs.events import EventLog
from dqfd_bc_keras.runs.provenance import provenance
from dqfd_bc_keras.runs.resume import given_demos, read_config, restart_demos, saved_config
from dqfd_bc_keras.runs.writers import (
    COMPLETE,
    GIVEN_DEMOS,
    METRICS,
    RESTART,
    RESUME,
    append_row,
    check_dir,
    clear,
    plot_learning_curve,
    write_config,
    write_demonstrations,
    write_dynamic_demos,
    write_evals,
    write_metrics,
)
from dqfd_bc_keras.runtime import keras_conversions
from dqfd_bc_keras.seeds import final_eval_seed
from dqfd_bc_keras.training.loop import Callback, Learner, build, evaluate_at, run_evaluation, train_with_callback
from dqfd_bc_keras.training.records import DemoSummary, EpisodeRow, EvalRow
from dqfd_bc_keras.training.state import TrainingState

EVAL_FIELDS = EvalRow.columns()
"""evals.csv's columns, as the record spells them."""


@dataclass
class RunResult:
    """What a finished run reports: where, how long, its counts and the final evaluation."""

    out: Path
    episodes: int
    env_steps: int
    interactions: int
    stopped_early: bool
    wall_time: float
    evaluation: EvalResult
    run: RunDirectory | None = field(default=None, repr=False)
    """The run directory's learner and state, to go on training (`continue_run`)."""


class RunDirectory:
    """One run directory and the learner training into it."""

    def __init__(self, config: Config, out: Path, learner: Learner, state: TrainingState, quiet: bool) -> None:
        self.config, self.out, self.learner, self.state = config, out, learner, state
        self.metrics_rows = -1
        """Rows metrics.csv holds as this process wrote it (−1: not written yet by this process)."""
        self.events = EventLog(out / "tb")
        self.progress = None
        if not quiet and sys.stderr.isatty():
            from tqdm import tqdm

            self.progress = tqdm(
                total=config.total_steps,
                unit="step",
                dynamic_ncols=True,
                initial=int(learner.interaction.env_steps.numpy()),
            )

    def write_demonstrations(self, source: str | None) -> None:
        """What the run started from before any interaction (not interactions themselves), as it
        was given (checkpoints/demos_given.npz) and its summary: a dataset from `source` (a file, a
        Minari dataset, a Python object: DEMO_SOURCES), or one it recorded from its expert (None)."""
        data = self.learner.demos
        if data is None:
            return
        demo_io.save(data, self.out / "checkpoints" / GIVEN_DEMOS, force=True)
        meta = data.meta
        source = source or "recorded"
        write_demonstrations(
            self.out,
            DemoSummary(
                transitions=len(data),
                episodes=data.n_episodes,
                expert=meta.expert,
                episode_returns=meta.episode_returns,
                plain_returns=meta.plain_returns,
                pretrain_steps=self.config.pretrain_steps,
                source=source,
            ),
        )

    # --- called after every episode -------------------------------------------------------
    def on_episode(self, learner: Learner, state: TrainingState, row: EpisodeRow) -> None:
        step = row.env_step
        self.events.episode(row)
        if self.progress is not None:
            self.progress.update(step - self.progress.n)
            self.progress.set_postfix(episode=row.episode, ret=f"{row.return_:.0f}")
        self.write_metrics()
        if state.demo_updates:
            write_dynamic_demos(self.out, state.demo_updates)
        if step >= state.next_checkpoint:
            state.next_checkpoint = step + self.config.checkpoint_every
            self.save_checkpoint()

    def write_metrics(self) -> None:
        """metrics.csv: the new episode's row appended, so a long run writes each row once (a
        rewrite per episode cost O(episodes²)); written whole, atomically, when the file is not one
        row behind (this process's first episode, a resume). A crash in an append leaves at worst a
        partial last line, which the resume's rewrite replaces."""
        rows = self.state.metrics
        if self.metrics_rows == len(rows) - 1 and (self.out / METRICS).is_file():
            append_row(self.out / METRICS, rows[-1])
        else:
            write_metrics(self.out, rows)
        self.metrics_rows = len(rows)

    def evaluate(self, points: list[int]) -> list[EvalRow]:
        """One greedy evaluation of the current network, logged at each grid point in `points`."""
        rows = evaluate_at(self.learner, self.state, points)
        self.events.evaluations(rows)
        write_evals(self.out, self.state.evals)
        return rows

    # --- checkpoints (runs/checkpoints.py) -----------------------------------------------------
    def save_checkpoint(self) -> None:
        save_checkpoint(self.out, self.learner, self.state, self.config)

    def restore_checkpoint(self) -> None:
        self.state = restore_checkpoint(self.out, self.learner)
        self.learner.tally.count = self.state.interactions

    # --- the end ----------------------------------------------------------------------------
    def finish(self) -> RunResult:
        if self.progress is not None:
            self.progress.close()
        learner, out = self.learner, self.out
        with atomic_path(out / "q_network.keras") as tmp, keras_conversions():
            learner.agent.q_network.save(tmp)
        if learner.bc is not None:
            with atomic_path(out / "bc_model.keras") as tmp, keras_conversions():
                learner.bc.save(tmp)
        if learner.dynamic is not None:
            demo_io.save(learner.dynamic.dataset, out / "demos.npz", force=True)
        evaluation = run_evaluation(
            self.config, learner.agent, self.config.final_eval_episodes, final_eval_seed(self.config.seed)
        )
        write_text(out / "eval.json", json.dumps(evaluation.to_dict(), indent=1))
        plot_learning_curve(self.state.metrics, self.state.evals, self.config, out / "learning_curve.png")
        self.save_checkpoint()
        self.events.close(create=True)
        write_text(out / "provenance.json", json.dumps(provenance(), indent=1))
        write_text(
            out / COMPLETE,
            json.dumps(
                {
                    "episodes": self.state.episode,
                    "env_steps": int(learner.interaction.env_steps.numpy()),
                    "interactions": learner.interactions,
                }
            )
            + "\n",
            durable=True,
        )
        return RunResult(
            out,
            self.state.episode,
            int(learner.interaction.env_steps.numpy()),
            learner.interactions,
            self.state.stopped_early,
            self.state.wall_time,
            evaluation,
        )


def train(
    config: Config,
    out: str | Path,
    dataset: demo_io.DemoDataset | None = None,
    resume: bool = False,
    force: bool = False,
    quiet: bool = False,
    source: str | None = None,
    callback: Callback | None = None,
    started: Callable[[RunDirectory], None] | None = None,
) -> RunResult:
    """Train `config` into run directory `out` (or continue the run there with `resume`), as
    its only writer. A new run that fails before its first checkpoint leaves nothing behind.
    `source` says where a given `dataset` came from (DEMO_SOURCES; None: a file or a Minari
    dataset, as its metadata says); `callback` is given each episode's and evaluation's row;
    `started`, the run once it has its first checkpoint (stopped later, it goes on: `continue_run`)."""
    out = Path(out)
    if not resume:
        # before anything is written: a run that cannot fit (or whose env cannot) is refused, not killed halfway
        check_memory(config, checked_spaces(config))
    with DirectoryLock(out, check=lambda: check_dir(out, resume, force)) as lock:  # a live writer is named first
        mode = lock.checked
        if mode == RESTART:
            dataset = restart_demos(out, config, dataset, resume)
        resume = mode == RESUME
        try:
            if not resume:
                clear(out)
            run = _start(config, out, dataset, resume, quiet, source)
        except BaseException as error:
            if not resume:
                clear(out)  # and the lock removes a directory it made, left empty
            if isinstance(error, DivergedError):
                raise DivergedError(f"{out}: {error}; nothing was kept") from None
            if isinstance(error, KeyboardInterrupt) and not resume:  # what the command line says it left
                error.args = (f"{out}: nothing was kept (the run had not reached its first checkpoint)",)
            raise
        if started is not None:
            started(run)
        if resume:  # restored: what a kill cut short goes
            remove_temporaries(out)
            (out / COMPLETE).unlink(missing_ok=True)  # written again when it finishes again
        return _train_into(run, callback)


def continue_run(run: RunDirectory, total_steps: int, callback: Callback | None = None) -> RunResult:
    """Go on training the learner of `run`, finished or stopped in this process, to a budget of
    `total_steps`: its config.json says the new budget once a checkpoint has it."""
    with DirectoryLock(run.out):
        run.learner.extend(total_steps)
        run.config = run.learner.config
        run.progress = None
        run.events.close()  # closed by `finish`, or left open by a stop: opened again when used
        (run.out / COMPLETE).unlink(missing_ok=True)
        run.save_checkpoint()
        write_config(run.config, run.out)
        return _train_into(run, callback)


def _train_into(run: RunDirectory, callback: Callback | None) -> RunResult:
    """Steps 3–5 into the run's directory (until a False of `callback`), then its end."""
    try:
        train_with_callback(run.learner, run.state, run.on_episode, run.evaluate, callback)
    except DivergedError as error:
        kept = json.loads((run.out / "checkpoints" / "latest.json").read_text())["dir"]
        raise DivergedError(f"{run.out}: {error}; the last good checkpoint, {kept}, is kept") from None
    result = run.finish()
    result.run = run
    return result


def save_run(out: str | Path, learner: Learner, state: TrainingState, source: str | None) -> None:
    """Write `learner` and its `state`, trained in this process, as a complete run directory `out`
    (replacing a run there): what `evaluate.py`, `train.py --resume` and `DQfD.load` read."""
    out = Path(out)
    with DirectoryLock(out, check=lambda: check_dir(out, resume=False, force=True)):
        clear(out)
        write_config(learner.config, out)
        run = RunDirectory(learner.config, out, learner, state, quiet=True)
        run.write_demonstrations(source)
        write_metrics(out, state.metrics)
        write_evals(out, state.evals)
        if state.demo_updates:
            write_dynamic_demos(out, state.demo_updates)
        run.finish()


def _start(
    config: Config, out: Path, dataset: demo_io.DemoDataset | None, resume: bool, quiet: bool, source: str | None = None
) -> RunDirectory:
    """Steps 1–2 and the first checkpoint, or a resumed run's learner and state."""
    if resume:
        config = saved_config(out)
        if read_config(out / "config.json") != config:  # the budget a checkpoint has and config.json lacked
            write_config(config, out)
    else:
        write_config(config, out)
    if resume and config.uses_demos:  # the run's own D_demo, not a new recording (nor the --demos of this call)
        dataset = given_demos(out / "checkpoints" / GIVEN_DEMOS, config)
    learner, _ = build(config, dataset, fresh=not resume)
    run = RunDirectory(config, out, learner, TrainingState(), quiet)
    if resume:
        run.restore_checkpoint()
    else:
        run.write_demonstrations(source or (demo_io.given_source(dataset) if dataset is not None else None))
        run.state.next_checkpoint = config.checkpoint_every
        run.save_checkpoint()
    return run
