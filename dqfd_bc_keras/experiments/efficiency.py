"""Sample efficiency against Stable-Baselines3's DQN: steps to threshold, ratios, the RESULTS table.

`python -m dqfd_bc_keras.experiments efficiency` (baselines.py) runs the arms and writes EFFICIENCY_FILE
into the suite directory: per arm and seed, the first step of the evaluation grid (every `eval_every` steps,
10 greedy episodes with the run's fixed evaluation seeds) whose mean return reaches the plain
env's solved threshold. Steps are environment interactions that produced training data: for
our runs evals.csv's `interactions` (dynamic-demonstration roll-outs included, unlike
`env_step`), for SB3 its own `num_timesteps`. A seed that never reaches the threshold counts
as +inf, so a median is inf ("not reached") once half the seeds never do.

Everything below but `efficiency_section` is a pure function of those numbers.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from dqfd_bc_keras.experiments.lab_settings import LAB_SETTINGS, lab_settings
from dqfd_bc_keras.experiments.metrics import first_reaching
from dqfd_bc_keras.experiments.run_files import FinishedRun
from dqfd_bc_keras.experiments.stats import Values, bootstrap_ci
from dqfd_bc_keras.files import write_text

SB3_METHOD = "SB3 DQN (rl-zoo3)"
"""The method name of the Stable-Baselines3 arms."""
EFFICIENCY_FILE = "efficiency.json"
"""Written into the suite directory by `experiments efficiency` (baselines.py); quoted by the report."""
RESAMPLES, RNG_SEED, LEVEL = 10_000, 0, 0.95
"""Percentile bootstrap of every interval here: resamples, generator seed, coverage."""


def teachers() -> dict[str, float]:
    """Task → the imperfect teacher's mean return our final returns are compared with (each task's
    `teacher_return`, lab_settings.py), a user's registered tasks included."""
    return {task: lab.teacher_return for task, lab in LAB_SETTINGS.items() if lab.teacher_return is not None}


@dataclass
class ArmSteps:
    """One arm's seeds: where each first reached the threshold, and how each ended."""

    task: str
    method: str
    first: list[float | None]
    """Per seed: the first evaluated step whose mean return ≥ threshold; None if none did."""
    final: list[float]
    """Per seed: the mean return of the final evaluation (ours: eval.json; SB3: the last grid point)."""
    threshold: float
    anchor: float | None = None
    """SB3 arms: the median of an independent check of the same baseline, to compare with."""
    anchor_final: float | None = None
    """SB3 arms without such a check: a published final return of the same baseline."""

    @classmethod
    def of(
        cls,
        task: str,
        method: str,
        evals: Iterable[Iterable[tuple[float, float]]],
        final: Sequence[float],
        threshold: float,
        anchor: float | None = None,
        anchor_final: float | None = None,
    ) -> ArmSteps:
        """From each seed's (step, mean return) evaluations."""
        return cls(
            task,
            method,
            [first_reaching(e, threshold) for e in evals],
            [float(f) for f in final],
            threshold,
            anchor,
            anchor_final,
        )

    @property
    def target(self) -> float:
        return lab_settings(self.task).target_ratio

    @property
    def label(self) -> str:
        return f"{self.task} {self.method}"

    @property
    def steps(self) -> np.ndarray:
        """Per seed, +inf where the threshold was never reached (step 0 is a real answer)."""
        return np.array([np.inf if s is None else s for s in self.first], dtype=float)


def interaction_evals(run: FinishedRun) -> list[tuple[float, float]]:
    """(interactions, mean return) of each periodic evaluation of one of our runs.

    `env_step` counts training episodes only; a dynamic-demonstration roll-out is an interaction
    too (SB3 would pay for it in steps), so only `interactions` compares with SB3's counter
    (`data.load_runs` refuses an evals.csv without it).
    """
    return [(row["interactions"], row["mean_return"]) for row in run.evals]


def summarise(arm: ArmSteps) -> dict:
    """What the table shows of one arm: the median over seeds with its 95% bootstrap CI
    (inf where not reached), how many seeds reached the threshold, how many end above it."""
    steps = arm.steps
    return {
        "arm": arm.label,
        "seeds": steps.size,
        "reached": int(np.isfinite(steps).sum()),
        "median_steps": float(np.median(steps)),
        "ci": list(bootstrap_ci(steps, np.median, LEVEL, RESAMPLES, RNG_SEED)),
        "above_at_end": sum(f >= arm.threshold for f in arm.final),
    }


def ratio_ci(
    theirs: np.ndarray, ours: np.ndarray, resamples: int = RESAMPLES, seed: int = RNG_SEED
) -> tuple[float, float, float]:
    """median(theirs) ÷ median(ours) and its 95% percentile-bootstrap CI: (point, low, high).

    The two arms are independent runs, so each side's seeds are resampled on their own.
    Division as IEEE does it: ∞ ÷ finite = ∞ (an open-ended interval), finite ÷ ∞ = 0, and
    ∞ ÷ ∞ or 0 ÷ 0 are undefined (nan); if any resample is undefined, so is the CI.
    The ends are order statistics, never interpolated, so an ∞ end stays ∞.
    """
    rng = np.random.default_rng(seed)

    def medians(x: np.ndarray) -> np.ndarray:
        return np.median(x[rng.integers(0, x.size, size=(resamples, x.size))], axis=1)

    with np.errstate(divide="ignore", invalid="ignore"):
        point = float(np.median(theirs) / np.median(ours))
        ratios = medians(theirs) / medians(ours)
    if np.isnan(ratios).any():
        return point, np.nan, np.nan
    tail = 100.0 * (1.0 - LEVEL) / 2.0
    low, high = np.percentile(ratios, [tail, 100.0 - tail], method="inverted_cdf")
    return point, float(low), float(high)


def rows(arms: list[ArmSteps]) -> list[dict]:
    """`summarise` of each arm; ours also get `ratio` = [point, low, high] of SB3's median ÷
    theirs (`ratio_ci`) where the task has an SB3 arm, and `target_met` (point ≥ the task's `target_ratio`,
    lab_settings.py)."""
    sb3 = {a.task: a.steps for a in arms if a.method == SB3_METHOD}
    out = []
    for arm in arms:
        row = summarise(arm)
        if arm.method != SB3_METHOD and arm.task in sb3:
            row["ratio"] = list(ratio_ci(sb3[arm.task], arm.steps))
            row["target_met"] = bool(row["ratio"][0] >= arm.target)
        out.append(row)
    return out


def _steps(value: float) -> str:
    return f"{value:,.0f}" if np.isfinite(value) else "∞"


def times(value: float) -> str:
    return "undefined" if np.isnan(value) else f"{value:.1f}×" if np.isfinite(value) else "∞"


def table(arms: list[ArmSteps]) -> list[str]:
    """The arms as a markdown table: each of ours with SB3's median ÷ its median (95% CI) and
    whether that reaches the task's `target_ratio` (lab_settings.py); each SB3 arm with its independent check beside
    the median; then a note on any open-ended or undefined interval."""
    lines = [
        "| arm | median steps to threshold | 95% CI | seeds that reached it | above it at the end "
        "(median final return) | SB3's median ÷ this median [95% CI] | goal |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    notes = set()
    for arm, row in zip(arms, rows(arms), strict=True):
        median = _steps(row["median_steps"]) + ("" if np.isfinite(row["median_steps"]) else " (not reached)")
        if arm.anchor is not None:
            median += f"; independent check ≈ {arm.anchor:,.0f}"
        ratio = goal = "—"
        if "ratio" in row:
            point, low, high = row["ratio"]
            interval = "CI undefined" if np.isnan(low) else f"{times(low)}, {times(high)}"
            ratio = times(point) + ("" if np.isnan(point) else f" [{interval}]")
            goal = f"{arm.target:g}×: " + ("met" if row["target_met"] else "—" if np.isnan(point) else "not met")
            notes.add("undefined" if np.isnan(low) else "open" if high == np.inf else "")
        final = f"{row['above_at_end']}/{row['seeds']} ({np.median(arm.final):.1f}"
        final += f"; published ≈ {arm.anchor_final:g})" if arm.anchor_final is not None else ")"
        lines.append(
            f"| {row['arm']} | {median} | [{_steps(row['ci'][0])}, {_steps(row['ci'][1])}] | "
            f"{row['reached']}/{row['seeds']} | {final} | {ratio} | {goal} |"
        )
    if "open" in notes:
        lines += [
            "",
            "A ratio interval ending at ∞ is open-ended: in some resamples SB3's median is ∞ (at least "
            "half its seeds never reached the threshold) or ours is 0, so the data set no upper bound.",
        ]
    if "undefined" in notes:
        lines += [
            "",
            "Undefined: neither side's median reached the threshold (∞ ÷ ∞), in the data or in some resamples.",
        ]
    return lines


def teacher_verdict(final: Values, teacher: float) -> tuple[float, float, float, str]:
    """PREREGISTRATION §7: (median final return over seeds, its 95% bootstrap CI, verdict):
    *beats its teacher* if the CI lies wholly above the teacher's mean, *does not* if wholly
    below, else *inconclusive*."""
    median = float(np.median(final))
    low, high = bootstrap_ci(final, np.median, LEVEL, RESAMPLES, RNG_SEED)
    verdict = "beats its teacher" if low > teacher else "does not" if high < teacher else "inconclusive"
    return median, low, high, verdict


def teacher_table(arms: list[ArmSteps]) -> list[str]:
    """Our arms on the tasks with a teacher rule (`teachers()`) against the teacher's mean; [] if none."""
    teacher = teachers()
    ours = [a for a in arms if a.method != SB3_METHOD and a.task in teacher]
    if not ours:
        return []
    lines = [
        "| arm | imperfect teacher (100 episodes) | median final return [95% CI] | verdict |",
        "| --- | --- | --- | --- |",
    ]
    for arm in ours:
        median, low, high, verdict = teacher_verdict(arm.final, teacher[arm.task])
        lines.append(f"| {arm.label} | {teacher[arm.task]:g} | {median:.1f} [{low:.1f}, {high:.1f}] | {verdict} |")
    return lines


def save(path: Path, protocol: dict, arms: list[ArmSteps]) -> None:
    """Write EFFICIENCY_FILE: the evaluation protocol and every arm's seeds."""
    write_text(path, json.dumps({"protocol": protocol, "arms": [asdict(a) for a in arms]}, indent=1))


def load(path: Path) -> tuple[dict, list[ArmSteps]] | None:
    """(protocol, arms) of an EFFICIENCY_FILE; None if there is none or it predates this format
    (a list of rows whose steps were `env_step`s and whose SB3 runs were chunked)."""
    data = json.loads(path.read_text()) if path.is_file() else None
    if not isinstance(data, dict):
        return None
    return data["protocol"], [ArmSteps(**a) for a in data["arms"]]


def efficiency_section(suite_dir: Path) -> list[str]:
    """The "Sample efficiency" section of RESULTS.md, from `suite_dir`/EFFICIENCY_FILE."""
    path = suite_dir / EFFICIENCY_FILE
    loaded = load(path)
    if loaded is None:
        return [
            f"Not run (or {EFFICIENCY_FILE} predates the current protocol): "
            "`python -m dqfd_bc_keras.experiments efficiency "
            f"--out {suite_dir}` writes {EFFICIENCY_FILE}."
        ]
    protocol, arms = loaded
    thresholds = ", ".join(f"{task} {threshold:g}" for task, threshold in {a.task: a.threshold for a in arms}.items())
    return [
        f"Environment interactions until the mean of a {protocol['eval_episodes']}-episode greedy evaluation "
        f"on the plain env (fixed seeds, the same for every method; at step 0 and every "
        f"{protocol['eval_every']:,} steps) first reaches the threshold ({thresholds}). Ours count every "
        "interaction that produced training data (dynamic-demonstration roll-outs included); SB3 runs "
        "rl-zoo3's tuned DQN in one `learn()` call per seed and counts its own `num_timesteps`. Median and "
        "95% percentile-bootstrap CI over seeds, a seed that never reaches the threshold counted as ∞; the "
        f"ratio's CI resamples each side's seeds independently ({RESAMPLES:,} resamples). *Above it at the "
        "end*: the final evaluation (ours: eval.json after the run; SB3: the last grid point). *Independent "
        "check*: SB3's median from a separate check of the same baseline; *published*: rl-zoo3's benchmark "
        "(one run, final evaluation after its budget).",
        "",
        *table(arms),
        *(
            [
                "",
                "Against the imperfect teacher (docs/PREREGISTRATION.md §7; final evaluation: eval.json, 20 episodes):",
                "",
                *teacher_table(arms),
            ]
            if teacher_table(arms)
            else []
        ),
    ]
