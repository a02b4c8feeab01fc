"""What a study leaves in `--out` besides its trials: best.json, the params `train.py --params`
takes, and Optuna's own figures of the study (its matplotlib backend)."""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Any

from dqfd_bc_keras.files import atomic_path, write_text

if TYPE_CHECKING:
    import optuna

    from dqfd_bc_keras.tuning.study import TuneSettings

BEST = "best.json"
FIGURES = {
    "history.png": "plot_optimization_history",
    "importances.png": "plot_param_importances",
    "parallel.png": "plot_parallel_coordinate",
}
"""Each figure's file under OUT/figures/ and the `optuna.visualization.matplotlib` function that draws it."""


def best(study: optuna.Study, settings: TuneSettings) -> dict[str, Any] | None:
    """best.json's content: the best complete trial's params (as train.py --params takes them), its
    value, number, the study and its storage; None while no trial is complete."""
    from optuna.trial import TrialState

    if not study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,)):
        return None
    trial = study.best_trial
    return {
        "params": trial.user_attrs.get("params", trial.params),
        "value": trial.value,
        "trial": trial.number,
        "study": study.study_name,
        "storage": settings.storage_url,
        "metric": settings.metric,
        "tunes": study.user_attrs.get("tunes"),
    }


PARALLEL_PARAMS = 6
"""The parallel-coordinate figure shows the most important params only: sixteen axes are unreadable."""


def _most_important(study: optuna.Study) -> list[str] | None:
    """The PARALLEL_PARAMS params of most importance (None, all of them, while importances cannot be had)."""
    import optuna

    try:
        return list(optuna.importance.get_param_importances(study))[:PARALLEL_PARAMS]
    except (ValueError, RuntimeError, ZeroDivisionError):
        return None


def write_outputs(study: optuna.Study, settings: TuneSettings) -> list[Path]:
    """best.json and the figures under `settings.out` (atomically); the files written. A figure
    Optuna cannot draw yet (importances need two complete trials whose params differ) is skipped."""
    written: list[Path] = []
    found = best(study, settings)
    if found is None:
        return written
    path = settings.out / BEST
    write_text(path, json.dumps(found, indent=2) + "\n")
    written.append(path)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import optuna.visualization.matplotlib as figures

    (settings.out / "figures").mkdir(parents=True, exist_ok=True)
    for name, function in FIGURES.items():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the matplotlib backend is "experimental" to Optuna
            try:
                shown = {"params": _most_important(study)} if name == "parallel.png" else {}
                axes = getattr(figures, function)(study, **shown)
            except (ValueError, RuntimeError, ZeroDivisionError):
                continue
        figure = axes.figure
        figure.set_size_inches(10, 6)
        figure.tight_layout()
        with atomic_path(settings.out / "figures" / name) as tmp:
            figure.savefig(tmp, format="png", metadata={"Software": None})
        plt.close(figure)
        written.append(settings.out / "figures" / name)
    return written
