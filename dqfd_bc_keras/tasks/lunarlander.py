"""LunarLander-v3 (1000 steps, solved at 200), with Gymnasium's heuristic as the strong expert."""

from __future__ import annotations

import numpy as np

from dqfd_bc_keras.tasks.registry import ENV_DEFAULTS, TaskSpec, register_task


def heuristic(s: np.ndarray, hover_gain: float = 0.5) -> int:
    """Gymnasium's `heuristic` for the discrete LunarLander (gymnasium/envs/box2d/lunar_lander.py),
    transcribed so it needs no Box2D; `hover_gain` is its 0.5 on the altitude error."""
    angle_targ = np.clip(s[0] * 0.5 + s[2] * 1.0, -0.4, 0.4)  # lean towards the pad, not too far
    hover_targ = 0.55 * np.abs(s[0])  # the farther from the pad, the higher
    angle_todo = (angle_targ - s[4]) * 0.5 - s[5] * 1.0
    hover_todo = (hover_targ - s[1]) * hover_gain - s[3] * 0.5
    if s[6] or s[7]:  # a leg touches: stop turning, only brake the fall
        angle_todo = 0.0
        hover_todo = -s[3] * 0.5
    if hover_todo > np.abs(angle_todo) and hover_todo > 0.05:
        return 2
    if angle_todo < -0.05:
        return 3
    if angle_todo > 0.05:
        return 1
    return 0


def strong(obs: np.ndarray) -> int:
    """Gymnasium's own heuristic (252.8 ± 78.5 over 100 episodes, 91% at or above 200)."""
    return heuristic(obs)


def imperfect(obs: np.ndarray) -> int:
    """The heuristic with an over-eager altitude loop (gain 0.7 for 0.5), which fires the main
    engine more than it should (129.0 ± 135.0 over 100 episodes, 44% at or above 200)."""
    return heuristic(obs, hover_gain=0.7)


register_task(
    TaskSpec(
        "lunarlander",
        "LunarLander-v3",
        "lunarlander",
        1000,
        solved_return=200.0,
        defaults={**ENV_DEFAULTS, "eval_every": 1_000},
        experts={"strong": strong, "imperfect": imperfect},
        keys={"": 0, "left": 1, "up": 2, "right": 3},  # 1 and 3 fire the side engines: they push left and right
        fps=30,
        doc="LunarLander-v3, 1000 steps, solved at 200; as acrobot",
    )
)
