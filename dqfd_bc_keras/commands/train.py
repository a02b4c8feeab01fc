"""Train an agent with Algorithm 1 (DQfD-BC with a supervised expert loss) and evaluate it.

    dqfd-train                                       # cartpole, bayes, 5 imperfect-expert episodes
    dqfd-train --task mountaincar-goals --expert-loss ce --seed 3
    dqfd-train --env Acrobot-v1 --expert my_rules:swing       # any Gymnasium env, your demonstrator
    dqfd-train --env flappy_bird_gymnasium:FlappyBird-v0 --env-kwargs use_lidar=false --max-steps 1000 ...
    dqfd-train --env CartPole-v1 --demos minari:cartpole/expert-v0   # a local Minari dataset
    dqfd-train --demos demos.npz --set sigma0_sq=1.0 --set total_steps=20000
    dqfd-train --out runs/x --resume                 # continue a killed run from its checkpoint

From a checkout, `python train.py …` is the same command.

The arguments are parsed, and every setting validated, before TensorFlow is imported: `--help`
and a bad argument answer in about a second.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from dqfd_bc_keras import demos
from dqfd_bc_keras.choices import EXPERT_NAMES, TARGETS, TIMEOUT_MODES
from dqfd_bc_keras.commands.cli import (
    RESUMABLE,
    ArgumentParser,
    add_task_arguments,
    chosen_task,
    env_settings,
    positive_int,
    preset_default,
    run,
    seed,
)
from dqfd_bc_keras.core.config import QUICK, Config, parse_assignments
from dqfd_bc_keras.core.memory import check_memory
from dqfd_bc_keras.core.methods import METHODS
from dqfd_bc_keras.core.params import read_params
from dqfd_bc_keras.demos.experts import try_demonstrator
from dqfd_bc_keras.envs.make import checked_spaces, get_task, task_slug, task_spaces
from dqfd_bc_keras.envs.objects import stand_in, unmade_env
from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.files import DirectoryLock
from dqfd_bc_keras.runs.writers import check_dir, has_checkpoint

if TYPE_CHECKING:
    from dqfd_bc_keras.runs.directory import RunResult


def parse(argv: Sequence[str] | None) -> argparse.Namespace:
    parser = ArgumentParser(
        description=__doc__.split("\n\n")[0],
        epilog="Every Config field can be set with --set key=value "
        "(see dqfd_bc_keras/core/config.py for the list and the defaults).",
    )
    add_task_arguments(parser, default="cartpole")
    parser.add_argument(
        "--expert-loss",
        metavar="METHOD",
        help=f"J_E: {' | '.join(METHODS)} or your own MODULE:NAME (default: {preset_default('expert_loss')}; "
        "none = plain DQN; sqil = SQIL's rewards, no J_E)",
    )
    parser.add_argument("--target", choices=TARGETS, help=f"bootstrap target (default: {preset_default('target')})")
    parser.add_argument(
        "--timeout", choices=TIMEOUT_MODES, help=f"time-limit handling (default: {preset_default('timeout')})"
    )
    parser.add_argument(
        "--demos",
        help="demonstrations: a .npz file or minari:DATASET_ID (the local Minari cache); else recorded from --expert",
    )
    parser.add_argument(
        "--expert",
        "--policy",
        dest="expert",
        help=f"who demonstrates: a preset's {' | '.join(EXPERT_NAMES)} (default: {preset_default('expert')}; a preset "
        "of yours without one: its first expert), "
        "a rule module:function (obs → action) or a saved model.keras",
    )
    parser.add_argument(
        "--demo-episodes", type=positive_int, help=f"episodes to record (default: {preset_default('demo_episodes')})"
    )
    parser.add_argument(
        "--steps", type=positive_int, help=f"environment-step budget (default: {preset_default('total_steps')})"
    )
    parser.add_argument("--seed", type=seed, help=f"seed of every random generator (default: {preset_default('seed')})")
    parser.add_argument("--out", help="run directory (default: runs/TASK-LOSS-seedSEED)")
    parser.add_argument("--resume", action="store_true", help="continue the run in --out from its last checkpoint")
    parser.add_argument("--force", action="store_true", help="replace an existing run in --out")
    parser.add_argument(
        "--quick",
        action="store_true",
        help="a tiny budget (seconds), for tests and smoke checks (an Atari game: episodes of at most 200 steps)",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar and no summary")
    parser.add_argument(
        "--params",
        metavar="FILE",
        help="Config fields from a JSON file: `experiments tune`'s best.json, or an object of fields; "
        "the flags and --set win over it",
    )
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="any Config field")
    return parser.parse_args(argv)


def refuse_changes(config: Config, given: dict, demos_source: str | None) -> None:
    """`--resume` continues a run as it was configured: a flag giving another value is an error."""
    saved = config.to_dict()
    changed = [f"{key}={value!r} (the run has {saved[key]!r})" for key, value in given.items() if saved[key] != value]
    if demos_source:
        changed.append("--demos (the run keeps the demonstrations it started with)")
    if changed:
        raise ConfigError(
            f"--resume continues the run in its own config, but the command changes {', '.join(changed)}; "
            "drop those flags, or start the run over with --force"
        )


def gives_env_again(out: str, env_id: str) -> bool:
    """Whether the run in `out` was trained on a Python env object that `--env env_id` now gives
    again (`objects.stand_in`): then it is resumed in its own config, on the env `env_id` makes."""
    try:
        task = json.loads((Path(out) / "config.json").read_text()).get("task")
    except (OSError, ValueError, AttributeError):
        return False  # no readable config.json: saved_config says why
    if unmade_env(task):
        stand_in(task, env_id)
        return True
    return False


def check_out(out: str | None) -> None:
    """`--out` given empty would train into the default directory unasked; a name that is not UTF-8
    (a valid POSIX path) fails in TensorFlow, which writes only to UTF-8 paths: both refused here."""
    if out == "":
        raise ConfigError("--out must not be empty")
    if out is not None:
        try:
            out.encode()
        except UnicodeEncodeError:
            raise ConfigError(
                f"--out {os.fsencode(out)!r} is not a UTF-8 path, and TensorFlow writes only to "
                "those; choose another name"
            ) from None


NOTHING_WRITTEN = "nothing was written; run the same command again"
"""What an interrupt before the run's first checkpoint left, when training did not say it."""


def train_into(args: argparse.Namespace, task: str, quick: dict, given: dict, out: str) -> RunResult:
    """The run the arguments ask for, in `out`: a new one checked before TensorFlow loads, or the
    one there resumed in its own config (a flag that would change it is refused). `given`: the
    settings the user gave (flags, --env-kwargs, --set), which --quick's budget (`quick`) does not
    override."""
    overrides = {**quick, **given}
    dataset = None
    if not args.resume:  # what a new run needs, checked before TensorFlow loads
        task_spaces(task, overrides.get("env_kwargs"))  # the env first: the settings' errors assume a usable one
        config = Config.for_task(task, **overrides)
        check_memory(config, checked_spaces(config))
        if not (Path(out) / DirectoryLock.NAME).exists():  # else the lock's holder is named first, in `train`
            check_dir(Path(out), resume=False, force=args.force)
        if args.demos:
            dataset = demos.load_source(
                args.demos,
                task=config.task,
                timeout=config.timeout,
                env_kwargs=config.env_kwargs,
                max_transitions=config.demo_capacity,
            )
            config = dataclasses.replace(
                config,
                expert=demos.given_expert(args.demos, dataset),
                demo_episodes=demos.given_episodes(f"--demos {args.demos}", dataset, given.get("demo_episodes")),
            )
        elif config.uses_demos:
            try_demonstrator(config)  # a user's rule answers (or fails) once, in a second
    from dqfd_bc_keras.runs.directory import train  # TensorFlow from here on: every argument has been checked
    from dqfd_bc_keras.runs.resume import saved_config

    if args.resume:
        object_run = args.env is not None and gives_env_again(out, args.env)
        config = saved_config(out)
        changes = {
            **overrides,
            **({"task": args.env or args.task} if (args.env or args.task) and not object_run else {}),
        }
        if config.expert.startswith(demos.GIVEN) and "demo_episodes" not in given:
            changes.pop("demo_episodes", None)  # --quick's is a count to record; the run's, its dataset's
        refuse_changes(config, changes, args.demos)
    if not args.quiet:
        print(
            f"training {config.task} with expert loss {config.expert_loss} (seed {config.seed}) into {out}; "
            f"config: {out}/config.json",
            flush=True,
        )
    return train(config, out, dataset, resume=args.resume, force=args.force, quiet=args.quiet)


def main(argv: Sequence[str] | None = None) -> int:
    args = parse(argv)
    flags = {
        "expert_loss": args.expert_loss,
        "target": args.target,
        "timeout": args.timeout,
        "expert": args.expert,
        "demo_episodes": args.demo_episodes,
        "total_steps": args.steps,
        "seed": args.seed,
    }
    chosen = {k: v for k, v in flags.items() if v is not None}
    # Every override before the one validation: --max-steps or --set max_steps=N makes an env
    # without a time limit usable.
    task = chosen_task(args)
    assert task is not None  # --task defaults to cartpole
    params = read_params(args.params, task) if args.params else {}
    given = {**params, **chosen, **env_settings(args), **parse_assignments(args.set)}
    quick = {**QUICK, **get_task(task).quick} if args.quick else {}
    overrides = {**quick, **given}
    check_out(args.out)
    if args.demos and args.expert:
        raise ConfigError(
            f"--demos {args.demos} gives the demonstrations and --expert {args.expert} would record them: give one"
        )
    defaults = Config.__dataclass_fields__
    out = args.out or (
        f"runs/{task_slug(task)}-{overrides.get('expert_loss', defaults['expert_loss'].default)}"
        f"-seed{overrides.get('seed', defaults['seed'].default)}"
    )
    try:
        result = train_into(args, task, quick, given, out)
    except KeyboardInterrupt as error:  # what it left, as the disk says, unless training said it
        error.args = error.args or (RESUMABLE if has_checkpoint(Path(out)) else NOTHING_WRITTEN,)
        raise
    if not args.quiet:
        print(
            f"{result.episodes} episodes, {result.env_steps} env steps, {result.interactions} interactions in all"
            f"{' (early stop)' if result.stopped_early else ''}, {result.wall_time:.0f} s of training"
        )
        print(result.evaluation.summary())
    return 0


def cli() -> int:
    """The `dqfd-train` console script."""
    return run(main)
