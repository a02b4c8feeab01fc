"""Hyperparameter search on Optuna: `python -m dqfd_bc_keras.experiments tune …`, or from Python

    from dqfd_bc_keras.tuning import tune
    found = tune("acrobot", expert_loss="bayes", metric="threshold", trials=20, out="tuning/acrobot")
    DQfD("acrobot", **found.params)               # the best params, as train.py --params best.json takes them

The layer above the lab: a study's trials are ordinary run directories (the lab's archive format),
its search spaces are declared beside the methods (`core/search_space.py`, `Method.space`).
docs/TUNING.md says what each metric rewards and how a study is shared across machines.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from dqfd_bc_keras.tuning.study import TuneSettings


@dataclass(frozen=True)
class Tuned:
    """What a `tune` call leaves: the best complete trial (None while there is none) and the study."""

    params: dict[str, Any] | None
    value: float | None
    trial: int | None
    study: Any
    """The `optuna.Study`, for Optuna's own analysis (`study.trials_dataframe()`, …)."""
    best_file: Path | None
    """OUT/best.json, once a trial is complete."""


def tune(task: str = "cartpole", *, out: str | Path, **settings: Any) -> Tuned:
    """Run (or continue) a study: `TuneSettings`' fields as keywords, the command line's flags
    (`study_name`, `storage`, `trials`, `seeds`, `steps`, `metric`, `threshold`, `sampler`, `pruner`,
    `workers`, `backend`, `space_file`, `fixed` for `--set`, `quick`, `demos`, `env_kwargs`, …)."""
    from dqfd_bc_keras.tuning.outputs import BEST, write_outputs
    from dqfd_bc_keras.tuning.study import prepare
    from dqfd_bc_keras.tuning.workers import run_workers

    prepared = prepare(TuneSettings(out=Path(out), task=task, **settings))
    try:
        run_workers(prepared)
    finally:
        study = prepared.study()
        written = write_outputs(study, prepared.settings)
    found = (Path(out) / BEST) if written else None
    if found is None:
        return Tuned(None, None, None, study, None)
    best = study.best_trial
    return Tuned(best.user_attrs.get("params", best.params), best.value, best.number, study, found)


__all__ = ["TuneSettings", "Tuned", "tune"]
