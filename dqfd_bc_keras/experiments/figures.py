"""Figures over seeds for RESULTS.md (matplotlib, drawn off-screen, written atomically).

`learning_curves` is the analogue of the paper's Figs. 3–7 and 9–11 with many seeds;
`case_runs` is the paper's own kind of picture: one best, one average and one worst run per arm.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np

from ..files import atomic_path

Curves = list[np.ndarray]
"""One per-episode series per run; runs differ in length (CartPole stops early)."""
Trace = tuple[str, np.ndarray, float]
"""A run as drawn: its label (`seed 3`), its per-episode series and the score that ranks it."""


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path) -> None:
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=100)
    _pyplot().close(fig)


def mean_band(curves: Curves, level: float = 0.95, resamples: int = 1_000, seed: int = 0
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per episode: the mean over the runs still going, its percentile-bootstrap band, and how
    many runs are still going.

    A bootstrap resample of the runs is a vector of counts (how often each run was drawn), so
    every resample's per-episode mean is one matrix product: Σ_j w_j·x_je / Σ_j w_j·[run j
    reached episode e]. Episodes that no drawn run reached do not count for the band.
    """
    length = max(len(c) for c in curves)
    values = np.zeros((len(curves), length))
    present = np.zeros((len(curves), length))
    for j, curve in enumerate(curves):
        values[j, :len(curve)], present[j, :len(curve)] = curve, 1.0
    mean = values.sum(axis=0) / present.sum(axis=0)
    rng = np.random.default_rng(seed)
    weights = np.stack([np.bincount(rng.integers(0, len(curves), len(curves)), minlength=len(curves))
                        for _ in range(resamples)]).astype(float)
    sums, counts = weights @ values, weights @ present
    boot = np.divide(sums, counts, out=np.full_like(sums, np.nan), where=counts > 0)
    tail = 100.0 * (1.0 - level) / 2.0
    low, high = np.nanpercentile(boot, [tail, 100.0 - tail], axis=0)
    return mean, low, high, present.sum(axis=0)


def learning_curves(title: str, arms: dict[str, Curves], ylabel: str, path: Path) -> None:
    """Each arm's mean per-episode curve over seeds with its 95% bootstrap band.

    Runs stop at different episodes (CartPole's early stop) and the mean at episode e is over the
    runs that reached e: once fewer than half the runs are still going, it shows the slowest
    seeds only, so from there the mean is drawn dotted and without a band.
    """
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for color, (name, curves) in zip(itertools.cycle(plt.cm.tab10.colors), arms.items()):
        mean, low, high, running = mean_band(curves)
        episodes = np.arange(1, len(mean) + 1)
        most = running >= len(curves) / 2  # a prefix: runs only ever stop
        ax.plot(episodes[most], mean[most], color=color, lw=1.5, label=f"{name} ({len(curves)} seeds)")
        ax.fill_between(episodes[most], low[most], high[most], color=color, alpha=0.2, lw=0)
        tail = max(int(most.sum()) - 1, 0)
        ax.plot(episodes[tail:], mean[tail:], color=color, lw=0.8, ls=":")
    ax.set_xlabel("training episode")
    ax.set_ylabel(ylabel)
    ax.set_title(f"{title}: mean over seeds, 95% bootstrap band\n(dotted: fewer than half the seeds still running)",
                 fontsize=10)
    ax.legend(loc="best", fontsize=8)
    _save(fig, path)


def trailing_mean(curve: np.ndarray, window: int) -> np.ndarray:
    """Entry e: the mean of the last `window` entries up to e (fewer at the start)."""
    sums = np.cumsum(np.concatenate([[0.0], curve]))
    ends = np.arange(1, len(curve) + 1)
    starts = np.maximum(ends - window, 0)
    return (sums[ends] - sums[starts]) / (ends - starts)


def pick_cases(runs: list[Trace]) -> dict[str, Trace]:
    """The paper's three cases: best (highest score), average (closest to the median), worst."""
    scores = np.array([score for _, _, score in runs])
    return {"best": runs[int(np.argmax(scores))], "average": runs[int(np.argmin(np.abs(scores - np.median(scores))))],
            "worst": runs[int(np.argmin(scores))]}


def case_runs(title: str, cases: dict[str, dict[str, Trace]], ylabel: str, path: Path) -> None:
    """The paper's picture: per case (best, average, worst) one panel with one run of each arm.

    `cases[case][arm]` is the run drawn.
    """
    plt = _pyplot()
    fig, axes = plt.subplots(1, len(cases), figsize=(5 * len(cases), 4), sharey=True, squeeze=False)
    for ax, (case, runs) in zip(axes[0], cases.items()):
        for color, (arm, (run, curve, _)) in zip(itertools.cycle(plt.cm.tab10.colors), runs.items()):
            ax.plot(np.arange(1, len(curve) + 1), curve, color=color, lw=1, label=f"{arm} ({run})")
        ax.set_title(f"{case} run")
        ax.set_xlabel("training episode")
        ax.legend(loc="best", fontsize=7)
    axes[0][0].set_ylabel(ylabel)
    fig.suptitle(title)
    _save(fig, path)


def setting_figures(setting: str, arms: dict[str, list[Trace]], case_arms: list[str], score: str, ylabel: str,
                    stem: Path) -> list[Path]:
    """A setting's two figures, `<stem>-curves.png` (every arm) and `<stem>-cases.png` (the arms
    `case_arms`, runs ranked by `score`); returns their paths."""
    curves, cases = stem.with_name(f"{stem.name}-curves.png"), stem.with_name(f"{stem.name}-cases.png")
    learning_curves(setting, {name: [curve for _, curve, _ in runs] for name, runs in arms.items()}, ylabel, curves)
    picked = {name: pick_cases(arms[name]) for name in case_arms}
    case_runs(f"{setting}: single runs ranked by {score}",
              {case: {name: picked[name][case] for name in case_arms} for case in ("best", "average", "worst")},
              ylabel, cases)
    return [curves, cases]
