"""Power and seeds per arm: how likely a rule of stats.py is to decide as it should with n seeds,
and the n it needs, from the normal approximation (two arms sharing one spread).

Every function is pure: the same inputs give the same numbers.
"""

from __future__ import annotations

import numpy as np
from scipy import stats as sps

from dqfd_bc_keras.experiments.stats import Values, as_sample


def pooled_sd(a: Values, b: Values) -> float:
    """The pooled standard deviation of two arms, √(((n_a − 1)s_a² + (n_b − 1)s_b²)/(n_a + n_b − 2)):
    the spread the power calculation assumes both arms share."""
    x, y = as_sample(a), as_sample(b)
    if x.size + y.size < 3:
        raise ValueError(f"a pooled spread needs 3 values or more, got {x.size} and {y.size}")
    squares = np.sum((x - x.mean()) ** 2) + np.sum((y - y.mean()) ** 2)
    return float(np.sqrt(squares / (x.size + y.size - 2)))


def sd_from_ci(ci: tuple[float, float], n: int, level: float = 0.95) -> float:
    """The spread of one arm's values from the normal CI of its mean over n seeds:
    half-width · √n / z_{(1 + level)/2} (a reported interval is often all that is left of a round)."""
    if n < 2:
        raise ValueError(f"a spread needs n ≥ 2 seeds, got {n}")
    return float((ci[1] - ci[0]) / 2.0 * np.sqrt(n) / _z((1.0 + level) / 2.0))


def _z(p: float) -> float:
    return float(sps.norm.ppf(p))


def _check_design(sd: float, margin: float, alpha: float) -> None:
    if sd < 0.0 or margin <= 0.0 or not 0.0 < alpha < 0.5:
        raise ValueError(f"need sd ≥ 0, margin > 0 and 0 < alpha < 0.5, got sd={sd}, margin={margin}, alpha={alpha}")


def _check_power(power: float) -> None:
    if not 0.0 < power < 1.0:
        raise ValueError(f"power must be in (0, 1), got {power}")


def bound_power(sd: float, distance: float, n: int, alpha: float = 0.05) -> float:
    """The chance that the one-sided (1 − α) bound of mean(a) − mean(b), n seeds per arm, falls
    short of a line `distance` away from the true difference (normal approximation):
    Φ(distance / (sd·√(2/n)) − z_{1−α}). E.g. the upper bound below +margin when the truth is 0.
    """
    _check_design(sd, distance, alpha)
    if n < 1:
        raise ValueError(f"need n ≥ 1 seeds per arm, got {n}")
    if sd == 0.0:
        return 1.0
    return float(sps.norm.cdf(distance / (sd * np.sqrt(2.0 / n)) - _z(1.0 - alpha)))


def seeds_for_bound(sd: float, distance: float, power: float = 0.8, alpha: float = 0.05) -> int:
    """Seeds per arm for `bound_power` to reach `power`:

        n = ⌈2 (z_{1−α} + z_{1−β})² sd² / distance²⌉,  β = 1 − power,

    the one-sided (non-inferiority / superiority) sample size of Chow, Shao & Wang 2008, §3.2.3.
    """
    _check_design(sd, distance, alpha)
    _check_power(power)
    return max(1, int(np.ceil(2.0 * (_z(1.0 - alpha) + _z(power)) ** 2 * sd**2 / distance**2)))


def equivalence_power(sd: float, margin: float, n: int, alpha: float = 0.05) -> float:
    """The power of TOST at α (the (1 − 2α) CI inside ±margin) with n seeds per arm when the true
    difference is 0, normal approximation: both bounds must fall inside, and each misses with
    1 − `bound_power`, so the power is max(0, 2Φ(margin / (sd·√(2/n)) − z_{1−α}) − 1).
    The percentile bootstrap's interval is narrower than the normal one with few seeds (plug-in
    spread), so the decision `tost_ci` makes reaches at least this power (tests/test_stats.py).
    """
    return max(0.0, 2.0 * bound_power(sd, margin, n, alpha) - 1.0)


def seeds_for_equivalence(sd: float, margin: float, power: float = 0.8, alpha: float = 0.05) -> int:
    """Seeds per arm for TOST at α to show |Δ| < margin with `power` when the true Δ is 0:

        n = ⌈2 (z_{1−α} + z_{1−β/2})² sd² / margin²⌉,  β = 1 − power,

    the inverse of `equivalence_power` (Julious 2004, Stat. Med. 23:1921, equivalence with a
    true zero difference; Chow, Shao & Wang 2008, §3.2.4 with ε = 0). β/2, not β: with Δ = 0
    the two one-sided tests each miss with β/2. For a share, sd = √(p(1 − p)) (ibid. §4.2).
    """
    _check_design(sd, margin, alpha)
    _check_power(power)
    return max(1, int(np.ceil(2.0 * (_z(1.0 - alpha) + _z(1.0 - (1.0 - power) / 2.0)) ** 2 * sd**2 / margin**2)))
