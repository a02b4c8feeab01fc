"""Demonstration datasets: record them with any demonstrator (a scripted expert, a rule
`module:function`, a saved `.keras` model), save them as plain `.npz`, and load them back with
every check a learner relies on; Minari datasets convert both ways (`demos/minari.py`).

    python -m dqfd_bc_keras.demos record --task cartpole --expert imperfect --episodes 5 --out demos.npz
    python -m dqfd_bc_keras.demos record --env Acrobot-v1 --policy my_rules:swing --out acrobot.npz
    python -m dqfd_bc_keras.demos record --env flappy_bird_gymnasium:FlappyBird-v0 --env-kwargs use_lidar=false \\
        --max-steps 1000 --policy my_rules:flap --out flappy.npz
    python -m dqfd_bc_keras.demos inspect demos.npz
    python -m dqfd_bc_keras.demos export demos.npz --minari mountaincar/imperfect-v0
"""

from __future__ import annotations

from collections.abc import Sequence

from dqfd_bc_keras.choices import EXPERT_NAMES, TIMEOUT_MODES
from dqfd_bc_keras.commands.cli import ArgumentParser, add_task_arguments, chosen_task, env_settings, positive_int, seed
from dqfd_bc_keras.demos.minari import to_minari
from dqfd_bc_keras.demos.npz import load, save
from dqfd_bc_keras.demos.recording import record
from dqfd_bc_keras.errors import ConfigError


def main(argv: Sequence[str] | None = None) -> int:
    parser = ArgumentParser(prog="python -m dqfd_bc_keras.demos", description=__doc__.split("\n\n")[0])
    commands = parser.add_subparsers(dest="command", required=True)
    rec = commands.add_parser("record", help="record a dataset with a demonstrator")
    add_task_arguments(rec, required=True)
    rec.add_argument(
        "--expert",
        "--policy",
        dest="expert",
        required=True,
        help=f"a preset's {' | '.join(EXPERT_NAMES)}, a rule module:function (obs → action) "
        "or a saved model.keras (its greedy policy)",
    )
    rec.add_argument("--episodes", type=positive_int, default=5)
    rec.add_argument("--seed", type=seed, default=0, help="episode i resets with seed + i")
    rec.add_argument("--epsilon", type=float, default=0.0, help="probability of a random action")
    rec.add_argument("--timeout", choices=TIMEOUT_MODES, default="bootstrap")
    rec.add_argument("--out", required=True, help="the .npz file to write")
    rec.add_argument("--force", action="store_true", help="overwrite an existing file")
    ins = commands.add_parser("inspect", help="print a dataset's summary")
    ins.add_argument("path")
    exp = commands.add_parser("export", help="publish a dataset in the local Minari cache")
    exp.add_argument("path", help="the .npz dataset (recorded with --timeout bootstrap)")
    exp.add_argument("--minari", required=True, metavar="DATASET_ID", help="e.g. acrobot/imperfect-v0")
    exp.add_argument("--force", action="store_true", help="replace an existing Minari dataset of that id")
    args = parser.parse_args(argv)
    if args.command == "record":
        if not args.out.endswith(".npz"):
            raise ConfigError(f"--out must end in .npz, got {args.out!r}")
        env = env_settings(args)
        dataset = record(
            chosen_task(args),
            args.expert,
            args.episodes,
            args.seed,
            args.epsilon,
            args.timeout,
            env.get("max_steps"),
            env.get("env_kwargs"),
        )
        save(dataset, args.out, force=args.force)
        print(f"wrote {args.out}")
    elif args.command == "export":
        dataset = load(args.path)
        print(f"wrote Minari dataset {args.minari} to {to_minari(dataset, args.minari, force=args.force)}")
    else:
        dataset = load(args.path)
    print(dataset.summary())
    return 0
