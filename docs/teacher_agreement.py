"""How often each shipped MinAtar model takes its teacher's action: on the states of the episodes it
was given (recorded again as its run recorded them) and on held-out episodes of the same teacher.

    .venv/bin/python docs/teacher_agreement.py [--models minatar-asterix,...] [--held-out 20]
    .venv/bin/python docs/teacher_agreement.py --quick       # Breakout, one held-out episode: seconds

A model that agrees on its demonstrations but not on held-out states has memorised them; one that
agrees on most held-out states yet plays far below its teacher is undone by its few mistakes, which
take it where no demonstration went (the compounding error of imitation). Prints a markdown table.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import json

import numpy as np

import dqfd_bc_keras
from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.demos.recording import record
from dqfd_bc_keras.experiments.estimators import HELD_OUT_SEED  # seeds no run demonstrates
from dqfd_bc_keras.seeds import demo_seed
from dqfd_bc_keras.training.loop import record_demos

MODELS = Path(__file__).resolve().parents[1] / "models"


def agreement(model, obs: np.ndarray, actions: np.ndarray) -> float:
    """The share of states where the model's highest output is the teacher's action."""
    return float(np.mean(np.argmax(model.predict(obs, batch_size=1024, verbose=0), axis=1) == actions))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--models", default="", help="comma-separated folders of models/ (default: every MinAtar one)")
    parser.add_argument("--held-out", type=int, default=20, help="held-out teacher episodes (default %(default)s)")
    parser.add_argument("--quick", action="store_true", help="minatar-breakout, one held-out episode")
    args = parser.parse_args(argv)
    names = args.models.split(",") if args.models else sorted(p.name for p in MODELS.glob("minatar-*"))
    names, held_out = (["minatar-breakout"], 1) if args.quick else (names, args.held_out)
    print("| model | teacher's episodes | states | Q-network agrees | BC model agrees |")
    print("| --- | --- | --- | --- | --- |")
    for name in names:
        config = Config.from_dict(json.loads((MODELS / name / "config.json").read_text()))
        q_network = dqfd_bc_keras.load_model(MODELS / name / "q_network.keras")
        bc_model = dqfd_bc_keras.load_model(MODELS / name / "bc_model.keras")
        given = record_demos(config, config.expert)  # the run's own demonstrations, as train.py recorded them
        first = demo_seed(config.seed)
        held = record(config.task, config.expert, held_out, HELD_OUT_SEED, config.expert_epsilon, config.timeout)
        for label, demos in (
            (f"demonstrated (seeds {first}–{first + config.demo_episodes - 1})", given),
            (f"held out (seeds {HELD_OUT_SEED}–{HELD_OUT_SEED + held_out - 1})", held),
        ):
            obs = demos.obs.astype(np.float32)
            print(
                f"| {name} | {label} | {len(demos):,} | {agreement(q_network, obs, demos.actions):.1%} "
                f"| {agreement(bc_model, obs, demos.actions):.1%} |",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
