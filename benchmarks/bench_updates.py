"""Pre-training gradient updates per second, fused vs one graph call per update (and SB3).

Each configuration: the cartpole preset, 5 episodes of the imperfect expert in D_demo, batch
64, prioritized sampling, n-step returns and the priority write-back included. `fused` runs
`agent.learn(K)` (K updates in one graph call); `per_call` runs `agent.learn(1)` K times, the
cost of one graph call per update (what `train_on_batch` in a loop pays). When
Stable-Baselines3 is installed (`pip install -r benchmarks/requirements.txt`), SB3's DQN with
the same network and batch is timed on its `train()` too.

    python benchmarks/bench_updates.py [--updates 3000] [--json]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import dqfd_bc_keras  # noqa: E402, F401  (first: TensorFlow's threads and log level)
import keras  # noqa: E402
import tensorflow as tf  # noqa: E402
from dqfd_bc_keras.agent import make_agent  # noqa: E402
from dqfd_bc_keras.bc import build_bc_model  # noqa: E402
from dqfd_bc_keras.config import Config  # noqa: E402
from dqfd_bc_keras.demos import record  # noqa: E402

LOSSES = ("bayes", "ce", "bc_margin", "margin", "none")


def agent_for(loss: str, demos):
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
    def run(updates: int) -> None:
        for done in range(0, updates, steps_per_call):
            agent.learn(tf.constant(min(steps_per_call, updates - done)))
    return run


def per_call(agent):
    one = tf.constant(1)
    def run(updates: int) -> None:
        for _ in range(updates):
            agent.learn(one)
    return run


def parts(agent) -> dict:
    """The fused update taken apart: `train_step` alone on a fixed batch, and the prioritized
    sample + priority write-back alone (with |δ| = 1), each K per graph call."""
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

    return {"train_step_only": lambda n: train_only(tf.constant(n)),
            "sample_and_priorities_only": lambda n: replay_only(tf.constant(n))}


def sb3_rate(updates: int) -> float | None:
    """SB3 DQN's `train()` rate with a 64-64 MLP and batch 64, or None if SB3 is absent."""
    try:
        import gymnasium as gym
        import torch
        from stable_baselines3 import DQN
    except ImportError:
        return None
    torch.set_num_threads(1)
    model = DQN("MlpPolicy", gym.make("CartPole-v1"), batch_size=64, learning_starts=0,
                policy_kwargs={"net_arch": [64, 64]}, verbose=0, seed=0)
    model.learn(2000)  # fill the buffer
    model.train(gradient_steps=10, batch_size=64)
    start = time.perf_counter()
    model.train(gradient_steps=updates, batch_size=64)
    return updates / (time.perf_counter() - start)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--updates", type=int, default=3000, help="updates timed per configuration")
    parser.add_argument("--steps-per-call", type=int, default=100, help="K, updates fused per graph call")
    parser.add_argument("--losses", default=",".join(LOSSES))
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of lines")
    args = parser.parse_args(argv)
    demos = record("cartpole", "imperfect", episodes=5, seed=0)
    figures: dict[str, float] = {}
    for loss in args.losses.split(","):
        agent = agent_for(loss, demos)
        figures[f"{loss}/fused"] = rate(fused(agent, args.steps_per_call), args.updates)
        figures[f"{loss}/per_call"] = rate(per_call(agent), max(args.updates // 5, 50))
        figures[f"{loss}/ratio"] = figures[f"{loss}/fused"] / figures[f"{loss}/per_call"]
        if loss == "bayes":
            for name, run in parts(agent).items():
                figures[f"{loss}/{name}"] = rate(run, args.updates)
        if not args.json:
            print(f"{loss:10s} fused (K={args.steps_per_call}) {figures[f'{loss}/fused']:7.0f} updates/s   "
                  f"one call per update {figures[f'{loss}/per_call']:6.0f} updates/s   "
                  f"ratio {figures[f'{loss}/ratio']:.1f}x", flush=True)
    if not args.json and "bayes/train_step_only" in figures:
        print(f"bayes, taken apart: train_step alone {figures['bayes/train_step_only']:.0f} updates/s, "
              f"prioritized sample + write-back alone {figures['bayes/sample_and_priorities_only']:.0f}/s")
    sb3 = sb3_rate(args.updates)
    if sb3 is not None:
        figures["sb3_dqn"] = sb3
        for loss in args.losses.split(","):
            figures[f"{loss}/vs_sb3"] = figures[f"{loss}/fused"] / sb3
        if not args.json:
            print(f"SB3 DQN train() {sb3:7.0f} updates/s (uniform replay, 1-step loss only); "
                  + ", ".join(f"{loss} fused {figures[f'{loss}/vs_sb3']:.1f}x" for loss in args.losses.split(",")))
    elif not args.json:
        print("SB3 not installed: pip install -r benchmarks/requirements.txt to compare")
    if args.json:
        print(json.dumps({key: round(value, 3) for key, value in figures.items()}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
