"""The lab's command line: `python -m dqfd_bc_keras.experiments run|export|report|… …`.

The arguments are parsed before anything heavy is imported: `--help` and a bad argument answer
at once, and each command imports what it runs.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from importlib.util import find_spec
from pathlib import Path

from dqfd_bc_keras.commands.cli import ArgumentParser, add_task_arguments, chosen_task, env_settings, positive_int, run
from dqfd_bc_keras.experiments.names import BACKENDS, RUNS_PER_WORKER
from dqfd_bc_keras.experiments.suites import ALL, GRID_TASKS, SUITES, efficiency_tasks, on_task, suite_arms
from dqfd_bc_keras.tuning.command import tune_arguments, tune_command

EXIT_SKIPPED = 1
"""`report --strict`'s exit code when a run was skipped (2 stays a usage error)."""


def comma_list(allowed: Sequence[str], what: str) -> Callable[[str], list[str]]:
    """argparse type of a comma-separated list of names among `allowed`."""

    def parse(text: str) -> list[str]:
        names = text.split(",")
        unknown = sorted(set(names) - set(allowed))
        if unknown:
            raise argparse.ArgumentTypeError(f"unknown {what}(s) {unknown}; expected among {', '.join(allowed)}")
        return names

    return parse


def suite_name(text: str) -> str:
    """argparse type of `run`'s suite: a suite of the package, `all`, or a user's `module:NAME`
    (imported after parsing, by `suites.suite_arms`)."""
    if text in SUITES or text == "all" or ":" in text:
        return text
    choices = ", ".join(repr(name) for name in [*sorted(SUITES), "all"])
    raise argparse.ArgumentTypeError(f"invalid choice: {text!r} (choose from {choices}, or module:NAME)")


def say(line: str) -> None:
    """A progress line, shown as it comes (the output may be a pipe)."""
    print(line, flush=True)


def add_workers(parser: ArgumentParser) -> None:
    parser.add_argument("--workers", type=positive_int, default=2, help="runs at once (default 2: one per core)")


def run_arguments(parser: ArgumentParser) -> None:
    parser.add_argument(
        "suite",
        type=suite_name,
        help=f"one of {', '.join(sorted(SUITES))}; all: {', '.join(ALL)}; or your own list of arms as "
        "module:NAME (docs/EXTENDING.md)",
    )
    parser.add_argument("--seeds", type=positive_int, help="seeds 0 … N−1 per arm (default: each arm's planned seeds)")
    add_workers(parser)
    parser.add_argument("--out", required=True, help="suite directory")
    parser.add_argument(
        "--backend", choices=BACKENDS, default="local", help="local (a process pool, the default) or ray"
    )
    parser.add_argument("--address", help="Ray cluster to join (ray backend); default: a local Ray instance")
    add_task_arguments(parser)  # the suite's arms on this task instead of their own
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a Config field for every arm, e.g. expert=my_rules:swing on an env without scripted experts",
    )
    parser.add_argument(
        "--runs-per-worker",
        type=positive_int,
        default=RUNS_PER_WORKER,
        help="runs a worker process takes in turn before a fresh one replaces it (default %(default)s; "
        "1: a fresh process per run)",
    )
    parser.add_argument(
        "--restart-broken",
        action="store_true",
        help="start over every run whose checkpoint cannot be resumed (default: report it as failed)",
    )


def run_command(args: argparse.Namespace, parser: ArgumentParser) -> int:
    assignments = [
        *(
            f"{key}={json.dumps(value) if isinstance(value, dict) else value}"
            for key, value in env_settings(args).items()
        ),
        *args.set,
    ]
    task, moved = chosen_task(args), chosen_task(args) is not None or assignments
    suites = {suite: suite_arms(suite) for suite in (ALL if args.suite == "all" else (args.suite,))}
    # imported after the suites are found: a wrong module:NAME is refused before TensorFlow loads
    from dqfd_bc_keras.experiments.sweep import SweepOptions, run_suite

    options = SweepOptions(args.workers, args.backend, args.address, say, args.runs_per_worker)
    for suite, arms in suites.items():
        arms = on_task(arms, task, assignments) if moved else arms
        name = f"{suite} on {task}" if task else suite
        run_suite(arms, args.seeds, args.out, options, name=name, restart_broken=args.restart_broken)
    return 0


def export_arguments(parser: ArgumentParser) -> None:
    parser.add_argument("directory", help="suite directory")
    parser.add_argument("--out", required=True, help="archive to write, e.g. results.tar.xz")


def export_command(args: argparse.Namespace, parser: ArgumentParser) -> int:
    from dqfd_bc_keras.experiments.data import export_archive

    names = export_archive(args.directory, args.out)
    print(f"wrote {args.out}: {len(names)} files")
    return 0


def report_arguments(parser: ArgumentParser) -> None:
    parser.add_argument("source", help="a suite directory, or an archive written by `export`")
    parser.add_argument(
        "--docs",
        action="store_true",
        help="write docs/RESULTS.md, docs/per_seed.csv and docs/figures/ of the current directory",
    )
    parser.add_argument(
        "--results", help="markdown file to write, per_seed.csv beside it (overrides the default and --docs)"
    )
    parser.add_argument("--figures", help="directory for the PNG figures (default: figures/ beside the markdown)")
    parser.add_argument(
        "--strict",
        action="store_true",
        help=f"exit {EXIT_SKIPPED} if any run was skipped (a file missing, truncated or unreadable)",
    )


def report_command(args: argparse.Namespace, parser: ArgumentParser) -> int:
    from dqfd_bc_keras.experiments.report import PER_SEED, default_location, report, warn

    results = Path(args.results or (Path("docs") if args.docs else default_location(args.source)) / "RESULTS.md")
    figures = Path(args.figures or results.parent / "figures")
    skipped: list[str] = []

    def skip(line: str) -> None:
        skipped.append(line)
        warn(line)

    report(args.source, results, figures, warn=skip)
    print(f"wrote {results}, {results.with_name(PER_SEED)} and figures in {figures}")
    return EXIT_SKIPPED if args.strict and skipped else 0


def calibrate_arguments(parser: ArgumentParser) -> None:
    parser.add_argument("--out", required=True, help="JSON file to write")
    parser.add_argument("--figure", help="PNG file for the figure")
    parser.add_argument("--quick", action="store_true", help="one seed, one episode, CartPole only (seconds)")


def calibrate_command(args: argparse.Namespace, parser: ArgumentParser) -> int:
    from dqfd_bc_keras.experiments.estimators import main as calibrate

    calibrate(args.out, args.figure, args.quick)
    return 0


def grid_arguments(parser: ArgumentParser) -> None:
    parser.add_argument("--out", required=True, help="suite directory")
    parser.add_argument(
        "--task",
        choices=GRID_TASKS,
        action="append",
        help="run this task's grid only (repeatable; default: every task's); GRID.md shows all that ran",
    )
    parser.add_argument(
        "--quick", action="store_true", help="1 cell of CartPole, 1 seed, the QUICK budget (about a minute)"
    )
    parser.add_argument("--seeds", type=positive_int, help="seeds 0 … N−1 per arm (default: 5)")
    add_workers(parser)


def grid_command(args: argparse.Namespace, parser: ArgumentParser) -> int:
    from dqfd_bc_keras.experiments.grid import run_grid

    tasks = tuple(args.task) if args.task else None
    run_grid(args.out, args.quick, args.seeds, args.workers, progress=say, tasks=tasks)
    return 0


def replicate_arguments(parser: ArgumentParser) -> None:
    parser.add_argument("arm", help="an arm's directory name in the archive, e.g. cartpole-bootstrap-bayes")
    parser.add_argument("--seeds", required=True, help="A-B: the fresh seeds, inclusive")
    parser.add_argument("--out", required=True, help="directory of the reruns")
    parser.add_argument("--archive", default="docs/data/results.tar.xz", help="default: docs/data/results.tar.xz")
    add_workers(parser)


def replicate_command(args: argparse.Namespace, parser: ArgumentParser) -> int:
    from dqfd_bc_keras.experiments.replicate import parse_seeds, replicate

    replicate(args.arm, parse_seeds(args.seeds), args.out, args.archive, args.workers, progress=say)
    return 0


def efficiency_arguments(parser: ArgumentParser) -> None:
    parser.add_argument("--seeds", type=positive_int, default=10)
    parser.add_argument("--workers", type=positive_int, default=2)
    parser.add_argument(
        "--out",
        default="results",
        help="suite directory (runs are reused; the table is written there as efficiency.json)",
    )
    parser.add_argument(
        "--parts",
        type=comma_list(("ours", "sb3"), "part"),
        default=["ours", "sb3"],
        help="what to run: ours, sb3 or both (default)",
    )
    parser.add_argument(
        "--quick",
        action="store_true",
        help="one seed, tiny budgets: checks the command runs (writes no efficiency.json)",
    )
    parser.add_argument(
        "--no-run",
        action="store_true",
        help="run nothing: summarise the complete runs and SB3 files under --out, over the seeds each arm has",
    )
    parser.add_argument(
        "--tasks",
        type=comma_list(list(efficiency_tasks()), "task"),
        default=list(efficiency_tasks()),
        help=f"the tasks to run (default: all of {', '.join(efficiency_tasks())})",
    )
    parser.add_argument("--json", action="store_true", help="one JSON list with every arm's row (∞ as Infinity)")


def efficiency_command(args: argparse.Namespace, parser: ArgumentParser) -> int:
    if "sb3" in args.parts and find_spec("stable_baselines3") is None:
        parser.error("--parts sb3 needs Stable-Baselines3: pip install -r benchmarks/requirements.txt")
    from dqfd_bc_keras.experiments.baselines import measure
    from dqfd_bc_keras.experiments.efficiency import rows, table, teacher_table

    progress = (lambda line: None) if args.json else print
    steps = measure(args.parts, args.tasks, args.seeds, args.workers, Path(args.out), args.quick, args.no_run, progress)
    print(json.dumps(rows(steps)) if args.json else "\n".join([*table(steps), "", *teacher_table(steps)]))
    return 0


@dataclass(frozen=True)
class Command:
    """A subcommand: its line in `--help`, the arguments it adds, and the handler that runs it
    (given the parsed arguments and its own parser, to refuse what argparse could not)."""

    help: str
    arguments: Callable[[ArgumentParser], None]
    handler: Callable[[argparse.Namespace, ArgumentParser], int]
    description: str | None = None


COMMANDS = {
    "run": Command("run a suite's incomplete runs", run_arguments, run_command),
    "export": Command(
        "one archive of exactly the files the report reads",
        export_arguments,
        export_command,
        "Writes the suite's config.json, metrics.csv, evals.csv, eval.json, demonstrations.json, "
        "dynamic_demos.json and provenance.json of every complete run, its sweep logs and the sample-"
        "efficiency benchmark's files into one .tar.xz; the same data give the same bytes.",
    ),
    "report": Command(
        "statistics, figures, RESULTS.md and per_seed.csv of a suite directory or archive",
        report_arguments,
        report_command,
        "Writes RESULTS.md, per_seed.csv and figures/ into SOURCE if it is a suite directory, or into "
        "<name>-report/ beside it if it is an archive (results.tar.xz: results-report/); into the "
        "project's docs/ only with --docs. The hand-written block between the notes markers of an "
        "existing RESULTS.md is kept.",
    ),
    "calibrate": Command(
        "each σ² estimator on demonstrated, agent, random and far states",
        calibrate_arguments,
        calibrate_command,
        "Fits the bayes BC model with each estimator (3 seeds of each task's demonstrations) and "
        "writes mean σ² − σ0² per kind of state, the off/on-demo ratios and the pre-registered pick "
        "of the best other estimator to OUT (JSON).",
    ),
    "grid": Command(
        "the demonstration quality × quantity grid: runs, BC alone, GRID.md and heatmaps",
        grid_arguments,
        grid_command,
        "Runs every missing run of the grid (suite `demos`) and of BC alone into OUT, then writes "
        "OUT/GRID.md and OUT/figures/grid-TASK-*.png (docs/PREREGISTRATION.md §8, §12).",
    ),
    "replicate": Command(
        "rerun an archived arm at fresh seeds and compare its metrics' distributions",
        replicate_arguments,
        replicate_command,
        "Reruns the arm ARM of the archive (its directory name) with its config at seeds A-B, none of "
        "them archived, into OUT, then compares each metric's median and a Mann-Whitney rank test "
        "with the archive's runs (OUT/REPLICATE.md).",
    ),
    "efficiency": Command(
        "sample efficiency: interactions to the threshold, ours against SB3's DQN",
        efficiency_arguments,
        efficiency_command,
        "Runs the efficiency suite's arms and Stable-Baselines3's DQN as rl-zoo3 runs it (both evaluated "
        "on one grid), prints each arm's steps to the threshold and writes OUT/efficiency.json "
        "(dqfd_bc_keras/experiments/baselines.py).",
    ),
    "tune": Command(
        "a hyperparameter search on Optuna: resumable, shared by many workers",
        tune_arguments,
        tune_command,
        "Runs (or continues) an Optuna study of one method on one task: each trial the mean of its params' "
        "metric over --seeds runs, each an ordinary run directory under OUT/trials/; writes OUT/best.json "
        "(train.py --params) and Optuna's figures in OUT/figures/ (docs/TUNING.md).",
    ),
}
"""The subcommands in `--help`'s order."""


def main(argv: Sequence[str] | None = None) -> int:
    parser = ArgumentParser(prog="python -m dqfd_bc_keras.experiments", description=__doc__)
    subparsers = parser.add_subparsers(dest="command", required=True)
    parsers = {}
    for name, command in COMMANDS.items():
        parsers[name] = subparsers.add_parser(name, help=command.help, description=command.description)
        command.arguments(parsers[name])
    args = parser.parse_args(argv)
    return COMMANDS[args.command].handler(args, parsers[args.command])


if __name__ == "__main__":
    sys.exit(run(main, interrupted="every finished run is kept; run the same command again to go on"))
