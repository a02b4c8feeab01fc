"""Sample efficiency: environment steps until the greedy policy first solves the plain env.

For `bayes`, `ce`, `margin` (DQfD) and `none` (DQN), from 5 (CartPole) / 10 (MountainCar)
episodes of the imperfect expert, each seed is one run of the experiment runner with a greedy
evaluation of 10 episodes (fixed seeds) on the plain env every 1,000 env steps. Reported per
arm: the median and 95% bootstrap CI over seeds of the first evaluated step whose mean return
reaches the threshold (CartPole-v1 475, MountainCar-v0 −110; a run that never does counts as
"not reached"), and how many seeds end the run above the threshold (final evaluation).
When Stable-Baselines3 is installed (`benchmarks/requirements.txt`), its DQN with rl-zoo3's tuned
hyperparameters is run under the same evaluation protocol, side by side.

    python benchmarks/bench_sample_efficiency.py [--seeds 10] [--workers 2] [--out results] [--parts ours,sb3] [--json]
    python benchmarks/bench_sample_efficiency.py --quick     # seconds: one seed, tiny budgets (tests)
"""

from __future__ import annotations

import argparse
import json
import sys
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import dqfd_bc_keras  # noqa: E402, F401  (first: TensorFlow's threads and log level)
import numpy as np  # noqa: E402

from dqfd_bc_keras.experiments.claims import first_reaching
from dqfd_bc_keras.experiments.data import load_runs  # noqa: E402
from dqfd_bc_keras.config import QUICK  # noqa: E402
from dqfd_bc_keras.envs import get_task  # noqa: E402
from dqfd_bc_keras.evaluation import evaluate  # noqa: E402
from dqfd_bc_keras.experiments.suites import Arm, arm, run_suite  # noqa: E402
from dqfd_bc_keras.files import write_text  # noqa: E402
from dqfd_bc_keras.experiments.report import EFFICIENCY_FILE, SB3_LABEL, efficiency_table  # noqa: E402
from dqfd_bc_keras.experiments.stats import bootstrap_ci  # noqa: E402

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
    """Ours, with only what differs from the presets overridden: on CartPole these are the paper and
    baselines suites' `cartpole/bootstrap` arms, so a shared `--out` runs them once."""
    if quick:
        return [Arm("cartpole", "bootstrap", "bayes", tuple({**QUICK, **PROTOCOL, "eval_every": 300}.items()), "eff")]
    return [arm(task, "bootstrap", loss, demo_episodes=episodes, **PROTOCOL)
            for task, episodes in TASKS.items() for loss in LOSSES]


def summarise(label: str, evals: list[list[tuple[int, float]]], final: list[float], threshold: float) -> dict:
    """Median and 95% bootstrap CI over all seeds; a seed that never reaches the threshold is
    censored (inf), so the median is "not reached" (None) once half the seeds never do."""
    firsts = [first_reaching(e, threshold) for e in evals]
    steps = np.array([np.inf if step is None else step for step in firsts])  # step 0 is a real answer
    median, ci = float(np.median(steps)), bootstrap_ci(steps, np.median)
    finite = lambda v: v if np.isfinite(v) else None  # noqa: E731  (JSON has no inf)
    return {"arm": label, "seeds": len(steps), "reached": int(np.isfinite(steps).sum()),
            "median_steps": finite(median), "ci": [finite(ci[0]), finite(ci[1])],
            "above_at_end": int(sum(f >= threshold for f in final))}


def ours(run_dirs: list[Path]) -> tuple[list[list[tuple[int, float]]], list[float]]:
    """Each run's (env step, mean return) evaluations and its final evaluation's mean return."""
    runs = [record for run_dir in run_dirs for record in load_runs(run_dir)]
    return ([[(e["env_step"], e["mean_return"]) for e in r.evals] for r in runs],
            [r.final["mean_return"] for r in runs])


def sb3_run(task: str, seed: int, budget: int, path: Path) -> None:
    """One SB3 DQN run (rl-zoo3 hyperparameters), evaluated like ours: 10 greedy episodes on the
    plain env with fixed seeds every 1,000 steps; its evaluations are saved to `path`."""
    import gymnasium as gym
    import torch
    from stable_baselines3 import DQN

    torch.set_num_threads(1)
    spec = ZOO[task]
    model = DQN("MlpPolicy", gym.make(spec["env"]), seed=seed, verbose=0, **spec["kwargs"])
    policy = lambda obs: int(model.predict(obs, deterministic=True)[0])  # noqa: E731
    evals = []
    for done in range(PROTOCOL["eval_every"], budget + 1, PROTOCOL["eval_every"]):
        model.learn(PROTOCOL["eval_every"], reset_num_timesteps=False)
        result = evaluate(policy, task, PROTOCOL["eval_episodes"], seed=10_000 + seed * 1000)
        evals.append((done, result.mean_return))
    write_text(path, json.dumps({"task": task, "seed": seed, "budget": budget, "evals": evals}))


def sb3(tasks: list[str], seeds: int, workers: int, out: Path, quick: bool) -> dict[str, list] | None:
    """Every (task, seed) of SB3's DQN not yet in `out/sb3-dqn/`, on a process pool; None without SB3."""
    try:
        import stable_baselines3  # noqa: F401
    except ImportError:
        return None
    jobs = {(task, seed): out / "sb3-dqn" / task / f"seed{seed}{'-quick' if quick else ''}.json"
            for task in tasks for seed in range(seeds)}
    todo = [(task, seed, 3000 if quick else ZOO[task]["steps"], path)
            for (task, seed), path in jobs.items() if not path.is_file()]
    with ProcessPoolExecutor(max_workers=workers, mp_context=get_context("spawn")) as pool:
        for future in [pool.submit(sb3_run, *job) for job in todo]:
            future.result()
    runs = {task: [json.loads(jobs[task, seed].read_text())["evals"] for seed in range(seeds)] for task in tasks}
    return {task: (evals, [e[-1][1] for e in evals]) for task, evals in runs.items()}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", default="results", help="suite directory (runs are reused; the table is "
                        f"written there as {EFFICIENCY_FILE})")
    parser.add_argument("--parts", default="ours,sb3", help="what to run: ours, sb3 or both (default)")
    parser.add_argument("--quick", action="store_true", help="one seed, tiny budgets: checks the script runs")
    parser.add_argument("--json", action="store_true", help="one JSON object with every row")
    args = parser.parse_args(argv)
    seeds, out, parts = 1 if args.quick else args.seeds, Path(args.out), set(args.parts.split(","))
    suite = arms(args.quick)
    rows = []
    if "ours" in parts:
        run_suite(suite, seeds, out, workers=args.workers, progress=lambda line: None if args.json else print(line),
                  name="sample efficiency")
        for a in suite:
            dirs = [out / a.name / f"seed{seed}" for seed in range(seeds)]
            rows.append(summarise(f"{a.task} {a.expert_loss}", *ours(dirs), get_task(a.task).solved_return))
    baseline = sb3(sorted({a.task for a in suite}), seeds, args.workers, out, args.quick) if "sb3" in parts else None
    for task, (evals, final) in (baseline or {}).items():
        rows.append(summarise(f"{task} {SB3_LABEL}", evals, final, get_task(task).solved_return))
    if not args.quick:
        write_text(out / EFFICIENCY_FILE, json.dumps(rows, indent=1))
    print(json.dumps(rows) if args.json else "\n".join(efficiency_table(rows)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
