"""Demonstration datasets: record them with any demonstrator (a scripted expert, a rule
`module:function`, a saved `.keras` model), save them as plain `.npz`, and load them back with
every check a learner relies on; Minari datasets convert both ways (`demos/minari.py`).

    python -m dqfd_bc_keras.demos record --task cartpole --expert imperfect --episodes 5 --out demos.npz
    python -m dqfd_bc_keras.demos record --env Acrobot-v1 --policy my_rules:swing --out acrobot.npz
    python -m dqfd_bc_keras.demos record --env flappy_bird_gymnasium:FlappyBird-v0 --env-kwargs use_lidar=false \\
        --max-steps 1000 --policy my_rules:flap --out flappy.npz
    python -m dqfd_bc_keras.demos inspect demos.npz
    python -m dqfd_bc_keras.demos export demos.npz --minari mountaincar/imperfect-v0
    python -m dqfd_bc_keras.demos play --task cartpole --episodes 5 --out mine.npz     # you play, in a window
    python -m dqfd_bc_keras.demos show mine.npz                                        # replayed and checked
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from dqfd_bc_keras.choices import EXPERT_NAMES, TIMEOUT_MODES
from dqfd_bc_keras.commands.cli import (
    ArgumentParser,
    add_task_arguments,
    chosen_task,
    env_settings,
    positive_float,
    positive_int,
    run,
    seed,
)
from dqfd_bc_keras.demos.minari_export import to_minari
from dqfd_bc_keras.demos.npz import load, save
from dqfd_bc_keras.demos.recording import record
from dqfd_bc_keras.errors import ConfigError

PLAY_CONTROLS = """\
in the window:
  Enter (or an action key)  start an episode
  P                         pause, and go on
  Backspace                 discard the episode in play (it is not written) and start the next
  Esc, or close the window  quit (the finished episodes are already written)
  the action keys           the task's (a preset's, else the env's own, else --keys): the window
                            lists them beneath the game; --list-keys prints them with the pace
"""


def _parser() -> ArgumentParser:
    """The command line: record, inspect, export, play, show."""
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
    ply = commands.add_parser(
        "play",
        help="record your own demonstrations: play the env in a window",
        description="Play the env in a window; each finished episode is written to --out as it ends.",
        epilog=PLAY_CONTROLS,
        formatter_class=argparse.RawDescriptionHelpFormatter,  # the controls' lines as written
    )
    add_task_arguments(ply, required=True)
    ply.add_argument("--out", help="the .npz file to write (or minari:DATASET_ID); required unless --list-keys")
    ply.add_argument(
        "--list-keys", action="store_true", help="print the task's keys, pace and controls, and open no window"
    )
    ply.add_argument("--episodes", type=positive_int, help="episodes to record (default: until you quit)")
    ply.add_argument("--keys", help='a key map as JSON, e.g. \'{"a": 0, "d": 2, "": 1}\' ("" = no key pressed)')
    ply.add_argument(
        "--fps", type=positive_float, help="steps per second (default: the task's pace; --list-keys says it)"
    )
    ply.add_argument(
        "--seed", type=seed, help="episode i resets with seed + i (default 0; with --append after the last)"
    )
    ply.add_argument("--timeout", choices=TIMEOUT_MODES, default="bootstrap")
    ply.add_argument("--append", action="store_true", help="add episodes to --out (same task, kwargs and keys)")
    ply.add_argument("--force", action="store_true", help="overwrite an existing --out")
    shw = commands.add_parser("show", help="replay a dataset, checking it step by step, in a window or as MP4s")
    shw.add_argument("path")
    shw.add_argument("--video", metavar="DIR", help="write one MP4 per episode in DIR instead of showing them")
    shw.add_argument("--check", action="store_true", help="only replay and check, without a window")
    shw.add_argument("--fps", type=positive_float, help="steps per second (default: the rate they were played at)")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    if args.command == "play":
        from dqfd_bc_keras.demos.human import controls, play  # pygame from here on

        task, env = chosen_task(args), env_settings(args)
        assert task is not None  # --task or --env is required
        if args.list_keys:
            print("\n".join(controls(task, keys=args.keys, fps=args.fps, **env)))
            return 0
        if args.out is None:
            raise ConfigError("play: --out is required (the file to write), unless --list-keys")
        dataset = play(
            task,
            args.out,
            args.episodes,
            keys=args.keys,
            fps=args.fps,
            seed=args.seed,
            append=args.append,
            force=args.force,
            timeout=args.timeout,
            max_steps=env.get("max_steps"),
            env_kwargs=env.get("env_kwargs"),
        )
        if dataset is None:
            print("no episode finished: nothing written")
            return 0
    elif args.command == "show":
        from dqfd_bc_keras.demos.replaying import show

        dataset = show(args.path, window=not args.check, video=args.video, fps=args.fps)
        if args.video:
            print(f"wrote {dataset.n_episodes} video(s) in {args.video}")
    elif args.command == "record":
        if not args.out.endswith(".npz"):
            raise ConfigError(f"--out must end in .npz, got {args.out!r}")
        task, env = chosen_task(args), env_settings(args)
        assert task is not None  # --task or --env is required
        dataset = record(
            task,
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


def cli() -> int:
    """The `dqfd-demos` console script."""
    return run(main)
