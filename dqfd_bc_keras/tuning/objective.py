"""One trial: its params on each of the study's seeds, an ordinary run directory each, scored by
the study's metric; every evaluation reported to the pruner on the way.

The metrics are the lab's measures on a run's evaluation curve (the greedy evaluations at 0, E, 2E,
… interactions, evals.csv) and its final evaluation (eval.json):

- `final`: the final evaluation's mean return (maximised);
- `auc`: the area under the evaluation curve over the whole budget, divided by the budget (the
  curve's last value held to the end when early stopping ends a run sooner): the mean return over
  training, which rewards learning early as well as well (maximised);
- `threshold`: the interactions at the first evaluation whose mean reaches the threshold, every
  interaction the learner's data came from counted (roll-outs included); a run that never reaches it
  counts as the budget plus one evaluation period, its next grid point (minimised).

A trial's value is the mean over its seeds. Its intermediate value at evaluation j of seed k (step
k·evaluations-per-run + j) is that mean over the seeds done and seed k's value as it stands then:
the return at j (`final`), the area so far (`auc`), or the interactions it reached the threshold at,
else the budget plus a period, as if it never will, the seeds not yet run counted so too
(`threshold`: the value falls as runs reach it, since a pruner judges a trial by its best value so
far). Every trial runs the same seeds, so the pruner compares like with like. A run has budget/E + 1
steps; the evaluations past them (dynamic demonstrations' roll-outs count interactions beyond the
env-step budget) are scored, not reported.
"""

from __future__ import annotations

import contextlib
import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from dqfd_bc_keras.files import write_text
from dqfd_bc_keras.training.records import EpisodeRow, EvalRow

if TYPE_CHECKING:
    import optuna

    from dqfd_bc_keras.tuning.study import TuneSettings

Curve = list[tuple[int, float]]
"""(interactions, mean return) of each evaluation of a run so far."""


@dataclass(frozen=True)
class Metric:
    direction: Literal["maximize", "minimize"]
    doc: str


METRICS = {
    "final": Metric("maximize", "the final greedy evaluation's mean return"),
    "auc": Metric("maximize", "the mean return under the evaluation curve over the budget"),
    "threshold": Metric("minimize", "interactions until an evaluation reaches the threshold"),
}


def score(metric: str, curve: Curve, final: float | None, budget: int, period: int, threshold: float | None) -> float:
    """A run's value by `metric`: a finished run's (`final` given), or, while it runs, as it stands."""
    if metric == "final":
        return curve[-1][1] if final is None else final
    if metric == "auc":
        steps, means = np.array([s for s, _ in curve], float), np.array([m for _, m in curve], float)
        end = max(budget, int(steps[-1])) if final is not None else int(steps[-1])
        if end == 0:
            return float(means[0])
        steps, means = np.append(steps, end), np.append(means, means[-1])  # the last value held to the end
        return float(np.sum((steps[1:] - steps[:-1]) * (means[1:] + means[:-1]) / 2) / end)
    assert threshold is not None  # the study refuses the metric without one
    reached = next((step for step, mean in curve if mean >= threshold), None)
    return float(budget + period if reached is None else reached)


def intermediate(metric: str, done: list[float], current: float, remaining: int, never: float) -> float:
    """A trial's value as it stands: the mean over its seeds done and the running one's `current`
    value; for `threshold`, with the `remaining` seeds not yet run counted as `never` reaching it,
    so the value is the trial's if nothing more reaches the threshold, and it only falls as runs go
    on (the pruners judge a trial by its best value so far)."""
    values = [*done, current, *([never] * remaining if metric == "threshold" else [])]
    return float(np.mean(values))


class Pruned(Exception):
    """Raised from a run's callback when the pruner stops the trial (the run keeps its last checkpoint)."""


@dataclass
class Objective:
    """The study's objective: `objective(trial)` trains the trial's params on every seed and returns the mean."""

    settings: TuneSettings
    space: dict
    fixed: dict[str, Any]
    runner: str
    """This command's id, set on each trial it runs (its trials are failed if it is stopped)."""
    seconds: dict[int, float] = field(default_factory=dict)

    def __call__(self, trial: optuna.Trial) -> float:
        import optuna

        from dqfd_bc_keras.tuning.space import suggest

        started = time.perf_counter()
        trial.set_user_attr("runner", self.runner)
        params = suggest(trial, self.space)
        trial.set_user_attr("params", params)  # JSON values (a tuple field's choice decoded)
        directory = self.settings.trials_dir / f"trial-{trial.number:04d}"
        record: dict[str, Any] = {"trial": trial.number, "study": self.settings.name, "params": params, "per_seed": {}}
        try:
            for k, seed in enumerate(self.settings.seed_list):
                record["per_seed"][seed] = self._run(trial, params, k, seed, directory, record)
            value = float(np.mean(list(record["per_seed"].values())))
            record.update(state="COMPLETE", value=value)
            return value
        except Pruned:
            record["state"] = "PRUNED"
            raise optuna.TrialPruned() from None
        except BaseException as error:
            record.update(state="FAIL", error=f"{type(error).__name__}: {error}".rstrip(": "))
            with contextlib.suppress(Exception):  # the storage may be what failed
                trial.set_user_attr("error", record["error"])
            raise
        finally:
            self.seconds[trial.number] = record["seconds"] = round(time.perf_counter() - started, 1)
            directory.mkdir(parents=True, exist_ok=True)
            write_text(directory / "trial.json", json.dumps(record, indent=2) + "\n")

    def _run(self, trial: optuna.Trial, params: dict, k: int, seed: int, directory: Path, record: dict) -> float:
        """Seed `seed` of the trial (the k-th) in `directory`/seedS, reporting each evaluation."""
        import keras

        from dqfd_bc_keras.model import DQfD

        s = self.settings
        keras.backend.clear_session()  # the last run's graphs let go; each run sets its own seeds
        model = DQfD(
            s.task, s.demos, expert_loss=s.expert_loss, seed=seed, out=directory / f"seed{seed}", **self.fixed, **params
        )
        config = model.config
        budget, period = config.total_steps, config.eval_every
        per_run = budget // period + 1
        done = list(record["per_seed"].values())
        curve: Curve = []

        def report(row: EpisodeRow | EvalRow) -> None:
            if not isinstance(row, EvalRow):
                return
            curve.append((row.interactions, row.mean_return))
            if len(curve) > per_run:  # past the budget's grid (roll-outs' interactions): the next seed's steps
                return
            current = score(s.metric, curve, None, budget, period, s.threshold)
            value = intermediate(s.metric, done, current, s.seeds - k - 1, budget + period)
            step = k * per_run + len(curve) - 1
            trial.report(value, step)
            if trial.should_prune():
                record["pruned"] = {"seed": seed, "interactions": row.interactions, "step": step, "value": value}
                pruned = {"trial": trial.number, "study": s.name, "pruner": s.pruner, **record["pruned"]}
                write_text(directory / f"seed{seed}" / "pruned.json", json.dumps(pruned, indent=2) + "\n")
                raise Pruned

        model.learn(callback=report)
        final = json.loads((directory / f"seed{seed}" / "eval.json").read_text())["mean_return"]
        return score(s.metric, curve, float(final), budget, period, s.threshold)
