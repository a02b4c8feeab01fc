"""BC alone: what imitation without RL reaches on each cell of the demonstration grid.

There is no command of its own: `python -m dqfd_bc_keras.experiments grid --out results` runs it
(`run_imitation`) after the grid's training runs, and GRID.md reports it as the "BC alone" row;
`grid --quick` runs its quick cells. Its seeds are each cell's arm's own (`--seeds` sets only the
training runs').

Per cell and seed: the demonstrations a `ce` run of that seed records, the MLE BC model `ce`
fits on them (`bc_epochs`), and its greedy policy over the final evaluation's episodes and seeds
(what `evaluate.py RUN --policy bc` plays). No interaction beyond the demonstrations. Each result
is one JSON file, OUT/IMITATION_DIR/<arm>/seed<N>.json; complete ones are skipped.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable
from pathlib import Path

import keras
import numpy as np

from dqfd_bc_keras.core.bc import build_bc_model
from dqfd_bc_keras.evaluation import GreedyPolicy, evaluate
from dqfd_bc_keras.experiments.arm_config import Arm
from dqfd_bc_keras.experiments.suites import grid_arms, grid_tasks
from dqfd_bc_keras.files import write_text
from dqfd_bc_keras.runs.provenance import provenance
from dqfd_bc_keras.seeds import final_eval_seed
from dqfd_bc_keras.training.demonstrations import fit_bc, record_demos

IMITATION_DIR = "bc-alone"
"""The folder of the suite directory that holds BC alone's results (exported with the runs)."""


def imitation_arms(quick_budget: bool = False, tasks: tuple[str, ...] | None = None) -> list[Arm]:
    """One arm per grid cell of each task, named as its `ce` arm with `bc-alone` for the loss."""
    return [
        dataclasses.replace(a, expert_loss="bc-alone")
        for task in tasks or grid_tasks(quick_budget)
        for a in grid_arms(task, quick_budget)
        if a.expert_loss == "ce"
    ]


def imitate(a: Arm, seed: int) -> dict:
    """BC alone on arm `a`'s cell for one seed: the demonstrations, the fit, the evaluation."""
    config = dataclasses.replace(a, expert_loss="ce").config(seed)
    data = record_demos(config, config.expert)  # what a `ce` run of the seed records
    keras.utils.set_random_seed(config.seed)
    bc = build_bc_model(config, data.meta.obs_dim, data.meta.n_actions, data.obs_scale())
    accuracy = fit_bc(config, bc, data, config.bc_epochs, fit_index=0)
    result = evaluate(
        GreedyPolicy.from_model(bc),
        config.task,
        config.final_eval_episodes,
        final_eval_seed(seed),
        config.timeout,
        config.max_steps,
        config.env_kwargs,
    )
    return {
        "config": {
            k: v
            for k, v in config.to_dict().items()
            if k in ("task", "expert", "expert_epsilon", "demo_episodes", "bc_epochs", "seed")
        },
        "demo_transitions": len(data.obs),
        "demonstrator_return": float(np.mean(data.meta.plain_returns)),
        "train_accuracy": accuracy,
        **result.to_dict(),
        "provenance": provenance(),
    }


def run_imitation(
    out: str | Path,
    quick_budget: bool = False,
    progress: Callable[[str], None] = print,
    tasks: tuple[str, ...] | None = None,
) -> int:
    """Every missing (cell, seed) of BC alone on `tasks` (default: all the grid's) into `out`; returns how many ran."""
    ran = 0
    for a in imitation_arms(quick_budget, tasks):
        for seed in range(a.seeds):
            path = Path(out) / IMITATION_DIR / a.name / f"seed{seed}.json"
            if path.is_file():
                continue
            result = imitate(a, seed)
            write_text(path, json.dumps(result, indent=1) + "\n")
            progress(
                f"{a.name} seed{seed}: {result['demo_transitions']} demo transitions, "
                f"accuracy {result['train_accuracy']:.3f}, return {result['mean_return']:.1f}"
            )
            ran += 1
    return ran


def load_imitation(suite_dir: Path) -> dict[str, list[dict]]:
    """{arm name: its seeds' results, in seed order} of `suite_dir`/IMITATION_DIR."""
    root = suite_dir / IMITATION_DIR
    if not root.is_dir():
        return {}
    return {
        d.name: [json.loads(p.read_text()) for p in sorted(d.glob("seed*.json"), key=lambda p: int(p.stem[4:]))]
        for d in sorted(root.iterdir())
        if d.is_dir()
    }
