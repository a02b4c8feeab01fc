"""MountainCar-v0: the paper's sparse task (200 steps) and its goal-count variant (Figs. 9–11)."""

from __future__ import annotations

import numpy as np

from dqfd_bc_keras.tasks.registry import TaskSpec, register_task


def strong(obs: np.ndarray) -> int:
    """Follow the velocity, but at rest push right only if x < −0.49: starting from the right side of
    the valley a first push left builds the swing in fewer steps (threshold measured, ~−106 mean)."""
    position, velocity = obs[0], obs[1]
    return 2 if velocity > 0.0 or (velocity == 0.0 and position < -0.49) else 0


def imperfect(obs: np.ndarray) -> int:
    """Push right iff v ≥ 0: pumps energy by following the velocity but always starts rightwards (~−120)."""
    return 2 if obs[1] >= 0.0 else 0


EXPERTS = {"strong": strong, "imperfect": imperfect}
DEFAULTS = {"demo_episodes": 10, "total_steps": 100_000, "early_stop_window": 0}
"""Sparse rewards: 10 demonstrated episodes, 100k steps, no early stop (the budget ends a run)."""

register_task(
    TaskSpec(
        "mountaincar",
        "MountainCar-v0",
        "mountaincar",
        200,
        solved_return=-110.0,
        defaults=DEFAULTS,
        experts=EXPERTS,
        keys={"left": 0, "": 1, "right": 2},
        fps=30,
        doc="MountainCar-v0, 200 steps, sparse; no early stop (the budget ends it)",
    )
)
register_task(
    TaskSpec(
        "mountaincar-goals",
        "MountainCar-v0",
        "mountaincar",
        200,
        goal_reward=100.0,
        solved_return=-110.0,
        defaults=DEFAULTS,
        experts=EXPERTS,
        keys={"left": 0, "": 1, "right": 2},
        fps=30,
        doc="the paper's goal-count variant (Figs. 9–11): +100 on each flag",
    )
)
