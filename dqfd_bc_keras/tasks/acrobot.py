"""Acrobot-v1 (500 steps, solved at −100): a third classic-control task, with the generic env defaults."""

from __future__ import annotations

import numpy as np

from dqfd_bc_keras.tasks.registry import ENV_DEFAULTS, TaskSpec, register_task


def strong(obs: np.ndarray) -> int:
    """Torque +1 iff ω2 − 0.5·ω1 > 0: pumps energy with the second link's swing, against the
    first's (−78.7 ± 12.3 over 100 episodes, 95% of them at or above −100)."""
    return 2 if obs[5] - 0.5 * obs[4] > 0.0 else 0


def imperfect(obs: np.ndarray) -> int:
    """Torque +1 iff ω2 + 0.3·ω1 > 0: the same pump with the first link's term of the wrong sign,
    which swings up more slowly on average (−112.7 ± 38.1, min −281)."""
    return 2 if obs[5] + 0.3 * obs[4] > 0.0 else 0


register_task(
    TaskSpec(
        "acrobot",
        "Acrobot-v1",
        "acrobot",
        500,
        solved_return=-100.0,
        defaults={**ENV_DEFAULTS, "eval_every": 1_000},
        experts={"strong": strong, "imperfect": imperfect},
        keys={"left": 0, "": 1, "right": 2},  # torque −1, 0, +1 on the joint between the links
        fps=15,
        doc="Acrobot-v1, 500 steps, solved at −100; the generic env defaults (SB3's budget of 100k steps) with "
        "an evaluation every 1k, the sample-efficiency grid",
    )
)
