"""The statistics helpers against values computed by hand or taken from textbooks."""

import math

import numpy as np
import pytest
from dqfd_bc_keras.experiments.stats import (Summary, bootstrap_ci, bootstrap_diff_ci, equivalent, excludes_zero, fisher_exact,
                                 iqm, mann_whitney)

SAMPLE = np.arange(1.0, 11.0)  # 1..10: mean 5.5, population std √8.25


def test_iqm_is_the_mean_of_the_middle_half():
    # 1..8: drop 1, 2 and 7, 8; (3 + 4 + 5 + 6) / 4 = 4.5
    assert iqm(np.arange(1, 9)) == pytest.approx(4.5)
    assert iqm([1, 2, 3, 4, 5, 6, 7, 1000]) == pytest.approx(4.5)  # an outlying seed does not move it
    assert iqm(np.arange(1, 11)) == pytest.approx(5.5)  # 10 values: 2 trimmed each side, mean of 3..8


def test_bootstrap_ci_contains_the_mean_and_matches_the_normal_approximation():
    low, high = bootstrap_ci(SAMPLE, seed=0)
    assert low < 5.5 < high
    # the bootstrap's standard error of the mean is the plug-in σ/√n = √8.25/√10 ≈ 0.908
    half = 1.96 * math.sqrt(8.25 / 10)
    assert low == pytest.approx(5.5 - half, abs=0.15) and high == pytest.approx(5.5 + half, abs=0.15)


def test_bootstrap_ci_is_deterministic_for_a_seed():
    x = np.sqrt(SAMPLE)  # off the 0.1 lattice that means of 10 integers fall on
    assert bootstrap_ci(x, seed=3) == bootstrap_ci(x, seed=3)
    assert bootstrap_ci(x, seed=3) != bootstrap_ci(x, seed=4)


def test_bootstrap_ci_narrows_with_more_seeds():
    low, high = bootstrap_ci(SAMPLE)
    low4, high4 = bootstrap_ci(np.tile(SAMPLE, 4))  # same spread, 4× the seeds: about half as wide
    assert (high4 - low4) == pytest.approx((high - low) / 2, rel=0.1)


def test_bootstrap_ci_of_a_constant_sample_is_a_point():
    assert bootstrap_ci([7.0, 7.0, 7.0]) == (7.0, 7.0)
    assert bootstrap_ci([7.0]) == (7.0, 7.0)


def test_bootstrap_ci_takes_statistics_with_or_without_an_axis_argument():
    vectorised = bootstrap_ci(SAMPLE, statistic=np.median, resamples=500)
    one_by_one = bootstrap_ci(SAMPLE, statistic=lambda x: float(np.median(x)), resamples=500)
    assert vectorised == one_by_one  # the same resamples either way
    low, high = bootstrap_ci(SAMPLE, statistic=iqm)
    assert low < iqm(SAMPLE) < high


def test_bootstrap_ci_rejects_bad_input():
    with pytest.raises(ValueError, match="at least one"):
        bootstrap_ci([])
    with pytest.raises(ValueError, match="level"):
        bootstrap_ci(SAMPLE, level=1.5)


def test_bootstrap_diff_ci():
    assert bootstrap_diff_ci([5.0, 5.0, 5.0], [2.0, 2.0]) == (3.0, 3.0)
    low, high = bootstrap_diff_ci(SAMPLE + 3.0, SAMPLE)
    assert low < 3.0 < high and low > 0.0
    # independent resampling of both arms: about √2 wider than one arm's interval
    one_low, one_high = bootstrap_ci(SAMPLE)
    assert (high - low) == pytest.approx(math.sqrt(2) * (one_high - one_low), rel=0.1)


def test_mann_whitney_textbook_example_exact():
    # complete separation of 5 vs 5: U = 0; exact two-sided p = 2 / C(10, 5) = 2/252
    u, p = mann_whitney([1, 2, 3, 4, 5], [6, 7, 8, 9, 10])
    assert u == 0.0 and p == pytest.approx(2 / 252)
    u, p = mann_whitney([6, 7, 8, 9, 10], [1, 2, 3, 4, 5])
    assert u == 25.0 and p == pytest.approx(2 / 252)  # U is reported for the first sample


def test_mann_whitney_with_ties_by_hand():
    # a = [1, 2, 2], b = [2, 3, 4]: pairs a > b: none; ties 2 = 2 twice → U_a = 2 × ½ = 1.
    # Normal approximation with tie and continuity corrections: pooled ranks 1, 3, 3, 3, 5, 6
    # (one tie of size 3), μ = n1·n2/2 = 4.5, σ² = n1·n2/12 · (N + 1 − Σ(t³ − t)/(N(N − 1)))
    # = 9/12 · (7 − 24/30) = 4.65, z = (|U − μ| − ½)/σ = 3/√4.65, p = 2·(1 − Φ(z)) = erfc(z/√2).
    u, p = mann_whitney([1, 2, 2], [2, 3, 4])
    assert u == 1.0
    assert p == pytest.approx(math.erfc(3 / math.sqrt(4.65) / math.sqrt(2)))
    assert p == pytest.approx(0.16416, abs=1e-5)


def test_mann_whitney_identical_constant_samples():
    assert mann_whitney([3, 3, 3], [3, 3, 3]) == (4.5, 1.0)


def test_fisher_exact_lady_tasting_tea():
    # [[3, 1], [1, 3]]: P(k cups right) = C(4,k)·C(4,4−k)/C(8,4) = 1, 16, 36, 16, 1 over 70;
    # two-sided: the tables as or less likely than the observed one, (1 + 16 + 16 + 1)/70
    odds, p = fisher_exact(3, 4, 1, 4)
    assert odds == pytest.approx(9.0)
    assert p == pytest.approx(34 / 70) and p == pytest.approx(0.4857, abs=1e-4)
    assert fisher_exact(0, 10, 0, 10)[1] == 1.0
    assert fisher_exact(10, 10, 0, 10)[1] == pytest.approx(2 / math.comb(20, 10))
    with pytest.raises(ValueError, match="successes"):
        fisher_exact(5, 4, 0, 4)


@pytest.mark.parametrize("ci, margin, expected", [
    ((-1.0, 1.0), 2.0, True), ((-2.0, 2.0), 2.0, True), ((0.5, 1.5), 2.0, True),
    ((-3.0, 1.0), 2.0, False), ((1.0, 2.5), 2.0, False), ((-5.0, 5.0), 2.0, False),
])
def test_equivalent_means_the_whole_ci_is_inside_the_margin(ci, margin, expected):
    assert equivalent(ci, margin) is expected


def test_excludes_zero():
    assert excludes_zero((0.1, 2.0)) and excludes_zero((-2.0, -0.1))
    assert not excludes_zero((-0.1, 2.0)) and not excludes_zero((0.0, 1.0))


def test_summary():
    s = Summary.of(SAMPLE)
    assert (s.n, s.mean, s.iqm) == (10, 5.5, 5.5)
    assert (s.ci_low, s.ci_high) == bootstrap_ci(SAMPLE)
    assert Summary.of([2.0, 2.0]).format() == "2.0 [2.0, 2.0] (IQM 2.0)"
    assert Summary.of([1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 100.0]).format().endswith("(IQM 4.5)")  # mean of 3…6


def test_bootstrap_ci_of_a_censored_median_uses_order_statistics():
    """Seeds that never reach a threshold count as inf: the CI stays defined, its end inf once
    resamples with a majority of them are likely."""
    steps = [1000.0, 2000.0, 3000.0, np.inf, np.inf, 4000.0, 2000.0, 1000.0, 1000.0, 5000.0]
    low, high = bootstrap_ci(steps, np.median)
    assert low == 1000.0 and high == np.inf
    low, high = bootstrap_ci([1000.0, 2000.0, 3000.0, 4000.0] * 3 + [np.inf], np.median)
    assert {low, high} <= {1000.0, 2000.0, 3000.0, 4000.0} and low < high  # one inf in 13: order statistics
