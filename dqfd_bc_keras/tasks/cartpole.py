"""CartPole-v1: the paper's main task (500 steps, −100 on a fall) and its unstable 200-step variant."""

from __future__ import annotations

import numpy as np

from dqfd_bc_keras.tasks.registry import TaskSpec, register_task


def strong(obs: np.ndarray) -> int:
    """Push right iff θ + 0.5·θ̇ + 0.05·x + 0.1·ẋ > 0: PD balance on the pole (500/500) with small cart
    terms that keep the cart from drifting off the track, which matters once epsilon noise is added."""
    x, x_dot, theta, theta_dot = obs[0], obs[1], obs[2], obs[3]
    return int(theta + 0.5 * theta_dot + 0.05 * x + 0.1 * x_dot > 0.0)


def imperfect(obs: np.ndarray) -> int:
    """Push right iff θ̇ > 0: damps the pole's swing but ignores its angle, so it drifts over (~200)."""
    return int(obs[3] > 0.0)


EXPERTS = {"strong": strong, "imperfect": imperfect}
KEYS = {"left": 0, "right": 1}
"""Push left, push right; CartPole has no action for no key, so the last push goes on."""
FPS = 10
"""CartPole's physics steps 0.02 s (50 per second): at 10 a person sees it 5 times slower, and a
pole pushed one way from upright falls in about 10 steps, a second."""
DEFAULTS = {"total_steps": 50_000, "eval_every": 1_000}
"""Runs end within ~10–50k steps (early stop at 10 episodes ≥ 490): a finer evaluation grid makes
steps-to-threshold meaningful."""

register_task(
    TaskSpec(
        "cartpole",
        "CartPole-v1",
        "cartpole",
        500,
        fall_penalty=-100.0,
        solved_return=475.0,
        defaults=DEFAULTS,
        experts=EXPERTS,
        keys=KEYS,
        fps=FPS,
        doc="CartPole-v1, 500 steps, −100 on a fall; stops early at 10 episodes ≥ 490",
    )
)
register_task(
    TaskSpec(
        "cartpole-200",
        "CartPole-v1",
        "cartpole",
        200,
        fall_penalty=-100.0,
        solved_return=475.0,
        defaults=DEFAULTS,
        experts=EXPERTS,
        keys=KEYS,
        fps=FPS,
        doc="the paper's unstable variant with a 200-step limit",
    )
)
