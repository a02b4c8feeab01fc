"""Environment steps per second of the full online loop, against Stable-Baselines3's DQN.

Ours: the cartpole preset after pre-training, ε-greedy action, storing, one prioritized
update per env step (batch 64), episodes run as one graph call each (`training.Interaction`).
SB3 (when installed, `pip install -r benchmarks/requirements.txt`): DQN on CartPole-v1 with the
same 64-64 network, batch 64 and one gradient step per env step (train_freq=1,
gradient_steps=1), torch on one thread. Both are timed over the same number of env steps
after a warm-up, in the same run.

    python benchmarks/bench_online.py [--steps 5000] [--expert-loss bayes] [--json]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import dqfd_bc_keras  # noqa: E402, F401  (first: TensorFlow's threads and log level)
import tensorflow as tf  # noqa: E402

from dqfd_bc_keras import training  # noqa: E402
from dqfd_bc_keras.config import Config  # noqa: E402


def our_rate(steps: int, expert_loss: str) -> float:
    """Env steps per second of `Interaction.play`, episodes back to back, after one warm-up episode."""
    config = Config.for_task("cartpole", expert_loss=expert_loss, total_steps=10 * steps, pretrain_steps=100,
                             bc_epochs=2)
    learner, _ = training.build(config)
    interaction = learner.interaction

    def play(budget: int) -> int:
        done = 0
        while done < budget:
            obs = interaction.reset(seed=done)  # the default loop: the episode is recorded for D_demo
            before = int(interaction.env_steps.numpy())
            interaction.play(tf.constant(obs, tf.float32), tf.constant(budget - done, tf.int64))
            done += int(interaction.env_steps.numpy()) - before
        return done

    play(200)
    start = time.perf_counter()
    done = play(steps)
    return done / (time.perf_counter() - start)


def sb3_rate(steps: int) -> float | None:
    """SB3 DQN env steps per second with one gradient step per env step, or None if absent."""
    try:
        import gymnasium as gym
        import torch
        from stable_baselines3 import DQN
    except ImportError:
        return None
    torch.set_num_threads(1)
    model = DQN("MlpPolicy", gym.make("CartPole-v1"), batch_size=64, learning_starts=100, train_freq=1,
                gradient_steps=1, policy_kwargs={"net_arch": [64, 64]}, verbose=0, seed=0)
    model.learn(500)
    start = time.perf_counter()
    model.learn(steps, reset_num_timesteps=False)
    return steps / (time.perf_counter() - start)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=5000, help="env steps timed for each side")
    parser.add_argument("--expert-loss", default="bayes")
    parser.add_argument("--json", action="store_true", help="one JSON object: steps_per_s, sb3_steps_per_s, ratio")
    args = parser.parse_args(argv)
    ours = our_rate(args.steps, args.expert_loss)
    sb3 = sb3_rate(args.steps)
    figures = {"steps_per_s": round(ours, 1), "sb3_steps_per_s": None if sb3 is None else round(sb3, 1),
               "ratio": None if sb3 is None else round(ours / sb3, 3)}
    if args.json:
        print(json.dumps(figures))
        return 0
    print(f"ours ({args.expert_loss}, one prioritized update per env step): {ours:7.0f} env steps/s")
    if sb3 is None:
        print("SB3 not installed: pip install -r benchmarks/requirements.txt to compare")
    else:
        print(f"SB3 DQN (uniform replay, one update per env step):      {sb3:7.0f} env steps/s")
        print(f"ratio: {ours / sb3:.2f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
