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


TUNED_BAYES: dict[str, object] = {
    "learning_rate": 0.0002002542278540594,
    "n_step": 8,
    "batch_size": 64,
    "target_update_period": 222,
    "train_freq": 2,
    "epsilon_end": 0.084597361216957,
    "epsilon_fraction": 0.39545359487390785,
    "lambda_expert": 2.153665849906163,
    "priority_eps_demo": 0.20609935699952986,
    "temperature": 0.15473310032396576,
    "sigma0_sq": 0.5455685645543962,
    "prior_scale": 0.405213626992151,
    "bc_dropout": 0.26832266960433565,
    "bc_learning_rate": 0.0011807305271353146,
    "bc_epochs": 67,
    "dynamic_demos": "off",
}
"""`bayes`'s own defaults on Acrobot since 2026-12-07: PREREGISTRATION §16's study (30 TPE trials, seeds
1,000,000 and 1,000,001, interactions to −100 at 20,000 steps; its trial 5) reached −100 sooner than the
preset's defaults on seeds 0–9 at 100,000 interactions (docs/TUNING_PRESETS.md, docs/TASKS.md); the other
methods keep the generic ones."""


register_task(
    TaskSpec(
        "acrobot",
        "Acrobot-v1",
        "acrobot",
        500,
        solved_return=-100.0,
        defaults={**ENV_DEFAULTS, "eval_every": 1_000},
        method_defaults={"bayes": TUNED_BAYES},
        experts={"strong": strong, "imperfect": imperfect},
        keys={"left": 0, "": 1, "right": 2},  # torque −1, 0, +1 on the joint between the links
        fps=15,
        doc="Acrobot-v1, 500 steps, solved at −100; the generic env defaults (SB3's budget of 100k steps) with "
        "an evaluation every 1k, the sample-efficiency grid",
    )
)
