"""Online env steps per second with learning on MinAtar Breakout, ours against Stable-Baselines3's
DQN, and pre-training updates per second.

Ours: the `minatar-breakout` preset (its conv torso and batch; one update every `--train-freq` env
steps, 4 by default as SB3's schedule, so both sides do the same work per step) driven by the training
loop itself (`training.build`, then `training.train_episodes`): ε-greedy acting, storing, one
prioritized update every `train_freq` env steps, episode bookkeeping and dynamic-demonstration
updates, timed from a warm-up of `--warmup` env steps to the end of `--steps` more; and
pre-training (`agent.pretrain`) on its demonstrations, timed after `build`'s own warm-up
pre-training. SB3 (when installed, `pip install -r benchmarks/requirements.txt`): the pixels
baseline exactly (`studies/sb3_pixels.py`: MinAtar's network, rl-zoo3's Atari schedule, one
update of batch 32 every 4 env steps) on MinAtar/Breakout-v1, `learn()` timed over the same
`--steps` after the same warm-up (learning has started: learning_starts is 1% of the schedule);
then its `train()` alone, the counterpart of our pre-training updates. Both on one thread.

How it measures (`benchmarks/interleave.py`): each side in its own fresh process (TensorFlow and
torch never share one; OMP/MKL/TensorFlow/torch on one thread each), interleaved over `--rounds`
rounds; per side the median, min and max over rounds, each ratio ours ÷ SB3 per round and its
median, min and max, the versions, CPU count, load average and thread settings. `--sides sb3`
runs SB3 alone (our side reports nothing and the ratios are None).

    python benchmarks/bench_pixels.py [--steps 5000] [--updates 2000] [--rounds 3] [--sides ours,sb3]
                                      [--expert-loss bayes] [--train-freq 4] [--design package]
                                      [--json] [--quick]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import interleave
import numpy_loop_probe

TASK, ENV_ID = "minatar-breakout", "MinAtar/Breakout-v1"
WARMUP = 500
"""`--warmup`'s default: env steps (and, for ours, pre-training updates) before the clock starts:
graphs traced, learning under way on both sides."""
QUICK_WARMUP = 100


def our_figures(steps: int, updates: int, expert_loss: str, train_freq: int, warmup: int) -> dict[str, float]:
    """Our online env steps/s (the loop a run runs, after `warmup` steps, one update every
    `train_freq` steps) and pre-training updates/s."""

    from dqfd_bc_keras.core.config import Config
    from dqfd_bc_keras.training.loop import build, train_episodes
    from dqfd_bc_keras.training.state import TrainingState

    config = Config.for_task(
        TASK,
        expert_loss=expert_loss,
        total_steps=warmup + steps,
        pretrain_steps=warmup,
        bc_epochs=2,
        eval_every=warmup,
        early_stop_window=0,
        train_freq=train_freq,
    )
    learner, _ = build(config)
    figures = {}
    if config.uses_demos:
        start = time.perf_counter()
        learner.agent.pretrain(updates)
        figures["pretrain_updates_per_s"] = updates / (time.perf_counter() - start)
    # The evaluation grid (every `warmup` env steps, where `train_episodes` pauses an episode) is the
    # clock: each point marks the time and the env steps played; no evaluation is run.
    marks: list[tuple[float, int]] = []
    train_episodes(
        learner,
        TrainingState(),
        on_episode=lambda *_: None,
        on_eval=lambda _: marks.append((time.perf_counter(), int(learner.interaction.env_steps.numpy()))),
    )
    (t0, s0), (t1, s1) = marks[1], marks[-1]  # from the first point after the warm-up to the last
    figures["env_steps_per_s"] = (s1 - s0) / (t1 - t0)
    return figures


def sb3_figures(steps: int, updates: int, warmup: int) -> dict[str, float] | None:
    """SB3's env steps/s of `learn()` with the pixels baseline's schedule, after `warmup` steps, and
    its `train()` updates/s; None if SB3 is absent."""
    if not interleave.sb3_installed():
        return None
    from studies.sb3_pixels import hyperparameters, sb3_model

    budget = warmup + steps
    model = sb3_model(ENV_ID, seed=0, budget=budget, max_steps=10_000)
    model.learn(max(warmup, model.learning_starts))  # the timed steps learn
    start = time.perf_counter()
    model.learn(steps, reset_num_timesteps=False)
    figures = {"env_steps_per_s": steps / (time.perf_counter() - start)}
    batch = hyperparameters(budget)["batch_size"]
    model.train(gradient_steps=10, batch_size=batch)
    start = time.perf_counter()
    model.train(gradient_steps=updates, batch_size=batch)
    figures["train_updates_per_s"] = updates / (time.perf_counter() - start)
    return figures


def sides_list(text: str) -> list[str]:
    names = text.split(",")
    unknown = sorted(set(names) - set(interleave.SIDES))
    if unknown:
        raise argparse.ArgumentTypeError(f"unknown side(s) {unknown}; expected among {', '.join(interleave.SIDES)}")
    return names


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else [str(a) for a in argv]
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=5000, help="env steps timed for each side in each round")
    parser.add_argument(
        "--warmup", type=int, default=WARMUP, help="env steps before the clock starts (default %(default)s)"
    )
    parser.add_argument("--updates", type=int, default=2000, help="pre-training (SB3: train()) updates timed per round")
    parser.add_argument(
        "--sides",
        type=sides_list,
        default=list(interleave.SIDES),
        help="the sides to run (default ours,sb3; sb3 alone runs without our MinAtar support)",
    )
    parser.add_argument("--expert-loss", default="bayes")
    parser.add_argument(
        "--design",
        choices=("package", "numpy-probe"),
        default="package",
        help="our side: the package's training loop (default), or benchmarks/numpy_loop_probe.py's "
        "loop (everything but the update in numpy; a design probe, online steps only)",
    )
    parser.add_argument(
        "--train-freq",
        type=int,
        default=4,
        help="our env steps per update (default 4, SB3's schedule, so both sides do the same work "
        "per step; the preset trains every step, as MinAtar's DQN)",
    )
    interleave.add_arguments(parser)
    args = parser.parse_args(argv)
    if args.quick:
        args.warmup, args.steps, args.updates, args.rounds = QUICK_WARMUP, QUICK_WARMUP, 20, 1
    if args.design == "numpy-probe" and args.expert_loss == "none":
        parser.error("--design numpy-probe times DQfD's loop: it needs demonstrations (an --expert-loss but none)")
    if args.steps < args.warmup or args.updates < 1:
        parser.error(
            f"--steps must be ≥ --warmup {args.warmup} (the clock runs between evaluation-grid points that "
            "far apart) "
            "and --updates ≥ 1"
        )

    sides = {
        "ours": lambda: (
            None
            if "ours" not in args.sides
            else numpy_loop_probe.run(args.steps, args.warmup, args.train_freq, args.expert_loss)
            if args.design == "numpy-probe"
            else our_figures(args.steps, args.updates, args.expert_loss, args.train_freq, args.warmup)
        ),
        "sb3": lambda: sb3_figures(args.steps, args.updates, args.warmup) if "sb3" in args.sides else None,
    }
    ratios = {"env_steps_per_s": ("env_steps_per_s", "env_steps_per_s")}
    if args.expert_loss != "none" and args.design == "package":  # plain DQN has no demonstrations to pre-train on
        ratios["pretrain_vs_sb3_train"] = ("pretrain_updates_per_s", "train_updates_per_s")
    not_run = [
        f"{side}: not run (--sides {','.join(args.sides)})" for side in interleave.SIDES if side not in args.sides
    ]
    return interleave.main(
        "bench_pixels",
        __file__,
        argv,
        args,
        sides,
        ratios,
        settings={
            "env": ENV_ID,
            "task": TASK,
            "steps": args.steps,
            "warmup": args.warmup,
            "updates": args.updates,
            "sides": args.sides,
            "expert_loss": args.expert_loss,
            "design": args.design,
            "train_freq": args.train_freq,
            "ours": (
                f"{TASK} preset, {args.expert_loss}: "
                + ("numpy_loop_probe.run" if args.design == "numpy-probe" else "training.train_episodes")
                + f", one prioritized update of batch 32 every {args.train_freq} env steps"
            ),
            "sb3": "DQN as studies/sb3_pixels.py: MinAtarCNN, uniform replay, train_freq=4, gradient_steps=1, batch 32",
        },
        describe=lambda _: not_run,
    )


if __name__ == "__main__":
    sys.exit(main())
