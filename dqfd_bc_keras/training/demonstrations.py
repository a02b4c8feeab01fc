"""D_demo and π_bc's fits on it: Algorithm 1's step 1 (the demonstrations a run starts from) and
every fit of π_bc, the first (step 2) and the refits of dynamic demonstrations (dynamic.py)."""

from __future__ import annotations

import keras

from dqfd_bc_keras.core.bc import BCModel
from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.demos.dataset import DemoDataset
from dqfd_bc_keras.demos.recording import Demonstrator, record
from dqfd_bc_keras.seeds import BC_FIT, demo_seed, episode_seed
from dqfd_bc_keras.tasks import Rule


def demonstrations(config: Config, dataset: DemoDataset | None) -> DemoDataset | None:
    """Step 1: the given dataset, or `demo_episodes` recorded from the scripted `expert`."""
    if not config.uses_demos:
        return None
    return dataset if dataset is not None else record_demos(config, config.expert)


def record_demos(config: Config, expert: str | Demonstrator | Rule) -> DemoDataset:
    """`demo_episodes` episodes of `expert` (a name `make_demonstrator` takes, a callable, or one made) on the task."""
    return record(
        config.task,
        expert,
        config.demo_episodes,
        seed=demo_seed(config.seed),
        epsilon=config.expert_epsilon,
        timeout=config.timeout,
        max_steps=config.max_steps,
        env_kwargs=config.env_kwargs,
    )


def fit_bc(config: Config, bc: BCModel, data: DemoDataset, epochs: int, fit_index: int) -> float:
    """Fit (or refit, warm-started) π_bc on D_demo; returns its training accuracy.

    The global seed is set from (run seed, fit index), so a resumed run refits identically.
    """
    seed = episode_seed(config.seed, fit_index, BC_FIT) % 2**31
    keras.utils.set_random_seed(seed)
    metrics = bc.fit_demos(data.obs, data.actions, epochs=epochs, batch_size=config.batch_size, seed=seed)
    return metrics["accuracy"] if epochs else float("nan")
