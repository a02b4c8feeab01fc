"""Sample efficiency: environment steps until the greedy policy first solves the plain env.

For `bayes`, `ce`, `margin` (DQfD) and `none` (DQN), from 5 (CartPole) / 10 (MountainCar)
episodes of the imperfect expert, each seed is one run of the experiment runner with a greedy
evaluation of 10 episodes (fixed seeds) on the plain env every 1,000 env steps. Reported per
arm: the median and 95% bootstrap CI over seeds of the first evaluated step whose mean return
reaches the threshold (CartPole-v1 475, MountainCar-v0 −110; a run that never does counts as
"not reached"), and how many seeds end the run above the threshold (final evaluation).
When Stable-Baselines3 is installed (`benchmarks/requirements.txt`), its DQN with rl-zoo3's tuned
hyperparameters is run under the same evaluation protocol, side by side.

    python benchmarks/bench_sample_efficiency.py [--seeds 10] [--workers 2] [--out results/efficiency] [--json]
    python benchmarks/bench_sample_efficiency.py --quick     # seconds: one seed, tiny budgets (tests)
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import dqfd_bc_keras  # noqa: E402, F401  (first: TensorFlow's threads and log level)
import numpy as np  # noqa: E402

from dqfd_bc_keras.config import QUICK  # noqa: E402
from dqfd_bc_keras.envs import get_task  # noqa: E402
from dqfd_bc_keras.evaluation import evaluate  # noqa: E402
from dqfd_bc_keras.experiments import Arm, run_suite  # noqa: E402
from dqfd_bc_keras.stats import bootstrap_ci  # noqa: E402

LOSSES = ("bayes", "ce", "margin", "none")
TASKS = {"cartpole": 5, "mountaincar": 10}
"""Task → demonstration episodes of the imperfect expert."""
PROTOCOL = {"eval_every": 1000, "eval_episodes": 10}

# rl-baselines3-zoo's tuned DQN hyperparameters (hyperparams/dqn.yml) for the two plain envs.
ZOO = {
    "cartpole": {"env": "CartPole-v1", "steps": 50_000, "kwargs": dict(
        learning_rate=2.3e-3, batch_size=64, buffer_size=100_000, learning_starts=1000, gamma=0.99,
        target_update_interval=10, train_freq=256, gradient_steps=128, exploration_fraction=0.16,
        exploration_final_eps=0.04, policy_kwargs={"net_arch": [256, 256]})},
    "mountaincar": {"env": "MountainCar-v0", "steps": 120_000, "kwargs": dict(
        learning_rate=4e-3, batch_size=128, buffer_size=10_000, learning_starts=1000, gamma=0.98,
        target_update_interval=600, train_freq=16, gradient_steps=8, exploration_fraction=0.2,
        exploration_final_eps=0.07, policy_kwargs={"net_arch": [256, 256]})},
}


def arms(quick: bool) -> list[Arm]:
    if quick:
        return [Arm("cartpole", "bootstrap", "bayes", tuple({**QUICK, **PROTOCOL, "eval_every": 300}.items()), "eff")]
    return [Arm(task, "bootstrap", loss, tuple({**PROTOCOL, "demo_episodes": episodes}.items()), "eff")
            for task, episodes in TASKS.items() for loss in LOSSES]


def first_solved(evals: list[tuple[int, float]], threshold: float) -> int | None:
    """The first evaluated env step whose mean return reaches `threshold`, or None."""
    return next((step for step, mean in evals if mean >= threshold), None)


def summarise(label: str, steps: list[int | None], final_above: list[bool]) -> dict:
    reached = np.array([s for s in steps if s is not None], dtype=float)
    row = {"arm": label, "seeds": len(steps), "reached": len(reached),
           "median_steps": float(np.median(reached)) if len(reached) else None,
           "ci": list(bootstrap_ci(reached, np.median)) if len(reached) > 1 else None,
           "above_at_end": int(sum(final_above))}
    return row


def ours(run_dirs: list[Path], threshold: float) -> tuple[list[int | None], list[bool]]:
    steps, final = [], []
    for run_dir in run_dirs:
        with (run_dir / "evals.csv").open() as f:
            evals = [(int(r["env_step"]), float(r["mean_return"])) for r in csv.DictReader(f)]
        steps.append(first_solved(evals, threshold))
        final.append(json.loads((run_dir / "eval.json").read_text())["mean_return"] >= threshold)
    return steps, final


def sb3(task: str, seeds: int, quick: bool) -> tuple[list[int | None], list[bool]] | None:
    """SB3 DQN (rl-zoo3 hyperparameters), evaluated like ours: 10 greedy episodes every 1,000 steps."""
    try:
        import gymnasium as gym
        import torch
        from stable_baselines3 import DQN
    except ImportError:
        return None
    torch.set_num_threads(1)
    spec, threshold = ZOO[task], get_task(task).solved_return
    budget = 3000 if quick else spec["steps"]
    steps, final = [], []
    for seed in range(seeds):
        model = DQN("MlpPolicy", gym.make(spec["env"]), seed=seed, verbose=0, **spec["kwargs"])
        policy = lambda obs: int(model.predict(obs, deterministic=True)[0])  # noqa: E731
        evals = []
        for done in range(PROTOCOL["eval_every"], budget + 1, PROTOCOL["eval_every"]):
            model.learn(PROTOCOL["eval_every"], reset_num_timesteps=False)
            result = evaluate(policy, task, PROTOCOL["eval_episodes"], seed=10_000 + seed * 1000)
            evals.append((done, result.mean_return))
        steps.append(first_solved(evals, threshold))
        final.append(evals[-1][1] >= threshold)
    return steps, final


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", default="results/efficiency", help="suite directory (runs are reused)")
    parser.add_argument("--quick", action="store_true", help="one seed, tiny budgets: checks the script runs")
    parser.add_argument("--json", action="store_true", help="one JSON object with every row")
    args = parser.parse_args(argv)
    seeds = 1 if args.quick else args.seeds
    suite = arms(args.quick)
    run_suite(suite, seeds, args.out, workers=args.workers, progress=lambda line: None if args.json else print(line))
    rows = []
    for arm in suite:
        threshold = get_task(arm.task).solved_return
        run_dirs = [Path(args.out) / arm.name / f"seed{seed}" for seed in range(seeds)]
        rows.append(summarise(f"{arm.task} {arm.expert_loss}", *ours(run_dirs, threshold)))
    for task in sorted({arm.task for arm in suite}):
        baseline = sb3(task, seeds, args.quick)
        if baseline is not None:
            rows.append(summarise(f"{task} SB3 DQN (rl-zoo3)", *baseline))
    if args.json:
        print(json.dumps(rows))
        return 0
    print(f"{'arm':34s} {'median steps to solve':>22s}  {'95% CI':>18s}  reached  above at end")
    for row in rows:
        median = "not reached" if row["median_steps"] is None else f"{row['median_steps']:,.0f}"
        ci = "" if row["ci"] is None else f"[{row['ci'][0]:,.0f}, {row['ci'][1]:,.0f}]"
        print(f"{row['arm']:34s} {median:>22s}  {ci:>18s}  {row['reached']}/{row['seeds']}"
              f"      {row['above_at_end']}/{row['seeds']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
