"""The statistics helpers against values computed by hand, taken from textbooks or from rliable."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from dqfd_bc_keras.experiments.power import (
    bound_power,
    equivalence_power,
    pooled_sd,
    sd_from_ci,
    seeds_for_bound,
    seeds_for_equivalence,
)
from dqfd_bc_keras.experiments.stats import (
    CensoredSummary,
    Summary,
    beyond,
    bootstrap_ci,
    bootstrap_diff_ci,
    equivalent,
    fisher_exact,
    iqm,
    mann_whitney,
    score_distribution,
    stratified_bootstrap_ci,
    tost_ci,
)

SAMPLE = np.arange(1.0, 11.0)  # 1..10: mean 5.5, population std √8.25
Z95, Z90, Z80 = 1.6448536, 1.2815516, 0.8416212  # z_0.95, z_0.90, z_0.80 from a normal table


def phi(x: float) -> float:
    return 0.5 * (1.0 + math.erf(x / math.sqrt(2.0)))


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


@pytest.mark.parametrize(
    "ci, margin, expected",
    [
        ((-1.0, 1.0), 2.0, True),
        ((-2.0, 2.0), 2.0, True),
        ((0.5, 1.5), 2.0, True),
        ((-3.0, 1.0), 2.0, False),
        ((1.0, 2.5), 2.0, False),
        ((-5.0, 5.0), 2.0, False),
    ],
)
def test_equivalent_means_the_whole_ci_is_inside_the_margin(ci, margin, expected):
    assert equivalent(ci, margin) is expected


@pytest.mark.parametrize(
    "ci, expected",
    [
        ((2.5, 3.0), True),
        ((-3.0, -2.5), True),
        ((1.0, 3.0), False),
        ((-1.0, 1.0), False),
        ((-3.0, 3.0), False),
        ((2.0, 3.0), False),  # touching the margin: a difference larger than it is not shown
    ],
)
def test_beyond_means_the_whole_ci_is_outside_the_margin(ci, expected):
    assert beyond(ci, 2.0) is expected


def test_tost_reads_the_90_percent_interval():
    """TOST at α = 0.05 is the 90% CI inside ±margin: here the 95% CI crosses ±2.3, the 90% CI does not."""
    assert tost_ci(SAMPLE, SAMPLE) == bootstrap_diff_ci(SAMPLE, SAMPLE, level=0.9)
    assert tost_ci(SAMPLE, SAMPLE, alpha=0.025) == bootstrap_diff_ci(SAMPLE, SAMPLE, level=0.95)
    assert equivalent(tost_ci(SAMPLE, SAMPLE), 2.3) and not equivalent(bootstrap_diff_ci(SAMPLE, SAMPLE), 2.3)
    with pytest.raises(ValueError, match="alpha"):
        tost_ci(SAMPLE, SAMPLE, alpha=0.5)


def test_spreads_by_hand():
    # [1, 3]: squares 2; [2, 4, 6]: squares 8; pooled √((2 + 8)/(2 + 3 − 2))
    assert pooled_sd([1.0, 3.0], [2.0, 4.0, 6.0]) == pytest.approx(math.sqrt(10 / 3))
    assert pooled_sd([5.0, 5.0], [5.0, 5.0]) == 0.0
    # a 95% CI of ±1.96 around the mean of 4 seeds: sd = 1.96 · √4 / 1.96 = 2
    assert sd_from_ci((-1.96, 1.96), 4) == pytest.approx(2.0, rel=1e-4)
    assert sd_from_ci((10.0, 10.0 + 2 * Z95), 9, level=0.9) == pytest.approx(3.0)
    with pytest.raises(ValueError, match="3 values"):
        pooled_sd([1.0], [2.0])


def test_seeds_for_equivalence_by_hand():
    # n = 2 (z_0.95 + z_0.90)² sd² / margin²: 2 · 2.9264052² = 17.128 → 18 for sd = margin
    assert seeds_for_equivalence(1.0, 1.0) == math.ceil(2 * (Z95 + Z90) ** 2) == 18
    assert seeds_for_equivalence(2.0, 1.0) == math.ceil(8 * (Z95 + Z90) ** 2) == 69  # 68.51: √(0.2·0.8)/0.2 = 2
    assert seeds_for_equivalence(30.0, 25.0) == math.ceil(2 * (Z95 + Z90) ** 2 * 1.44) == 25  # 24.66
    assert seeds_for_equivalence(1.0, 1.0, power=0.9) == math.ceil(2 * (Z95 + 1.6448536) ** 2) == 22
    assert seeds_for_equivalence(0.01, 1.0) == 1


def test_equivalence_power_by_hand():
    # n = 18, sd = margin = 1: the SE of Δ is √(2/18) = 1/3, power = 2Φ(3 − z_0.95) − 1
    assert equivalence_power(1.0, 1.0, 18) == pytest.approx(2 * phi(3 - Z95) - 1, abs=1e-6)
    assert equivalence_power(1.0, 1.0, 18) == pytest.approx(0.8246, abs=1e-4)
    assert equivalence_power(1.0, 1.0, 8) == pytest.approx(2 * phi(2 - Z95) - 1, abs=1e-6)  # 0.2775
    assert equivalence_power(1.0, 1.0, 4) == 0.0  # √2 < z_0.95: the 90% CI cannot fit inside ±1 on average
    assert equivalence_power(0.0, 1.0, 2) == 1.0
    for sd, margin in ((1.0, 1.0), (36.1, 25.0), (0.4, 0.2)):  # the seeds it plans reach the power, one fewer not
        n = seeds_for_equivalence(sd, margin)
        assert equivalence_power(sd, margin, n) >= 0.8 > equivalence_power(sd, margin, n - 1)


def test_one_sided_bound_by_hand():
    # n = 2 (z_0.95 + z_0.80)² sd² / distance² = 12.37 → 13; power Φ(√(13/2) − z_0.95)
    assert seeds_for_bound(1.0, 1.0) == math.ceil(2 * (Z95 + Z80) ** 2) == 13
    assert bound_power(1.0, 1.0, 13) == pytest.approx(phi(math.sqrt(6.5) - Z95), abs=1e-6)
    assert bound_power(0.08, 0.25, 10) == pytest.approx(1.0, abs=1e-6)  # C4's spread: 10 seeds are plenty
    with pytest.raises(ValueError, match="margin > 0"):
        bound_power(1.0, 0.0, 10)
    with pytest.raises(ValueError, match="sd ≥ 0"):
        seeds_for_equivalence(-1.0, 1.0)
    with pytest.raises(ValueError, match="power"):
        seeds_for_equivalence(1.0, 1.0, power=1.0)


def _simulated_power(n: int, experiments: int = 300) -> float:
    """How often the TOST decision the claims use (bootstrap 90% CI inside ±1) says "equivalent"
    for two arms of n normal(0, 1) seeds: the truth is no difference."""
    rng = np.random.default_rng(7)
    return float(
        np.mean(
            [
                equivalent(tost_ci(rng.normal(size=n), rng.normal(size=n), resamples=1000, seed=i), 1.0)
                for i in range(experiments)
            ]
        )
    )


def test_equivalence_power_matches_a_simulation():
    """At the planned n the normal approximation matches the real decision; with few seeds the
    percentile bootstrap's interval is narrower than the normal one (plug-in spread), so the
    formula underestimates the power: plans err on the safe side."""
    n = seeds_for_equivalence(1.0, 1.0)
    assert _simulated_power(n) == pytest.approx(equivalence_power(1.0, 1.0, n), abs=0.07)
    assert equivalence_power(1.0, 1.0, 8) - 0.03 <= _simulated_power(8) <= equivalence_power(1.0, 1.0, 8) + 0.15


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


def test_censored_summary_uses_medians_and_order_statistics():
    s = CensoredSummary.of([3.0, 5.0, np.inf])
    assert (s.n, s.median, s.censored, s.ci_low, s.ci_high) == (3, 5.0, 1, 3.0, np.inf)
    assert s.format() == "median 5.0 [3.0, ∞] (1 of 3 censored)"
    assert CensoredSummary.of([np.inf, np.inf]).format(0) == "median ∞ [∞, ∞] (2 of 2 censored)"


RLIABLE = json.loads((Path(__file__).parent / "data" / "rliable_reference.json").read_text())
"""rliable 1.2.0's IQM (with its 95% stratified-bootstrap CI, 50,000 resamples) and performance profile
(with its 95% bands) of one (6 runs, 5 tasks) matrix, written by `python tests/rliable_reference.py`
in an environment with rliable (not a dependency of ours)."""
RLIABLE_SCORES, RLIABLE_TAUS = np.array(RLIABLE["scores"]), RLIABLE["taus"]


def test_iqm_and_its_stratified_interval_agree_with_rliable():
    point, (low, high) = RLIABLE["iqm"], RLIABLE["iqm_ci"]
    assert iqm(RLIABLE_SCORES.reshape(-1)) == pytest.approx(point, abs=1e-12)  # the middle 15 of 30, by hand too
    assert np.mean(np.sort(RLIABLE_SCORES.reshape(-1))[7:23]) == pytest.approx(point, abs=1e-12)
    ours = stratified_bootstrap_ci(RLIABLE_SCORES, iqm, 0.95, 50_000, 0)
    assert ours == pytest.approx((low, high), abs=0.01)  # two generators: bootstrap noise only


def test_the_performance_profile_and_its_bands_agree_with_rliable():
    profile, bands = RLIABLE["profile"], RLIABLE["profile_bands"]
    assert score_distribution(RLIABLE_SCORES, RLIABLE_TAUS) == pytest.approx(profile, abs=1e-8)
    ours = stratified_bootstrap_ci(
        RLIABLE_SCORES, lambda x, axis=None: score_distribution(x, RLIABLE_TAUS, axis), 0.95, 50_000, 0
    )
    assert ours.shape == (2, len(RLIABLE_TAUS))
    assert ours == pytest.approx(np.array(bands), abs=1 / 30 + 1e-9)  # a band's end moves by whole runs (1/30)


def test_a_stratified_bootstrap_keeps_every_task_and_draws_only_its_own_runs():
    # Task 0 is always 0 and task 1 always 1: any mix across tasks would move the mean off ½.
    scores = np.array([[0.0, 1.0], [0.0, 1.0], [0.0, 1.0]])
    assert stratified_bootstrap_ci(scores, np.mean, 0.95, 1_000, 0) == (0.5, 0.5)
    # One run per task: nothing to resample, the interval is the point.
    assert stratified_bootstrap_ci(np.array([[0.2, 0.9, 0.4]]), iqm) == pytest.approx((0.5, 0.5))
    # A task whose runs vary widens the interval; the statistic without an axis argument gives the same.
    varied = np.array([[0.0, 1.0], [2.0, 1.0]])
    assert stratified_bootstrap_ci(varied, np.mean, 0.95, 2_000, 3) == (0.5, 1.5)
    assert stratified_bootstrap_ci(varied, lambda x: float(np.mean(x)), 0.95, 2_000, 3) == (0.5, 1.5)


def test_score_distribution_counts_scores_strictly_above_each_threshold():
    scores = np.array([[0.0, 1.0], [2.0, 1.0]])
    assert list(score_distribution(scores, [-1, 0, 1, 2])) == [1.0, 0.75, 0.25, 0.0]
    assert score_distribution(np.stack([scores.reshape(-1), np.zeros(4)]), [0.5], axis=1).tolist() == [[0.75], [0.0]]


def test_a_stratified_bootstrap_rejects_what_is_not_a_matrix():
    with pytest.raises(ValueError, match="non-empty \\(runs, tasks\\) matrix, got shape \\(3,\\)"):
        stratified_bootstrap_ci(np.ones(3))
