"""Figures over seeds for RESULTS.md (matplotlib, drawn off-screen, written atomically).

`learning_curves` is the analogue of the paper's Figs. 3–7 and 9–11 with many seeds;
`case_runs` is the paper's own kind of picture: one best, one average and one worst run per arm.
Every figure names its seed counts, and the same data give the same PNG bytes: a fixed font,
size and dpi, and no software version in the file.
"""

from __future__ import annotations

import contextlib
import dataclasses
import itertools
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from dqfd_bc_keras.files import atomic_path

if TYPE_CHECKING:
    from matplotlib.typing import RcKeyType

STYLE: dict[RcKeyType, Any] = {"font.family": "DejaVu Sans", "font.size": 10, "savefig.dpi": 100}
"""DejaVu Sans ships with matplotlib, so the text is drawn the same wherever the report runs."""


@dataclass(frozen=True)
class Trace:
    """A run as drawn: its label (`seed 3`), its per-episode series (unsmoothed), the score that
    ranks it among its arm's runs, and whether it stopped early (solved) rather than at its budget."""

    label: str
    curve: np.ndarray
    score: float
    stopped: bool = False


@contextlib.contextmanager
def _figure(path: Path, **subplots) -> Iterator:
    """A figure drawn in STYLE and saved to `path` (atomically) when the block ends."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    with matplotlib.rc_context(STYLE):
        fig, axes = plt.subplots(**subplots)
        try:
            yield fig, axes
            fig.tight_layout()
            with atomic_path(path) as tmp:
                fig.savefig(tmp, metadata={"Software": None})
        finally:
            plt.close(fig)


def _colors() -> Iterator:
    import matplotlib

    return itertools.cycle(matplotlib.color_sequences["tab10"])


def seeds_text(counts: list[int]) -> str:
    """`10 seeds` or `3–5 seeds`: how many runs an arm of the figure has."""
    low, high = min(counts), max(counts)
    return f"{low} seed{'s' * (high > 1)}" if low == high else f"{low}–{high} seeds"


def mean_band(
    curves: list[np.ndarray], level: float = 0.95, resamples: int = 1_000, seed: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per episode: the mean over the runs that have it, its percentile-bootstrap band, and how
    many runs have it.

    A bootstrap resample of the runs is a vector of counts (how often each run was drawn), so
    every resample's per-episode mean is one matrix product: Σ_j w_j·x_je / Σ_j w_j·[run j
    reached episode e]. Episodes that no drawn run reached do not count for the band.
    """
    length = max(len(c) for c in curves)
    values = np.zeros((len(curves), length))
    present = np.zeros((len(curves), length))
    for j, curve in enumerate(curves):
        values[j, : len(curve)], present[j, : len(curve)] = curve, 1.0
    mean = values.sum(axis=0) / present.sum(axis=0)
    rng = np.random.default_rng(seed)
    weights = np.stack(
        [np.bincount(rng.integers(0, len(curves), len(curves)), minlength=len(curves)) for _ in range(resamples)]
    ).astype(float)
    sums, counts = weights @ values, weights @ present
    boot = np.divide(sums, counts, out=np.full_like(sums, np.nan), where=counts > 0)
    tail = 100.0 * (1.0 - level) / 2.0
    low, high = np.nanpercentile(boot, [tail, 100.0 - tail], axis=0)
    return mean, low, high, present.sum(axis=0)


def trailing_mean(curve: np.ndarray, window: int) -> np.ndarray:
    """Entry e: the mean of the last `window` entries up to e (fewer at the start)."""
    sums = np.cumsum(np.concatenate([[0.0], curve]))
    ends = np.arange(1, len(curve) + 1)
    starts = np.maximum(ends - window, 0)
    return (sums[ends] - sums[starts]) / (ends - starts)


def held(trace: Trace, window: int, length: int) -> np.ndarray:
    """The trace as a learning curve drawn over `length` episodes: its trailing mean of `window`
    episodes and, if it stopped early, that curve's last value held to the end. Without the hold
    the mean over seeds would lose each run as it solves and show the slow seeds only."""
    curve = trailing_mean(trace.curve, window)
    return np.pad(curve, (0, length - len(curve)), mode="edge") if trace.stopped else curve


def _draw_mean(ax, arms: dict[str, list[Trace]], window: int, length: int) -> None:
    """Each arm's mean over seeds with its 95% band; dotted, without band, once fewer than half its
    runs reach the episode (runs that ended at their budget, not stopped early, drop out)."""
    for color, (name, traces) in zip(_colors(), arms.items(), strict=False):
        mean, low, high, running = mean_band([held(t, window, length) for t in traces])
        episodes = np.arange(1, len(mean) + 1)
        most = running >= len(traces) / 2  # a prefix: runs only ever drop out
        ax.plot(episodes[most], mean[most], color=color, lw=1.5, label=f"{name} ({seeds_text([len(traces)])})")
        ax.fill_between(episodes[most], low[most], high[most], color=color, alpha=0.2, lw=0)
        tail = max(int(most.sum()) - 1, 0)
        ax.plot(episodes[tail:], mean[tail:], color=color, lw=0.8, ls=":")
    ax.set_xlabel("training episode")
    ax.legend(loc="best", fontsize=8)


def learning_curves(
    title: str, arms: dict[str, list[Trace]], ylabel: str, path: Path, window: int = 1, zoom: int | None = None
) -> None:
    """Each arm's mean per-episode curve over seeds with its 95% bootstrap band.

    `window` > 1 draws trailing means (said on the axis); `zoom` adds a panel of the first `zoom`
    episodes, unsmoothed, beside the full curve (where a claim is about early training).
    """
    traces = [t for runs in arms.values() for t in runs]
    length = max(len(t.curve) for t in traces)
    notes = [f"mean over seeds ({seeds_text([len(r) for r in arms.values()])} per arm), 95% bootstrap band"]
    if any(t.stopped for t in traces):
        notes.append(
            f"a run stopped early (solved) holds its {'last value' if window == 1 else 'last trailing mean'} "
            f"to episode {length}, so every seed counts at every episode"
        )
    if any(not t.stopped and len(t.curve) < length for t in traces):
        notes.append("dotted: fewer than half the seeds ran that long")
    smoothed = ylabel + (f"\n(trailing mean of {window} episodes)" if window > 1 else "")
    with _figure(
        path,
        ncols=2 if zoom else 1,
        figsize=(12 if zoom else 8, 4.5),
        squeeze=False,
        gridspec_kw={"width_ratios": [2, 1]} if zoom else None,
    ) as (fig, axes):
        _draw_mean(axes[0][0], arms, window, length)
        axes[0][0].set_ylabel(smoothed)
        if zoom:
            early = {name: [dataclasses.replace(t, curve=t.curve[:zoom]) for t in runs] for name, runs in arms.items()}
            _draw_mean(axes[0][1], early, 1, min(zoom, length))
            axes[0][1].set_title(f"first {zoom} episodes, unsmoothed", fontsize=9)
            axes[0][1].set_ylabel(ylabel)
        fig.suptitle(f"{title}: " + "\n".join(notes), fontsize=10)


def pick_cases(runs: list[Trace]) -> dict[str, Trace]:
    """The paper's three cases: best (highest score), average (closest to the median), worst."""
    scores = np.array([t.score for t in runs])
    return {
        "best": runs[int(np.argmax(scores))],
        "average": runs[int(np.argmin(np.abs(scores - np.median(scores))))],
        "worst": runs[int(np.argmin(scores))],
    }


def case_runs(title: str, cases: dict[str, dict[str, Trace]], seeds: dict[str, int], ylabel: str, path: Path) -> None:
    """The paper's picture: per case (best, average, worst) one panel with one run of each arm,
    unsmoothed as the paper draws them. `cases[case][arm]` is the run drawn, picked among the
    `seeds[arm]` runs of that arm."""
    with _figure(path, ncols=len(cases), figsize=(5 * len(cases), 4), sharey=True, squeeze=False) as (fig, axes):
        for ax, (case, runs) in zip(axes[0], cases.items(), strict=True):
            for color, (arm, trace) in zip(_colors(), runs.items(), strict=False):
                ax.plot(
                    np.arange(1, len(trace.curve) + 1),
                    trace.curve,
                    color=color,
                    lw=1,
                    label=f"{arm} ({trace.label} of {seeds[arm]})",
                )
            ax.set_title(f"{case} run")
            ax.set_xlabel("training episode")
            ax.legend(loc="best", fontsize=7)
        axes[0][0].set_ylabel(f"{ylabel}\n(unsmoothed)")
        fig.suptitle(f"{title} ({seeds_text(list(seeds.values()))} per arm)")


def setting_figures(
    setting: str,
    arms: dict[str, list[Trace]],
    case_arms: list[str],
    score: str,
    ylabel: str,
    stem: Path,
    window: int = 1,
    zoom: int | None = None,
) -> list[Path]:
    """A setting's two figures, `<stem>-curves.png` (every arm of `arms`) and `<stem>-cases.png`
    (the arms `case_arms`, runs ranked by `score`); returns their paths."""
    curves, cases = stem.with_name(f"{stem.name}-curves.png"), stem.with_name(f"{stem.name}-cases.png")
    learning_curves(setting, arms, ylabel, curves, window, zoom)
    picked = {name: pick_cases(arms[name]) for name in case_arms}
    case_runs(
        f"{setting}: best, average and worst run by {score}",
        {case: {name: picked[name][case] for name in case_arms} for case in ("best", "average", "worst")},
        {name: len(arms[name]) for name in case_arms},
        ylabel,
        cases,
    )
    return [curves, cases]


@dataclass(frozen=True)
class Heatmap:
    """A table drawn as coloured squares: `shown` gives the colours, `values` the number written in
    each square by `text` (∞: never; nan: —)."""

    rows: list[str]
    columns: list[str]
    values: np.ndarray
    shown: np.ndarray
    text: Callable[[float], str]
    title: str


def heatmap(table: Heatmap, colors: dict, label: str, path: Path) -> None:
    """`table` drawn with the colour map `colors` (imshow's arguments), its colour bar labelled `label`."""
    with _figure(path, figsize=(1.1 * len(table.columns) + 3, 0.55 * len(table.rows) + 2)) as (fig, ax):
        fig.colorbar(ax.imshow(table.shown, aspect="auto", **colors), ax=ax, label=label)
        for i, j in np.ndindex(table.values.shape):
            v = float(table.values[i, j])
            ax.text(
                j,
                i,
                table.text(v) if np.isfinite(v) else "never" if v == np.inf else "—",
                ha="center",
                va="center",
                fontsize=7,
            )
        ax.set_xticks(range(len(table.columns)), table.columns, fontsize=7)
        ax.set_yticks(range(len(table.rows)), table.rows, fontsize=8)
        ax.set_title(table.title)
