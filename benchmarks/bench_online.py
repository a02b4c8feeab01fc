"""Environment steps per second of the full online loop, against Stable-Baselines3's DQN.

Ours: the cartpole preset after pre-training, ε-greedy action, storing, one prioritized
update per env step (batch 64), episodes run as one graph call each (`training.Interaction`).
SB3 (when installed, `pip install -r benchmarks/requirements.txt`): DQN on CartPole-v1 with the
same 64-64 network, batch 64 and one gradient step per env step (train_freq=1,
gradient_steps=1), torch on one thread. Each side is timed over the same number of env steps
after a warm-up.

How it measures (`benchmarks/interleave.py`): each side runs in its own fresh process (TensorFlow
and torch never share one; OMP/MKL/TensorFlow/torch on one thread each), interleaved over
`--rounds` rounds (ours, SB3; then SB3, ours; ...). It reports per side the median, min and max
env steps/s over rounds, the ratio ours ÷ SB3 computed per round and its median, min and max,
and the versions, CPU count, load average and thread settings that ran.

    python benchmarks/bench_online.py [--steps 5000] [--rounds 3] [--expert-loss bayes] [--json] [--quick]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import interleave


def our_rate(steps: int, expert_loss: str) -> float:
    """Env steps per second of `Interaction.play`, episodes back to back, after one warm-up episode."""
    import tensorflow as tf

    from dqfd_bc_keras.core.config import Config
    from dqfd_bc_keras.training import loop as training

    config = Config.for_task(
        "cartpole", expert_loss=expert_loss, total_steps=10 * steps, pretrain_steps=100, bc_epochs=2
    )
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
    model = DQN(
        "MlpPolicy",
        gym.make("CartPole-v1"),
        batch_size=64,
        learning_starts=100,
        train_freq=1,
        gradient_steps=1,
        policy_kwargs={"net_arch": [64, 64]},
        verbose=0,
        seed=0,
    )
    model.learn(500)
    start = time.perf_counter()
    model.learn(steps, reset_num_timesteps=False)
    return steps / (time.perf_counter() - start)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else [str(a) for a in argv]
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=5000, help="env steps timed for each side in each round")
    parser.add_argument("--expert-loss", default="bayes")
    interleave.add_arguments(parser)
    args = parser.parse_args(argv)
    if args.quick:
        args.steps, args.rounds = 300, 1  # bench_updates' --quick runs two: the interleaving end to end

    def sb3() -> dict | None:
        rate = sb3_rate(args.steps)
        return None if rate is None else {"steps_per_s": rate}

    sides = {"ours": lambda: {"steps_per_s": our_rate(args.steps, args.expert_loss)}, "sb3": sb3}
    return interleave.main(
        "bench_online",
        __file__,
        argv,
        args,
        sides,
        ratios={"steps_per_s": ("steps_per_s", "steps_per_s")},
        settings={
            "steps": args.steps,
            "expert_loss": args.expert_loss,
            "ours": f"{args.expert_loss}, one prioritized update per env step",
            "sb3": "DQN, uniform replay, train_freq=1, gradient_steps=1, batch 64, 64-64",
        },
    )


if __name__ == "__main__":
    sys.exit(main())
