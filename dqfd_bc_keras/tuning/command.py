"""`python -m dqfd_bc_keras.experiments tune`: its arguments and what it runs (docs/TUNING.md)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from dqfd_bc_keras.commands.cli import ArgumentParser, add_task_arguments, chosen_task, env_settings, positive_int
from dqfd_bc_keras.experiments.names import BACKENDS
from dqfd_bc_keras.seeds import TUNE_SEED
from dqfd_bc_keras.tuning.objective import METRICS
from dqfd_bc_keras.tuning.space import params_text
from dqfd_bc_keras.tuning.study import PRUNERS, SAMPLERS

if TYPE_CHECKING:
    from dqfd_bc_keras.tuning import Tuned


def tune_arguments(parser: ArgumentParser) -> None:
    add_task_arguments(parser, default="cartpole")
    demos = parser.add_mutually_exclusive_group()
    demos.add_argument("--demos", help="demonstrations: a .npz file or minari:DATASET_ID (as train.py takes them)")
    demos.add_argument("--expert", help="who demonstrates: a preset's expert, module:function or a .keras model")
    parser.add_argument("--expert-loss", default="bayes", metavar="METHOD", help="the method tuned (default: bayes)")
    parser.add_argument("--out", required=True, help="study directory: study.db, trials/, best.json, figures/")
    parser.add_argument(
        "--trials",
        type=positive_int,
        default=20,
        help="trials the study holds when done, those of earlier runs counted (default 20)",
    )
    parser.add_argument("--study-name", help="default: TASK-METHOD-METRIC")
    parser.add_argument(
        "--storage",
        help="an Optuna storage URL (default: sqlite:///OUT/study.db; postgresql://… or mysql://… to share "
        "across machines), or a journal file's path ending in .log",
    )
    parser.add_argument(
        "--seeds",
        type=positive_int,
        default=1,
        help=f"each trial the mean over K runs, seeds {TUNE_SEED:,} … {TUNE_SEED:,} + K − 1 (default 1; never the "
        "seeds of evaluations and studies, 0 and up)",
    )
    parser.add_argument("--steps", type=positive_int, help="each run's env-step budget (default: the task's)")
    parser.add_argument(
        "--metric",
        choices=tuple(METRICS),
        default="auc",
        help="auc: mean return under the evaluation curve (default); final: the final evaluation's return; "
        "threshold: interactions until an evaluation reaches --threshold (minimised)",
    )
    parser.add_argument(
        "--threshold", type=float, help="the threshold metric's return (default: the task's solved return)"
    )
    parser.add_argument("--sampler", choices=SAMPLERS, default="tpe", help="default: tpe")
    parser.add_argument(
        "--pruner", choices=PRUNERS, default="median", help="stops a trial early on its evaluations (default: median)"
    )
    parser.add_argument("--workers", type=positive_int, default=2, help="trials at once (default 2: one per core)")
    parser.add_argument("--backend", choices=BACKENDS, default="local", help="local (processes, the default) or ray")
    parser.add_argument("--address", help="Ray cluster to join (ray backend); default: a local Ray instance")
    parser.add_argument("--space", help="a JSON file over the method's search space (docs/TUNING.md)")
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a Config field every trial keeps (out of the search)",
    )
    parser.add_argument("--quick", action="store_true", help="train.py --quick's budget for every run (tests)")


def tune_command(args: argparse.Namespace, parser: ArgumentParser) -> int:
    from dqfd_bc_keras.core.config import parse_assignments
    from dqfd_bc_keras.tuning import tune

    settings = env_settings(args)
    task = chosen_task(args)
    assert task is not None  # --task defaults to cartpole
    found = tune(
        task,
        out=Path(args.out),
        env_kwargs=settings.get("env_kwargs", {}),
        max_steps=settings.get("max_steps"),
        demos=args.demos or args.expert,
        expert_loss=args.expert_loss,
        trials=args.trials,
        study_name=args.study_name,
        storage=args.storage,
        seeds=args.seeds,
        steps=args.steps,
        metric=args.metric,
        threshold=args.threshold,
        sampler=args.sampler,
        pruner=args.pruner,
        workers=args.workers,
        backend=args.backend,
        address=args.address,
        space_file=args.space,
        fixed=parse_assignments(args.set),
        quick=args.quick,
    )
    print(summary(found))
    return 0


def summary(found: Tuned) -> str:
    """The study's last lines: its trials by state, the best one and where best.json is."""
    from collections import Counter

    states = Counter(trial.state.name.lower() for trial in found.study.trials)
    counts = ", ".join(f"{n} {state}" for state, n in sorted(states.items()))
    if found.params is None:
        return f"study {found.study.study_name}: {counts}; no trial is complete yet"
    assert found.best_file is not None and found.value is not None  # with the params
    return (
        f"study {found.study.study_name}: {counts}; best {found.value:.6g} (trial {found.trial}): "
        f"{params_text(found.params)}\nwrote {found.best_file} (train.py --params {found.best_file}) and "
        f"figures in {found.best_file.parent / 'figures'}"
    )
