"""Evaluate a trained agent: greedy episodes on the plain env (CartPole-v1, MountainCar-v0, …).

    dqfd-evaluate runs/cartpole-bayes-0                 # the run's Q-network, 100 episodes
    dqfd-evaluate runs/cartpole-bayes-0 --policy bc     # its BC model instead
    dqfd-evaluate model.keras --task cartpole --json    # a bare model file: name its task
    dqfd-evaluate models/acrobot --episodes 3 --video videos/   # also MP4s (needs moviepy)
    dqfd-evaluate model.keras --env my_envs:Maze-v0 --max-steps 200 --env-kwargs size=9

From a checkout, `python evaluate.py …` is the same command. The arguments are parsed before
TensorFlow is imported.
"""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Callable, Sequence

from dqfd_bc_keras.choices import POLICY_FILES
from dqfd_bc_keras.commands.cli import (
    ArgumentParser,
    add_task_arguments,
    chosen_task,
    env_settings,
    positive_int,
    run,
    seed,
)
from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.files import write_text
from dqfd_bc_keras.seeds import EVAL_SEED

PROGRESS_EVERY = 10.0
"""Seconds between two progress lines of a long evaluation."""


def progress_lines(total: int) -> Callable[[int], None]:
    """A callback for `evaluate`: one line on stderr at most every PROGRESS_EVERY seconds."""
    started = last = time.monotonic()

    def report(done: int) -> None:
        nonlocal last
        now = time.monotonic()
        if now - last >= PROGRESS_EVERY and done < total:
            last = now
            print(f"evaluated {done} of {total} episodes ({now - started:.0f} s)", file=sys.stderr, flush=True)

    return report


def main(argv: Sequence[str] | None = None) -> int:
    parser = ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("target", help="a run directory (config.json + models) or a .keras file")
    add_task_arguments(parser)  # default: the config.json's task
    parser.add_argument(
        "--policy",
        choices=sorted(POLICY_FILES),
        help="a run directory's q_network.keras (q, the default) or bc_model.keras (bc)",
    )
    parser.add_argument("--episodes", type=positive_int, default=100, help="greedy episodes (default 100)")
    parser.add_argument(
        "--seed", type=seed, default=EVAL_SEED, help=f"episode i is reset with seed + i (default {EVAL_SEED})"
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of the summary")
    parser.add_argument("--out", help="also write the JSON result to this file")
    parser.add_argument(
        "--video",
        metavar="DIR",
        help="also record the episodes as MP4 files in DIR (needs moviepy: requirements-extras.txt)",
    )
    args = parser.parse_args(argv)
    if args.out == "":  # else it would be skipped without a word
        raise ConfigError("--out must not be empty")
    from dqfd_bc_keras.evaluation import evaluate, load_policy, record_video  # TensorFlow from here on

    env = env_settings(args)
    policy, settings = load_policy(
        args.target, args.policy, chosen_task(args), env.get("max_steps"), env.get("env_kwargs")
    )
    if args.video:
        files = record_video(
            policy,
            settings.task,
            args.video,
            args.episodes,
            args.seed,
            settings.timeout,
            settings.max_steps,
            settings.env_kwargs,
        )
        print(f"recorded {len(files)} episode(s) in {args.video}", file=sys.stderr)
    result = evaluate(
        policy,
        settings.task,
        args.episodes,
        args.seed,
        settings.timeout,
        settings.max_steps,
        settings.env_kwargs,
        progress=progress_lines(args.episodes),
    )
    report = {**result.to_dict(), "model": str(settings.model_path)}
    if args.out:
        write_text(args.out, json.dumps(report, indent=2) + "\n")
    print(json.dumps(report) if args.json else f"{settings.model_path}\n{result.summary()}")
    return 0


def cli() -> int:
    """The `dqfd-evaluate` console script."""
    return run(main, interrupted="evaluation interrupted: nothing was written")
