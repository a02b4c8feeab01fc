"""Statistics over seeds: robust averages, bootstrap intervals, significance and equivalence.

The paper shows single runs; issue D compares arms over many seeds the way rliable
(Agarwal et al. 2021) recommends: a point estimate (mean, and the interquartile mean, which a
few outlying seeds cannot drag), a 95% percentile-bootstrap interval, a two-sided test of the
difference (Mann–Whitney U for values, Fisher's exact test for proportions) and, for a claim of
"no difference", equivalence within a margin stated in advance (two one-sided tests by the
interval: the whole interval of the difference lies inside ±margin).

Every function is pure: the same inputs (and seed) give the same numbers.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats as sps

Statistic = Callable[..., float]


def iqm(x: Sequence[float], axis: int | None = None) -> float | np.ndarray:
    """Interquartile mean: the mean of the middle 50% (25% trimmed from each side).

    rliable's definition (`scipy.stats.trim_mean(x, 0.25)`): as robust as the median to a
    few failed or lucky seeds, yet it averages half the data rather than one value.
    """
    return sps.trim_mean(np.asarray(x, dtype=float), 0.25, axis=axis)


def _as_sample(x: Sequence[float]) -> np.ndarray:
    sample = np.asarray(x, dtype=float).reshape(-1)
    if sample.size == 0:
        raise ValueError("a statistic over seeds needs at least one value, got none")
    return sample


def _resampled(statistic: Statistic, sample: np.ndarray, rng: np.random.Generator, resamples: int) -> np.ndarray:
    """`statistic` of `resamples` bootstrap resamples (rows of `sample` drawn with replacement)."""
    rows = sample[rng.integers(0, sample.size, size=(resamples, sample.size))]
    try:
        return np.asarray(statistic(rows, axis=1), dtype=float)  # numpy-style statistics: vectorised
    except TypeError:
        return np.array([statistic(row) for row in rows], dtype=float)


def _percentiles(values: np.ndarray, level: float) -> tuple[float, float]:
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1), got {level}")
    tail = 100.0 * (1.0 - level) / 2.0
    # Censored samples (inf: "never reached") have no interpolation between values: take order statistics.
    method = "linear" if np.isfinite(values).all() else "inverted_cdf"
    low, high = np.percentile(values, [tail, 100.0 - tail], method=method)
    return float(low), float(high)


def bootstrap_ci(
    x: Sequence[float], statistic: Statistic = np.mean, level: float = 0.95, resamples: int = 10_000, seed: int = 0,
) -> tuple[float, float]:
    """Percentile-bootstrap confidence interval of `statistic(x)`.

    Resample the seeds with replacement `resamples` times and take the central `level` of the
    statistic's values. No normality assumption (returns over seeds are often bimodal: solved
    or not); a fixed-seed generator makes reports reproducible. A constant sample gives the
    single point (c, c).
    """
    sample = _as_sample(x)
    return _percentiles(_resampled(statistic, sample, np.random.default_rng(seed), resamples), level)


def bootstrap_diff_ci(
    a: Sequence[float], b: Sequence[float], statistic: Statistic = np.mean, level: float = 0.95,
    resamples: int = 10_000, seed: int = 0,
) -> tuple[float, float]:
    """Percentile-bootstrap confidence interval of `statistic(a) − statistic(b)`.

    The two arms are independent sets of seeds, so each is resampled on its own.
    """
    rng = np.random.default_rng(seed)
    first = _resampled(statistic, _as_sample(a), rng, resamples)
    second = _resampled(statistic, _as_sample(b), rng, resamples)
    return _percentiles(first - second, level)


def mann_whitney(a: Sequence[float], b: Sequence[float]) -> tuple[float, float]:
    """Two-sided Mann–Whitney U test: (U of `a`, p).

    U counts the pairs (a_i, b_j) with a_i > b_j, ties counting ½. A rank test: it needs no
    normality and is insensitive to outlying seeds. scipy's `method="auto"` gives the exact
    p-value for small samples without ties, else the normal approximation with tie and
    continuity corrections. Two samples of one and the same value give p = 1.
    """
    result = sps.mannwhitneyu(_as_sample(a), _as_sample(b), alternative="two-sided", method="auto")
    return float(result.statistic), float(result.pvalue)


def fisher_exact(successes_a: int, n_a: int, successes_b: int, n_b: int) -> tuple[float, float]:
    """Two-sided Fisher's exact test of two proportions: (odds ratio, p).

    The table is [[successes_a, n_a − successes_a], [successes_b, n_b − successes_b]]. Exact,
    so valid for the handful of runs per arm a proportion such as "runs that never finish" has.
    """
    if not (0 <= successes_a <= n_a and 0 <= successes_b <= n_b):
        raise ValueError(f"need 0 ≤ successes ≤ n, got {successes_a}/{n_a} and {successes_b}/{n_b}")
    result = sps.fisher_exact([[successes_a, n_a - successes_a], [successes_b, n_b - successes_b]],
                              alternative="two-sided")
    return float(result.statistic), float(result.pvalue)


def equivalent(diff_ci: tuple[float, float], margin: float) -> bool:
    """Equivalence by the interval (TOST): the whole CI of the difference lies within ±margin.

    "Not significantly different" is no evidence of sameness (few seeds make any p large);
    a difference whose plausible values are all smaller than a margin fixed in advance is.
    """
    low, high = diff_ci
    return -margin <= low and high <= margin


def excludes_zero(diff_ci: tuple[float, float]) -> bool:
    """The CI of a difference lies entirely on one side of 0: a significant difference."""
    low, high = diff_ci
    return low > 0 or high < 0


@dataclass(frozen=True)
class Summary:
    """One arm's metric over seeds: how many, mean, IQM and the mean's 95% bootstrap CI."""

    n: int
    mean: float
    iqm: float
    ci_low: float
    ci_high: float

    @classmethod
    def of(cls, x: Sequence[float], level: float = 0.95, resamples: int = 10_000, seed: int = 0) -> Summary:
        sample = _as_sample(x)
        low, high = bootstrap_ci(sample, np.mean, level, resamples, seed)
        return cls(int(sample.size), float(sample.mean()), float(iqm(sample)), low, high)

    def format(self, digits: int = 1) -> str:
        """`mean [low, high] (IQM x)` for a table cell."""
        return (f"{self.mean:.{digits}f} [{self.ci_low:.{digits}f}, {self.ci_high:.{digits}f}] "
                f"(IQM {self.iqm:.{digits}f})")
