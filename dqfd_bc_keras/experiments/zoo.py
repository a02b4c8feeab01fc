"""The baseline as its authors run it: rl-baselines3-zoo's tuned DQN entries for the tasks the lab compares
on, and the measured or published figures each is checked against (dqfd_bc_keras/experiments/baselines.py
runs them)."""

from __future__ import annotations

from typing import Any, NotRequired, TypedDict


class ZooEntry(TypedDict):
    """An rl-baselines3-zoo entry: the env id, the policy, one `learn()` budget and DQN's keyword arguments,
    and the observation wrapper rl-zoo3 puts on the env (`module:Class`), if any."""

    env: str
    policy: str
    n_timesteps: int
    kwargs: dict[str, Any]
    env_wrapper: NotRequired[str]


# rl-baselines3-zoo's tuned DQN entries, verbatim: hyperparams/dqn.yml of DLR-RM/rl-baselines3-zoo
# at 22e3ff24 (2026-04-23; these two entries unchanged since 2020). `n_timesteps` is rl-zoo3's one
# `learn()` budget, so it also sets the length of the ε schedule (exploration_fraction × n_timesteps).
ZOO: dict[str, ZooEntry] = {
    "cartpole": {
        "env": "CartPole-v1",
        "policy": "MlpPolicy",
        "n_timesteps": 50_000,
        "kwargs": dict(
            learning_rate=2.3e-3,
            batch_size=64,
            buffer_size=100_000,
            learning_starts=1000,
            gamma=0.99,
            target_update_interval=10,
            train_freq=256,
            gradient_steps=128,
            exploration_fraction=0.16,
            exploration_final_eps=0.04,
            policy_kwargs={"net_arch": [256, 256]},
        ),
    },
    "mountaincar": {
        "env": "MountainCar-v0",
        "policy": "MlpPolicy",
        "n_timesteps": 120_000,
        "kwargs": dict(
            learning_rate=4e-3,
            batch_size=128,
            buffer_size=10_000,
            learning_starts=1000,
            gamma=0.98,
            target_update_interval=600,
            train_freq=16,
            gradient_steps=8,
            exploration_fraction=0.2,
            exploration_final_eps=0.07,
            policy_kwargs={"net_arch": [256, 256]},
        ),
    },
    # rl-zoo3 tunes these two entries identically (its LunarLander entry is for v2; v3 fixed bugs in v2).
    **{
        task: {
            "env": env,
            "policy": "MlpPolicy",
            "n_timesteps": 100_000,
            "kwargs": dict(
                learning_rate=6.3e-4,
                batch_size=128,
                buffer_size=50_000,
                learning_starts=0,
                gamma=0.99,
                target_update_interval=250,
                train_freq=4,
                gradient_steps=-1,
                exploration_fraction=0.12,
                exploration_final_eps=0.1,
                policy_kwargs={"net_arch": [256, 256]},
            ),
        }
        for task, env in (("acrobot", "Acrobot-v1"), ("lunarlander", "LunarLander-v3"))
    },
    # rl-zoo3 has no DQN entry for MiniGrid (its MiniGrid entries are PPO's): its `default` entry, SB3's own
    # DQN defaults and MlpPolicy, on the wrapper its MiniGrid entries use (hyperparams/ppo.yml: the 7×7×3 view
    # and the mission, flattened). `n_timesteps` is the budget PREREGISTRATION §15's pilot gives.
    "minigrid-empty": {
        "env": "MiniGrid-Empty-8x8-v0",
        "policy": "MlpPolicy",
        "n_timesteps": 100_000,
        "kwargs": {},
        "env_wrapper": "minigrid.wrappers:FlatObsWrapper",
    },
}
ANCHOR = {"cartpole": 28_000, "mountaincar": 90_000}
"""An independent check of this baseline (one `learn()`, an evaluation callback): SB3's DQN with the
same hyperparameters first reached 475 on CartPole-v1 at 22k/28k/36k steps (3 seeds, median 28k) and
−110 on MountainCar-v0 at 88k/96k. Printed beside the measured median: the two should agree."""
ANCHOR_FINAL = {"acrobot": -76.6, "lunarlander": 154.0}
"""Where no such check exists, rl-zoo3's published benchmark (benchmark.md; one run each, final
evaluation after 100k steps; LunarLander-v2): printed beside the median final return."""
