"""Who takes a study's trials: this process (one worker), a pool of worker processes, or Ray tasks,
each taking trials until the study holds enough; and what is left when they are stopped.

Ctrl-C or SIGTERM stops the workers within seconds: each running trial's run stops where
`train.py` would (its last checkpoint kept) and the trial is marked failed by Optuna; a worker
still running `STOP_GRACE` seconds later is killed, and its trial is marked failed here.
"""

from __future__ import annotations

import os
import sys
import time
from typing import TYPE_CHECKING

from dqfd_bc_keras import runtime
from dqfd_bc_keras.commands.cli import EXIT_USAGE, Terminated
from dqfd_bc_keras.errors import ConfigError, DqfdError
from dqfd_bc_keras.experiments.sweep import as_worker, ray_session, stop_processes
from dqfd_bc_keras.tuning.objective import Objective
from dqfd_bc_keras.tuning.space import params_text
from dqfd_bc_keras.tuning.study import FAILURES_IN_A_ROW, Prepared, open_storage

if TYPE_CHECKING:
    import optuna


def take_trials(prepared: Prepared) -> None:
    """Run trials of the study until it holds `trials` complete, pruned or running ones. A trial
    whose params the algorithm cannot use (a ConfigError, a diverged run) fails and the next one
    starts; `FAILURES_IN_A_ROW` failures in a row stop the worker with the last one's error."""
    import optuna
    from optuna.trial import TrialState

    optuna.logging.set_verbosity(optuna.logging.ERROR)  # a line of ours per trial instead of Optuna's
    study = prepared.study()
    objective = Objective(prepared.settings, prepared.space, prepared.fixed, prepared.runner)
    failures: list[str] = []
    counted = (TrialState.COMPLETE, TrialState.PRUNED, TrialState.RUNNING, TrialState.WAITING)

    def told(study: optuna.Study, trial: optuna.trial.FrozenTrial) -> None:
        _say(progress_line(study, trial, objective.seconds.get(trial.number)))
        failures[:] = [*failures, str(trial.user_attrs.get("error", ""))] if trial.state == TrialState.FAIL else []

    while len(study.get_trials(deepcopy=False, states=counted)) < prepared.settings.trials:
        study.optimize(objective, n_trials=1, catch=(DqfdError,), callbacks=[told], gc_after_trial=True)
        if len(failures) >= FAILURES_IN_A_ROW:
            raise ConfigError(f"{len(failures)} trials in a row failed; the last: {failures[-1]}")


def progress_line(study: optuna.Study, trial: optuna.trial.FrozenTrial, seconds: float | None) -> str:
    """One line per finished trial: its state and value, the best so far, its params."""
    from optuna.trial import TrialState

    took = f", {seconds:.0f} s" if seconds is not None else ""
    params = params_text(trial.user_attrs.get("params", trial.params))
    if trial.state == TrialState.COMPLETE:
        best = study.best_trial
        what = f"{trial.value:.6g} (best {best.value:.6g}, trial {best.number})"
    elif trial.state == TrialState.PRUNED:
        pruned_at = max(trial.intermediate_values, default=None)
        what = f"pruned at step {pruned_at}" if pruned_at is not None else "pruned"
    else:
        what = f"failed: {trial.user_attrs.get('error', 'stopped before it ran')}"
    return f"trial {trial.number}: {what}{took}; {params}"


def _say(line: str) -> None:
    print(line, flush=True)


def run_workers(prepared: Prepared) -> None:
    """Take the study's trials with `workers` workers of `backend` (one: this process)."""
    settings = prepared.settings
    try:
        if settings.backend == "ray":
            _ray(prepared)
        elif settings.workers == 1:
            take_trials(prepared)
        else:
            _local(prepared)
    finally:
        fail_left_running(prepared)


def _local(prepared: Prepared) -> None:
    from multiprocessing import get_context

    context = get_context("spawn")
    processes = [context.Process(target=_worker, args=(prepared,)) for _ in range(prepared.settings.workers)]
    for process in processes:
        process.start()
    try:
        for process in processes:
            process.join()
    except BaseException:
        stop_processes(processes)  # a trial still running after the grace: failed by `fail_left_running`
        raise
    failed = [p.exitcode for p in processes if p.exitcode]
    if failed:
        raise ConfigError(f"{len(failed)} of {len(processes)} workers stopped with an error (said above)")


def _worker(prepared: Prepared) -> None:
    """A worker process (`sweep.as_worker`: SIGTERM stops the trial under way as Ctrl-C stops a run)."""
    as_worker()
    code = 0
    try:
        take_trials(prepared)
    except Terminated:
        code = 143
    except DqfdError as error:
        print(f"error: {error}", file=sys.stderr)
        code = EXIT_USAGE
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def _ray(prepared: Prepared) -> None:
    """`workers` Ray tasks on one CPU each, every one taking trials as a local worker does (the
    storage must reach every machine: a database server, not a SQLite file, across machines)."""
    settings = prepared.settings
    with ray_session(settings.workers, settings.address) as ray:
        task = ray.remote(num_cpus=1, max_retries=0)(_ray_worker)
        pending = [task.remote(prepared) for _ in range(settings.workers)]
        try:
            ray.get(pending)
        except BaseException:
            for ref in pending:
                ray.cancel(ref)
            time.sleep(1.0)
            raise


def _ray_worker(prepared: Prepared) -> None:
    runtime.configure()
    take_trials(prepared)


def fail_left_running(prepared: Prepared) -> None:
    """Mark failed every trial this command started that is still running (its worker was killed,
    or stopped between Optuna's creating the trial and running it): no trial is left RUNNING."""
    from optuna.trial import TrialState

    storage = open_storage(prepared.settings.storage_url)
    for trial in storage.get_all_trials(
        storage.get_study_id_from_name(prepared.settings.name), states=(TrialState.RUNNING,)
    ):
        if trial.user_attrs.get("runner") == prepared.runner:
            storage.set_trial_state_values(trial._trial_id, TrialState.FAIL)  # as Optuna's own stale-trial check does
