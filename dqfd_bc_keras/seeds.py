"""Every seed a run derives from its own `Config.seed`, one function each.

A run's randomness comes from several independent streams (demonstrations, training resets,
evaluations, BC refits, …); deriving each in one place keeps them apart and lets anything
outside the run (the lab, the SB3 baseline) use exactly the same evaluation episodes.
"""

from __future__ import annotations

import numpy as np

MAX_SEED = 2**31 - 1
"""The largest run seed: every generator it seeds (NumPy's legacy one wants < 2³²) takes it and
every seed derived from it below."""

TRAIN, ROLLOUT, BC_FIT = 0, 2, 3
"""Streams of `episode_seed`: training resets, dynamic-demonstration roll-outs, BC (re)fits."""


def demo_seed(seed: int) -> int:
    """Reset seed of the first recorded demonstration episode (episode i uses this + i)."""
    return seed * 1000


EVAL_SEED = 12345
"""Reset seed of the first episode of `evaluate.py` (and `DQfD.evaluate`), unless told another."""


def eval_seed(seed: int) -> int:
    """Reset seed of the first periodic-evaluation episode, apart from training's seeds."""
    return 10_000 + seed * 1000


def final_eval_seed(seed: int) -> int:
    """Reset seed of the first episode of the final evaluation (eval.json)."""
    return eval_seed(seed) + 1_000_000


def episode_seed(seed: int, episode: int, stream: int = TRAIN) -> int:
    """A reset seed per (run seed, episode, stream): a resumed run replays the same starts."""
    return int(np.random.SeedSequence([seed, stream, episode]).generate_state(1)[0])


TUNE_SEED = 1_000_000
"""The first run seed of a hyperparameter search (`experiments tune --seeds K`: TUNE_SEED … TUNE_SEED
+ K − 1, the same K for every trial). Evaluations and studies use seeds from 0 up (the lab's arms
0 … 89 at most, `replicate`'s fresh ones a few hundred): what a search is tuned on is never what
its result is judged on. Every seed a tuning run derives stays apart too (demonstrations from
10⁹, evaluations from 10⁹ + 10⁴) and below MAX_SEED."""
