"""Pre-training gradient updates per second, fused vs one graph call per update (and SB3).

Each configuration: the cartpole preset, 5 episodes of the imperfect expert in D_demo, batch
64, prioritized sampling, n-step returns and the priority write-back included. `fused` runs
`agent.learn(K)` (K updates in one graph call); `per_call` runs `agent.learn(1)` K times, the
cost of one graph call per update (what `train_on_batch` in a loop pays); for `bayes` the fused
update is also taken apart (`train_step` alone, prioritized sample + write-back alone). When
Stable-Baselines3 is installed (`pip install -r benchmarks/requirements.txt`), SB3's DQN with
the same network and batch is timed on its `train()` (torch on one thread); the headline ratio
is `bayes` fused ÷ SB3 `train()`.

How it measures (`benchmarks/interleave.py`): each side (all of ours; SB3) runs in its own fresh
process (TensorFlow and torch never share one; OMP/MKL/TensorFlow/torch on one thread each),
interleaved over `--rounds` rounds (ours, SB3; then SB3, ours; ...). It reports per figure the
median, min and max over rounds, each ratio ours ÷ SB3 computed per round and its median, min
and max, and the versions, CPU count, load average and thread settings that ran.

    python benchmarks/bench_updates.py [--updates 3000] [--rounds 3] [--losses bayes,ce] [--json] [--quick]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import interleave

LOSSES = ("bayes", "ce", "bc_margin", "margin", "none")


def agent_for(loss: str, demos):
    import keras

    from dqfd_bc_keras.core.agent import make_agent
    from dqfd_bc_keras.core.bc import build_bc_model
    from dqfd_bc_keras.core.config import Config

    keras.utils.set_random_seed(0)
    config = Config.for_task("cartpole", expert_loss=loss)
    bc = None
    if config.uses_bc:
        bc = build_bc_model(config, demos.meta.obs_dim, demos.meta.n_actions, demos.obs_scale())
        bc.fit_demos(demos.obs, demos.actions, epochs=1)
    return make_agent(config, demos, bc)


def rate(run, updates: int) -> float:
    """Updates per second of `run(updates)`, after one warm-up call that traces the graph."""
    run(10)
    start = time.perf_counter()
    run(updates)
    return updates / (time.perf_counter() - start)


def fused(agent, steps_per_call: int):
    import tensorflow as tf

    def run(updates: int) -> None:
        for done in range(0, updates, steps_per_call):
            agent.learn(tf.constant(min(steps_per_call, updates - done)))

    return run


def per_call(agent):
    import tensorflow as tf

    one = tf.constant(1)

    def run(updates: int) -> None:
        for _ in range(updates):
            agent.learn(one)

    return run


def parts(agent) -> dict:
    """The fused update taken apart: `train_step` alone on a fixed batch, and the prioritized
    sample + priority write-back alone (with |δ| = 1), each K per graph call."""
    import tensorflow as tf

    batch = agent.replay.sample(agent.config.batch_size, agent.beta())
    ones = tf.ones([agent.config.batch_size])

    @tf.function(input_signature=[tf.TensorSpec([], tf.int32)])
    def train_only(steps):
        for _ in tf.range(steps):
            agent.train_step(batch)

    @tf.function(input_signature=[tf.TensorSpec([], tf.int32)])
    def replay_only(steps):
        for _ in tf.range(steps):
            sampled = agent.replay.sample(agent.config.batch_size, agent.beta())
            agent.replay.update_priorities(sampled.indices, ones + 0.0 * sampled.rewards)

    return {
        "train_step_only": lambda n: train_only(tf.constant(n)),
        "sample_and_priorities_only": lambda n: replay_only(tf.constant(n)),
    }


def sb3_rate(updates: int) -> float | None:
    """SB3 DQN's `train()` rate with a 64-64 MLP and batch 64, or None if SB3 is absent."""
    try:
        import gymnasium as gym
        import torch
        from stable_baselines3 import DQN
    except ImportError:
        return None
    torch.set_num_threads(1)
    model = DQN(
        "MlpPolicy",
        gym.make("CartPole-v1"),
        batch_size=64,
        learning_starts=0,
        policy_kwargs={"net_arch": [64, 64]},
        verbose=0,
        seed=0,
    )
    model.learn(2000)  # fill the buffer
    model.train(gradient_steps=10, batch_size=64)
    start = time.perf_counter()
    model.train(gradient_steps=updates, batch_size=64)
    return updates / (time.perf_counter() - start)


def our_figures(losses: list[str], updates: int, steps_per_call: int) -> dict[str, float]:
    """Every figure of ours, in this process: per loss fused, per_call and their ratio; bayes taken apart."""
    from dqfd_bc_keras.demos import record

    demos = record("cartpole", "imperfect", episodes=5, seed=0)
    figures: dict[str, float] = {}
    for loss in losses:
        agent = agent_for(loss, demos)
        figures[f"{loss}/fused"] = rate(fused(agent, steps_per_call), updates)
        figures[f"{loss}/per_call"] = rate(per_call(agent), max(updates // 5, 50))
        figures[f"{loss}/ratio"] = figures[f"{loss}/fused"] / figures[f"{loss}/per_call"]
        if loss == "bayes":
            for name, run in parts(agent).items():
                figures[f"{loss}/{name}"] = rate(run, updates)
    return figures


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else [str(a) for a in argv]
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--updates", type=int, default=3000, help="updates timed per configuration and round")
    parser.add_argument("--steps-per-call", type=int, default=100, help="K, updates fused per graph call")
    parser.add_argument("--losses", default=",".join(LOSSES))
    interleave.add_arguments(parser)
    args = parser.parse_args(argv)
    if args.quick:
        args.updates, args.steps_per_call, args.losses, args.rounds = 50, 25, "bayes", 2
    losses = args.losses.split(",")

    def sb3() -> dict | None:
        train = sb3_rate(args.updates)
        return None if train is None else {"train": train}

    sides = {"ours": lambda: our_figures(losses, args.updates, args.steps_per_call), "sb3": sb3}
    headline = "bayes" if "bayes" in losses else losses[0]
    ratios = {
        f"{loss}/fused_vs_sb3": (f"{loss}/fused", "train")
        for loss in [headline] + [loss for loss in losses if loss != headline]
    }
    return interleave.main(
        "bench_updates",
        __file__,
        argv,
        args,
        sides,
        ratios,
        settings={
            "updates": args.updates,
            "steps_per_call": args.steps_per_call,
            "losses": losses,
            "per_call_updates": max(args.updates // 5, 50),
            "sb3": "DQN train(), uniform replay, 1-step loss, batch 64, 64-64",
        },
    )


if __name__ == "__main__":
    sys.exit(main())
