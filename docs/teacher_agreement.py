"""How often each shipped MinAtar model takes its teacher's action: on the states of the episodes it
was given (recorded again as its run recorded them), on held-out episodes of the same teacher, and on
the states its own greedy play reaches; and what its teacher scores when it errs as often.

    .venv/bin/python docs/teacher_agreement.py [--models minatar-asterix,...] [--held-out 20]
    .venv/bin/python docs/teacher_agreement.py --quick       # Breakout, one held-out episode: seconds

A model that agrees on its demonstrations but not on held-out states has memorised them. One that
agrees on most held-out states yet plays far below its teacher is undone by its few mistakes, in one
of two ways, which the last two measurements tell apart: they take it where no demonstration went
(the compounding error of imitation: it agrees less on the states its own play visits, where the
teacher is asked what it would have done, DAgger's question), or the game does not forgive them
(its teacher, made to take a uniformly random action often enough to differ from itself as often
as the model differs from it on held-out states, scores little too). Prints two markdown tables.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import json
import os

import numpy as np

import dqfd_bc_keras
from dqfd_bc_keras import runtime

os.environ.update(runtime.environment())  # runtime.configure()'s settings, before TensorFlow loads

from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.demos.recording import expert_returns, make_demonstrator, record
from dqfd_bc_keras.envs.make import get_task, task_spaces
from dqfd_bc_keras.evaluation import GreedyPolicy
from dqfd_bc_keras.experiments.estimators import HELD_OUT_SEED  # seeds no run demonstrates
from dqfd_bc_keras.seeds import demo_seed
from dqfd_bc_keras.training.demonstrations import record_demos

MODELS = Path(__file__).resolve().parents[1] / "models"
KINDS = {"q_network": "Q-network", "bc_model": "BC model"}


def seeds_text(episodes: int) -> str:
    return f"seeds {HELD_OUT_SEED}–{HELD_OUT_SEED + episodes - 1}"


def agreement(model, obs: np.ndarray, actions: np.ndarray) -> float:
    """The share of states where the model's highest output is the teacher's action."""
    return float(np.mean(np.argmax(model.predict(obs, batch_size=1024, verbose=0), axis=1) == actions))


def own_play(model, config: Config, episodes: int) -> tuple[int, float, float]:
    """The model's greedy play on `episodes` held-out seeds: the states it visits, its mean return, and
    the share of those states where it takes the action its teacher would take there."""
    played = record(config.task, GreedyPolicy.from_model(model), episodes, HELD_OUT_SEED, 0.0, config.timeout)
    teacher = make_demonstrator(config.expert, config.task)
    teacher_actions = np.array([teacher(obs) for obs in played.obs])
    return len(played), float(np.mean(played.meta.episode_returns)), float(np.mean(played.actions == teacher_actions))


def erring_teacher(config: Config, disagreement: float, n_actions: int, episodes: int) -> tuple[float, np.ndarray]:
    """The teacher's returns over `episodes` held-out seeds when it disagrees with itself on a share
    `disagreement` of the steps: a uniformly random action (the same one 1/A of the time) with
    probability ε = disagreement · A / (A − 1)."""
    epsilon = min(1.0, disagreement * n_actions / (n_actions - 1))
    return epsilon, expert_returns(get_task(config.task).family, config.expert, episodes, HELD_OUT_SEED, epsilon)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--models", default="", help="comma-separated folders of models/ (default: every MinAtar one)")
    parser.add_argument("--held-out", type=int, default=20, help="held-out teacher episodes (default %(default)s)")
    parser.add_argument("--own-play", type=int, default=20, help="episodes each model plays (default %(default)s)")
    parser.add_argument("--teacher", type=int, default=100, help="episodes of the erring teacher (default %(default)s)")
    parser.add_argument("--quick", action="store_true", help="minatar-breakout, one episode of each")
    args = parser.parse_args(argv)
    names = args.models.split(",") if args.models else sorted(p.name for p in MODELS.glob("minatar-*"))
    if args.quick:
        names, args.held_out, args.own_play, args.teacher = ["minatar-breakout"], 1, 1, 1
    print("| model | the states of | states | Q-network agrees | BC model agrees |")
    print("| --- | --- | --- | --- | --- |")
    erring = [row for name in names for row in agreements(name, args)]
    print()
    print("| model | its | held-out disagreement | teacher's ε | the teacher's return with that ε (mean ± sd) |")
    print("| --- | --- | --- | --- | --- |")
    for name, kind, disagreement, epsilon, returns in erring:
        print(f"| {name} | {kind} | {disagreement:.1%} | {epsilon:.3f} | {returns.mean():.2f} ± {returns.std():.2f} |")
    return 0


def agreements(name: str, args: argparse.Namespace) -> list[tuple]:
    """Print the model's rows of agreement; return its erring teachers' rows, one per network."""
    config = Config.from_dict(json.loads((MODELS / name / "config.json").read_text()))
    models = {kind: dqfd_bc_keras.load_model(MODELS / name / f"{kind}.keras") for kind in KINDS}
    given = record_demos(config, config.expert)  # the run's own demonstrations, as train.py recorded them
    first = demo_seed(config.seed)
    held = record(config.task, config.expert, args.held_out, HELD_OUT_SEED, config.expert_epsilon, config.timeout)

    def shares(demos) -> dict[str, float]:
        return {kind: agreement(model, demos.obs.astype(np.float32), demos.actions) for kind, model in models.items()}

    held_agrees, given_agrees = shares(held), shares(given)
    for label, states, agrees in (
        (f"demonstrated (seeds {first}–{first + config.demo_episodes - 1})", len(given), given_agrees),
        (f"held out ({seeds_text(args.held_out)})", len(held), held_agrees),
    ):
        print(f"| {name} | {label} | {states:,} | {agrees['q_network']:.1%} | {agrees['bc_model']:.1%} |", flush=True)
    for kind in KINDS:
        states, mean_return, agrees = own_play(models[kind], config, args.own_play)
        cells = " | ".join(f"{agrees:.1%}" if other == kind else "" for other in KINDS)
        label = f"its {KINDS[kind]}'s own play ({seeds_text(args.own_play)}; return {mean_return:.2f})"
        print(f"| {name} | {label} | {states:,} | {cells} |", flush=True)
    n_actions = task_spaces(config.task).n_actions
    return [
        (name, KINDS[kind], 1.0 - agrees, *erring_teacher(config, 1.0 - agrees, n_actions, args.teacher))
        for kind, agrees in held_agrees.items()
    ]


if __name__ == "__main__":
    raise SystemExit(main())
