"""Statistics over seeds: robust averages, bootstrap intervals, significance and equivalence.

The paper shows single runs; the lab compares arms over many seeds the way rliable
(Agarwal et al. 2021) recommends: a point estimate (mean, and the interquartile mean, which a
few outlying seeds cannot drag), a 95% percentile-bootstrap interval, a two-sided test of the
difference (Mann–Whitney U for values, Fisher's exact test for proportions) and, for a claim of
"no difference", equivalence within a margin stated in advance: two one-sided tests (TOST) at
α, i.e. the (1 − 2α) interval of the difference (90% at α = 0.05) lies inside ±margin.
Seeds per arm come from the power of that test (power.py).

Every function is pure: the same inputs (and seed) give the same numbers.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy import stats as sps

Statistic = Callable[..., float | np.ndarray]
"""A statistic over a sample (np.mean, iqm): one value, or one per row with `axis=1`."""
Values = Sequence[float] | np.ndarray
"""A metric's values over seeds, as a list or an array."""


def iqm(x: Values, axis: int | None = None) -> float | np.ndarray:
    """Interquartile mean: the mean of the middle 50% (25% trimmed from each side).

    rliable's definition (`scipy.stats.trim_mean(x, 0.25)`): as robust as the median to a
    few failed or lucky seeds, yet it averages half the data rather than one value.
    """
    return sps.trim_mean(np.asarray(x, dtype=float), 0.25, axis=axis)


def as_sample(x: Values) -> np.ndarray:
    """`x` as a flat float array; ValueError if it is empty (no statistic over no seeds)."""
    sample = np.asarray(x, dtype=float).reshape(-1)
    if sample.size == 0:
        raise ValueError("a statistic over seeds needs at least one value, got none")
    return sample


def _resampled(statistic: Statistic, sample: np.ndarray, rng: np.random.Generator, resamples: int) -> np.ndarray:
    """`statistic` of `resamples` bootstrap resamples (rows of `sample` drawn with replacement)."""
    return _per_row(statistic, sample[rng.integers(0, sample.size, size=(resamples, sample.size))])


def _per_row(statistic: Statistic, rows: np.ndarray) -> np.ndarray:
    """`statistic` of each row of `rows`: all at once for numpy-style statistics (`axis=1`), else row by row."""
    try:
        return np.asarray(statistic(rows, axis=1), dtype=float)
    except TypeError:
        return np.array([np.asarray(statistic(row), dtype=float) for row in rows])


def _stratified_resampled(statistic: Statistic, matrix: np.ndarray, rng: np.random.Generator, resamples: int):
    """`statistic` of `resamples` stratified resamples of a (runs, tasks) matrix: each task's runs drawn
    with replacement on their own, every task kept, each resample flattened to runs × tasks scores."""
    runs, tasks = matrix.shape
    rows = rng.integers(0, runs, size=(resamples, runs, tasks))
    return _per_row(statistic, matrix[rows, np.arange(tasks)].reshape(resamples, runs * tasks))


def _percentiles(values: np.ndarray, level: float) -> tuple[float, float]:
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1), got {level}")
    tail = 100.0 * (1.0 - level) / 2.0
    # Censored samples (inf: "never reached") have no interpolation between values: take order statistics.
    method: Literal["linear", "inverted_cdf"] = "linear" if np.isfinite(values).all() else "inverted_cdf"
    low, high = np.percentile(values, [tail, 100.0 - tail], method=method)
    return float(low), float(high)


def bootstrap_ci(
    x: Values,
    statistic: Statistic = np.mean,
    level: float = 0.95,
    resamples: int = 10_000,
    seed: int = 0,
) -> tuple[float, float]:
    """Percentile-bootstrap confidence interval of `statistic(x)`.

    Resample the seeds with replacement `resamples` times and take the central `level` of the
    statistic's values. No normality assumption (returns over seeds are often bimodal: solved
    or not); a fixed-seed generator makes reports reproducible. A constant sample gives the
    single point (c, c).
    """
    sample = as_sample(x)
    return _percentiles(_resampled(statistic, sample, np.random.default_rng(seed), resamples), level)


def bootstrap_diff_ci(
    a: Values,
    b: Values,
    statistic: Statistic = np.mean,
    level: float = 0.95,
    resamples: int = 10_000,
    seed: int = 0,
) -> tuple[float, float]:
    """Percentile-bootstrap confidence interval of `statistic(a) − statistic(b)`.

    The two arms are independent sets of seeds, so each is resampled on its own.
    """
    rng = np.random.default_rng(seed)
    first = _resampled(statistic, as_sample(a), rng, resamples)
    second = _resampled(statistic, as_sample(b), rng, resamples)
    return _percentiles(first - second, level)


def stratified_bootstrap_ci(
    scores: np.ndarray,
    statistic: Statistic = iqm,
    level: float = 0.95,
    resamples: int = 10_000,
    seed: int = 0,
) -> tuple[float, float] | np.ndarray:
    """Percentile-bootstrap interval of `statistic` over a (runs, tasks) matrix of scores, resampling
    the runs of each task on their own (rliable's `StratifiedBootstrap`, tasks fixed).

    Across games the seeds of a game are exchangeable but the games are not: a resample keeps
    every game and draws its runs with replacement. `statistic(matrix, axis=None)`-style
    statistics take the flattened (runs × tasks) scores of one resample (with `axis=1`, all at
    once); one returning a vector per resample (a performance profile) gives a (2, len) array of
    lows and highs.
    """
    matrix = np.asarray(scores, dtype=float)
    if matrix.ndim != 2 or matrix.size == 0:
        raise ValueError(f"a stratified bootstrap takes a non-empty (runs, tasks) matrix, got shape {matrix.shape}")
    values = _stratified_resampled(statistic, matrix, np.random.default_rng(seed), resamples)
    if values.ndim == 1:
        return _percentiles(values, level)
    return np.array([_percentiles(column, level) for column in values.T]).T


def stratified_bootstrap_diff_ci(
    a: np.ndarray,
    b: np.ndarray,
    statistic: Statistic = iqm,
    level: float = 0.95,
    resamples: int = 10_000,
    seed: int = 0,
) -> tuple[float, float]:
    """Percentile-bootstrap interval of `statistic(a) − statistic(b)` for two (runs, tasks) matrices of
    independent runs on the same tasks: each matrix's runs resampled within each task on its own."""
    first, second = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if first.ndim != 2 or second.ndim != 2 or first.shape[1] != second.shape[1] or 0 in first.shape + second.shape:
        raise ValueError(
            f"two non-empty (runs, tasks) matrices on the same tasks, got shapes {first.shape}, {second.shape}"
        )
    rng = np.random.default_rng(seed)
    differences = _stratified_resampled(statistic, first, rng, resamples) - _stratified_resampled(
        statistic, second, rng, resamples
    )
    return _percentiles(differences, level)


def score_distribution(scores: np.ndarray, taus: Sequence[float], axis: int | None = None) -> np.ndarray:
    """A performance profile (rliable's `score_distributions`): for each τ, the share of all runs of
    all tasks whose score is above τ (strictly). With `axis=1`, one profile per row."""
    values = np.asarray(scores, dtype=float)
    thresholds = np.asarray(taus, dtype=float)
    if axis is None:
        return (values.reshape(-1, 1) > thresholds).mean(axis=0)
    return (np.moveaxis(values, axis, -1)[..., None] > thresholds).mean(axis=-2)


def mann_whitney(a: Values, b: Values) -> tuple[float, float]:
    """Two-sided Mann–Whitney U test: (U of `a`, p).

    U counts the pairs (a_i, b_j) with a_i > b_j, ties counting ½. A rank test: it needs no
    normality and is insensitive to outlying seeds. scipy's `method="auto"` gives the exact
    p-value for small samples without ties, else the normal approximation with tie and
    continuity corrections. Two samples of one and the same value give p = 1.
    """
    result = sps.mannwhitneyu(as_sample(a), as_sample(b), alternative="two-sided", method="auto")
    return float(result.statistic), float(result.pvalue)


def holm(p: Sequence[float], family: int | None = None) -> list[float]:
    """Holm–Bonferroni adjusted p-values, in the order given: the k-th smallest is multiplied by
    m − k + 1, then made monotone and capped at 1 (Holm 1979). `family` (≥ len(p)) is m, the
    pre-registered number of comparisons: those not yet run count as p = 1, so a partial study is
    adjusted as strictly as the whole one."""
    m = len(p) if family is None else family
    if m < len(p):
        raise ValueError(f"a family of {m} comparisons cannot hold {len(p)}")
    adjusted, running = [1.0] * len(p), 0.0
    for rank, i in enumerate(np.argsort(np.asarray(p, dtype=float), kind="stable")):
        running = max(running, (m - rank) * float(p[i]))
        adjusted[i] = min(1.0, running)
    return adjusted


def fisher_exact(successes_a: int, n_a: int, successes_b: int, n_b: int) -> tuple[float, float]:
    """Two-sided Fisher's exact test of two proportions: (odds ratio, p).

    The table is [[successes_a, n_a − successes_a], [successes_b, n_b − successes_b]]. Exact,
    so valid for the handful of runs per arm a proportion such as "runs that never finish" has.
    """
    if not (0 <= successes_a <= n_a and 0 <= successes_b <= n_b):
        raise ValueError(f"need 0 ≤ successes ≤ n, got {successes_a}/{n_a} and {successes_b}/{n_b}")
    result = sps.fisher_exact(
        [[successes_a, n_a - successes_a], [successes_b, n_b - successes_b]], alternative="two-sided"
    )
    return float(result.statistic), float(result.pvalue)


def tost_ci(
    a: Values,
    b: Values,
    alpha: float = 0.05,
    resamples: int = 10_000,
    seed: int = 0,
) -> tuple[float, float]:
    """The (1 − 2α) percentile-bootstrap CI of mean(a) − mean(b): TOST's interval.

    Each of its ends is a one-sided bound at α, so "the whole interval inside ±margin" is both
    one-sided tests rejecting at α: a TOST at α = 0.05 reads the 90% interval, not the 95% one.
    """
    if not 0.0 < alpha < 0.5:
        raise ValueError(f"alpha must be in (0, 0.5), got {alpha}")
    return bootstrap_diff_ci(a, b, np.mean, 1.0 - 2.0 * alpha, resamples, seed)


def equivalent(diff_ci: tuple[float, float], margin: float) -> bool:
    """Equivalence by the interval: the whole `diff_ci` lies within ±margin (TOST when it is `tost_ci`).

    "Not significantly different" is no evidence of sameness (few seeds make any p large);
    a difference whose plausible values are all smaller than a margin fixed in advance is.
    """
    low, high = diff_ci
    return -margin <= low and high <= margin


def beyond(diff_ci: tuple[float, float], margin: float) -> bool:
    """The whole `diff_ci` lies outside ±margin: a difference larger than the margin is shown
    (at α one-sided when it is `tost_ci`), the counterpart of `equivalent`."""
    low, high = diff_ci
    return low > margin or high < -margin


@dataclass(frozen=True)
class Summary:
    """One arm's metric over seeds: how many, mean, IQM and the mean's 95% bootstrap CI."""

    n: int
    mean: float
    iqm: float
    ci_low: float
    ci_high: float

    @classmethod
    def of(cls, x: Values, level: float = 0.95, resamples: int = 10_000, seed: int = 0) -> Summary:
        sample = as_sample(x)
        low, high = bootstrap_ci(sample, np.mean, level, resamples, seed)
        return cls(int(sample.size), float(sample.mean()), float(iqm(sample)), low, high)

    def format(self, digits: int = 1) -> str:
        """`mean [low, high] (IQM x)` for a table cell."""
        return (
            f"{self.mean:.{digits}f} [{self.ci_low:.{digits}f}, {self.ci_high:.{digits}f}] (IQM {self.iqm:.{digits}f})"
        )


@dataclass(frozen=True)
class CensoredSummary:
    """One arm's censored metric over seeds (inf: the event never happened): the median and its
    95% bootstrap CI by order statistics. A mean over inf is undefined; a median is not, and a
    censored seed ranks after every finished one by construction."""

    n: int
    median: float
    ci_low: float
    ci_high: float
    censored: int

    @classmethod
    def of(cls, x: Values, level: float = 0.95, resamples: int = 10_000, seed: int = 0) -> CensoredSummary:
        sample = as_sample(x)
        low, high = bootstrap_ci(sample, np.median, level, resamples, seed)
        return cls(int(sample.size), float(np.median(sample)), low, high, int(np.sum(np.isinf(sample))))

    def format(self, digits: int = 1) -> str:
        """`median x [low, high] (k of n censored)` for a table cell, ∞ for inf."""

        def number(value: float) -> str:
            return "∞" if np.isinf(value) else f"{value:.{digits}f}"

        return (
            f"median {number(self.median)} [{number(self.ci_low)}, {number(self.ci_high)}] "
            f"({self.censored} of {self.n} censored)"
        )
