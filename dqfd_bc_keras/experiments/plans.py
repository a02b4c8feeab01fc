"""Seeds per arm of each claim setting, planned by power (docs/PREREGISTRATION.md §5).

A claim's rule (claims.py) reaches its verdict with probability `rule_power` given the spread of
its metric over seeds and the seeds per arm; a plan takes the spread from the previous round
(or an assumption, stated) and asks for the seeds that give POWER.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.experiments.arms import Setting
from dqfd_bc_keras.experiments.claims import ALPHA, GOALS_MARGIN, PAPER, RETURN_MARGIN, SHARE_MARGIN, TODAY, rule_power
from dqfd_bc_keras.experiments.power import sd_from_ci, seeds_for_bound, seeds_for_equivalence

POWER = 0.8
"""Every rule is planned to reach its verdict with this power when bayes and ce truly do not differ."""
MIN_SEEDS = 10
"""Seeds per arm at least, whatever the power calculation says: a spread has to be seen to be trusted."""


@dataclass(frozen=True)
class Plan:
    """The seeds one claim setting needs: the spread of its judged metric over seeds assumed, where
    that spread comes from, the rule's margin and whether the rule is TOST or (C4) one bound."""

    metric: str
    sd: float
    source: str
    margin: float
    one_sided: bool = False

    def power(self, n: int) -> float:
        return rule_power(self.sd, self.margin, n, self.one_sided)

    @property
    def seeds(self) -> int:
        """Seeds per arm for POWER (at least MIN_SEEDS)."""
        needed = seeds_for_bound if self.one_sided else seeds_for_equivalence
        return max(MIN_SEEDS, needed(self.sd, self.margin, POWER, ALPHA))

    def describe(self) -> str:
        """The plan in one line of RESULTS.md: spread, source, rule, seeds and their power."""
        rule = f"the upper bound below +{self.margin:g}" if self.one_sided else f"TOST within ±{self.margin:g}"
        return (
            f"sd {self.sd:.3g} of `{self.metric}` ({self.source}); {rule} → {self.seeds} seeds per arm "
            f"(power {self.power(self.seeds):.2f}; with {MIN_SEEDS}: {self.power(MIN_SEEDS):.2f})"
        )


PREVIOUS_SEEDS = 10
PREVIOUS_ROUND = (
    f"the previous round's {PREVIOUS_SEEDS} seeds per arm, docs/RESULTS.md of 2026-11-26: each arm's "
    "sd from the 95% bootstrap CI of its mean as half-width · √n / 1.96, pooled over bayes and ce"
)


def _previous(bayes_ci: tuple[float, float], ce_ci: tuple[float, float]) -> float:
    """The pooled sd of two arms of the previous round from their CIs (equal n)."""
    return float(np.sqrt(np.mean([sd_from_ci(ci, PREVIOUS_SEEDS) ** 2 for ci in (bayes_ci, ce_ci)])))


def _limit(task: str) -> int:
    return Config.for_task(task).limit


PLANNED_SEEDS: dict[tuple[str, str], Plan] = {
    ("C1", "cartpole/naive"): Plan(
        "mean_train_return",
        _previous((384.2, 422.3), (357.0, 407.6)),
        PREVIOUS_ROUND,
        RETURN_MARGIN * _limit("cartpole"),
    ),
    ("C1", "cartpole-200/naive"): Plan(
        "mean_train_return",
        _previous((166.7, 183.1), (171.8, 184.2)),
        PREVIOUS_ROUND,
        RETURN_MARGIN * _limit("cartpole-200"),
    ),
    # A share's sd is √(p(1 − p)); the paper says unfinished runs "do not happen often": 1 in 5 assumed.
    ("C2", TODAY.name): Plan(
        "unfinished",
        float(np.sqrt(0.2 * 0.8)),
        "assumed: unfinished runs uncommon, as the paper says (§4); the previous round had "
        "none in either arm, which leaves no spread to measure",
        SHARE_MARGIN,
    ),
    ("C2", PAPER.name): Plan(
        "collapsed",
        float(np.sqrt(0.7 * 0.3)),
        "observed: 7 of 10 runs collapsed in each arm at the archive's 10 seeds per arm "
        "(docs/PREREGISTRATION.md §11; the plan before them assumed the worst case p = ½)",
        SHARE_MARGIN,
    ),
    ("C3", "cartpole/bootstrap"): Plan(
        "mean_train_return",
        _previous((365.1, 402.3), (363.1, 400.8)),
        PREVIOUS_ROUND,
        RETURN_MARGIN * _limit("cartpole"),
    ),
    # The previous round put Δ near 0, so the decisive question is showing it below +margin.
    ("C4", "mountaincar-goals/*"): Plan(
        "goals_first30", _previous((0.86, 0.96), (0.90, 0.99)), PREVIOUS_ROUND, GOALS_MARGIN, one_sided=True
    ),
}
"""Per (claim, setting name): the spread assumed, its source, the margin and the seeds it needs."""


def planned_seeds(claim_id: str, setting: Setting | str) -> int:
    """Seeds per arm for `claim_id` on `setting` (one of its Settings, or that setting's name):
    POWER to reach the claim's verdict when bayes and ce truly do not differ, at least MIN_SEEDS."""
    name = setting if isinstance(setting, str) else setting.name
    if (claim_id, name) not in PLANNED_SEEDS:
        raise ConfigError(
            f"no planned seeds for claim {claim_id!r} on setting {name!r}; planned: {sorted(PLANNED_SEEDS)}"
        )
    return PLANNED_SEEDS[(claim_id, name)].seeds
