"""The SB3 baseline and the sample-efficiency benchmark: environment interactions until the greedy
policy first solves the plain env, ours against Stable-Baselines3's DQN.

Ours: `bayes`, `ce`, `margin` (DQfD) and `none` (DQN) from 5 (CartPole) / 10 (MountainCar)
episodes of the imperfect expert, and `bayes` (the default) from 10 episodes on Acrobot and
LunarLander; one run of the experiment runner per seed. The baseline:
Stable-Baselines3's DQN as rl-zoo3 runs it (its tuned hyperparameters, one `learn()` call of
n_timesteps per seed, so ε decays over the schedule it was tuned with). Both are evaluated on
one grid, at step 0 and every 1,000 steps: 10 greedy episodes on the plain env with the seed's
fixed evaluation seeds (`seeds.eval_seed`). A step is an environment interaction that produced
training data: ours count dynamic-demonstration roll-outs too (evals.csv's `interactions`), SB3
counts its own `num_timesteps`. Per arm: median and 95% bootstrap CI over seeds of the first
grid step whose mean reaches the threshold (CartPole-v1 475, MountainCar-v0 −110; never: ∞),
and for ours SB3's median ÷ ours with its bootstrap CI against the goal (10× on CartPole and
MountainCar, 5× on Acrobot and LunarLander: dqfd_bc_keras/experiments/efficiency.py). SB3's rows
show an independent check beside them.

    python -m dqfd_bc_keras.experiments efficiency [--seeds 10] [--workers 2] [--out results] [--parts ours,sb3]
                                       [--tasks cartpole,mountaincar,acrobot,lunarlander] [--json]
    python -m dqfd_bc_keras.experiments efficiency --quick   # seconds: one seed, tiny budgets (tests)

(`python benchmarks/bench_sample_efficiency.py …` is the same command.) SB3 is optional:
pip install -r benchmarks/requirements.txt.

Writes only under --out: efficiency.json (the arms of parts not run this time are kept) and
sb3-dqn/<task>/seed<k>.json (evaluations, hyperparameters, versions; reused while they match).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Collection, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from importlib.metadata import version
from multiprocessing import get_context
from pathlib import Path
from typing import NamedTuple, cast

import gymnasium as gym
import numpy as np

from dqfd_bc_keras.core.config import QUICK
from dqfd_bc_keras.envs.episodes import play
from dqfd_bc_keras.envs.make import get_task
from dqfd_bc_keras.evaluation import evaluate
from dqfd_bc_keras.experiments.arm_config import Arm
from dqfd_bc_keras.experiments.data import load_runs
from dqfd_bc_keras.experiments.efficiency import EFFICIENCY_FILE, SB3_METHOD, ArmSteps, interaction_evals, load, save
from dqfd_bc_keras.experiments.metrics import first_reaching, solved_return
from dqfd_bc_keras.experiments.suites import PROTOCOL, SUITES
from dqfd_bc_keras.experiments.sweep import SweepOptions, run_suite
from dqfd_bc_keras.experiments.zoo import ANCHOR, ANCHOR_FINAL, ZOO
from dqfd_bc_keras.files import write_text
from dqfd_bc_keras.plugins import load as load_object
from dqfd_bc_keras.seeds import eval_seed

PARTS = ("ours", "sb3")
"""What the benchmark runs: our arms, SB3's DQN, or both."""

QUICK_PROTOCOL, QUICK_SB3_STEPS = {**PROTOCOL, "eval_every": 300}, 1500
"""--quick: our quick arm's evaluation interval for both sides, and SB3's budget (seconds)."""


def arms(quick: bool) -> list[Arm]:
    """Ours: the lab's `efficiency` suite (on CartPole its arms are the paper's `cartpole/bootstrap`
    arms, so a shared `--out` runs them once), or one tiny arm."""
    if quick:
        return [Arm("cartpole", "bootstrap", "bayes", tuple({**QUICK, **QUICK_PROTOCOL}.items()), "eff")]
    return SUITES["efficiency"]


def ours(suite: list[Arm], seeds: int, out: Path, complete_only: bool = False) -> list[ArmSteps]:
    """Each arm's seeds (complete runs under `out`; with `complete_only`, those that exist),
    stepped by `interactions`."""
    steps = []
    for a in suite:
        dirs = [out / a.name / f"seed{seed}" for seed in range(seeds)]
        runs = [r for d in dirs if not complete_only or (d / "eval.json").is_file() for r in load_runs(d)]
        if not runs:
            continue
        steps.append(
            ArmSteps.of(
                a.task,
                a.expert_loss,
                map(interaction_evals, runs),
                [r.final.mean_return for r in runs],
                solved_return(a.task),
            )
        )
    return steps


def sb3_run(task: str, seed: int, budget: int, every: int, path: Path) -> None:
    """One SB3 DQN run as rl-zoo3 runs it (one `learn()` of `budget` steps), its greedy policy
    evaluated like ours at step 0 and every `every` steps of its own counter, saved to `path`."""
    import torch
    from stable_baselines3 import DQN
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.env_util import make_vec_env

    class Grid(BaseCallback):
        """10 greedy episodes (the seed's evaluation seeds) at step 0 and at every multiple of
        `every` up to `budget`: a rollout of `train_freq` steps may run past the budget."""

        def __init__(self) -> None:
            super().__init__()
            self.evals: list[tuple[int, float]] = []

        def _evaluate(self) -> None:
            policy = lambda obs: int(self.model.predict(obs, deterministic=True)[0])
            seeds = range(eval_seed(seed), eval_seed(seed) + PROTOCOL["eval_episodes"])
            if wrapper is None:
                mean = evaluate(policy, task, PROTOCOL["eval_episodes"], seed=eval_seed(seed)).mean_return
            else:  # the plain env as SB3 sees it, through rl-zoo3's wrapper: its rewards and ends untouched
                with wrapper(gym.make(spec["env"])) as plain:
                    mean = float(np.mean(play(plain, policy, seeds).returns))
            self.evals.append((self.num_timesteps, mean))

        def _on_training_start(self) -> None:
            self._evaluate()

        def _on_step(self) -> bool:
            if self.num_timesteps % every == 0 and self.num_timesteps <= budget:
                self._evaluate()
            return True

    torch.set_num_threads(1)
    spec = ZOO[task]
    wrapper: Callable[[gym.Env], gym.Env] | None = None
    if "env_wrapper" in spec:
        wrapper = cast(Callable[[gym.Env], gym.Env], load_object(spec["env_wrapper"], f"{task}'s env_wrapper"))
    grid, started = Grid(), time.perf_counter()
    # as rl-zoo3 makes it: a DummyVecEnv of a Monitor, wrapped in the entry's env_wrapper
    env = make_vec_env(spec["env"], n_envs=1, seed=seed, wrapper_class=wrapper)
    model = DQN(spec["policy"], env, seed=seed, verbose=0, **spec["kwargs"])
    model.learn(total_timesteps=budget, callback=grid)
    write_text(
        path,
        json.dumps(
            {
                **sb3_settings(task, seed, budget, every),
                "evals": grid.evals,
                "seconds": time.perf_counter() - started,
                "versions": {name: version(name) for name in ("stable-baselines3", "torch", "gymnasium")},
            }
        ),
    )


def sb3_settings(task: str, seed: int, budget: int, every: int) -> dict:
    """What an SB3 run's file records of how it was run, and must match for it to be reused."""
    spec = ZOO[task]
    return {
        "task": task,
        "env": spec["env"],
        "seed": seed,
        "n_timesteps": budget,
        "eval_every": every,
        "eval_episodes": PROTOCOL["eval_episodes"],
        "eval_seed": eval_seed(seed),
        "hyperparameters": {
            "policy": spec["policy"],
            **spec["kwargs"],
            **({"env_wrapper": spec["env_wrapper"]} if "env_wrapper" in spec else {}),
        },
    }


class SB3Job(NamedTuple):
    task: str
    seed: int
    budget: int
    every: int
    path: Path

    @property
    def current(self) -> bool:
        """Its file exists and records the settings asked for (a changed setting reruns it)."""
        wanted = sb3_settings(self.task, self.seed, self.budget, self.every)
        return self.path.is_file() and wanted.items() <= json.loads(self.path.read_text()).items()


def _at(step: float | None) -> str:
    return "never" if step is None else f"{step:,.0f}"


def run_sb3(
    jobs: Sequence[SB3Job],
    workers: int,
    progress: Callable[[str], None] = print,
    finished: Callable[[SB3Job], None] | None = None,
) -> None:
    """The jobs whose files are missing or stale, on a process pool; `finished(job)` as each ends."""
    todo = [job for job in jobs if not job.current]
    progress(f"SB3 DQN: {len(jobs)} runs, {len(jobs) - len(todo)} complete, {len(todo)} to run on {workers} worker(s)")
    if not todo:
        return
    with ProcessPoolExecutor(max_workers=workers, mp_context=get_context("spawn")) as pool:
        futures = {pool.submit(sb3_run, *job): job for job in todo}
        for done, future in enumerate(as_completed(futures), start=1):
            future.result()
            job = futures[future]
            run = json.loads(job.path.read_text())
            threshold = get_task(job.task).solved_return
            first = None if threshold is None else first_reaching(run["evals"], threshold)
            reached = "" if threshold is None else f"threshold first reached at {_at(first)}, "
            progress(
                f"[{done}/{len(todo)}] sb3 {job.task} seed{job.seed}: {reached}final return "
                f"{run['evals'][-1][1]:.2f} ({run['seconds']:.0f} s)"
            )
            if finished is not None:
                finished(job)


def sb3(
    tasks: list[str],
    seeds: int,
    workers: int,
    out: Path,
    quick: bool,
    progress: Callable[[str], None] = print,
    complete_only: bool = False,
) -> list[ArmSteps]:
    """Every (task, seed) of SB3's DQN whose file under `out/sb3-dqn/` is missing or stale, on a
    process pool (with `complete_only`, none: the current files only); then each task's seeds."""
    every = (QUICK_PROTOCOL if quick else PROTOCOL)["eval_every"]
    jobs = {
        (task, seed): SB3Job(
            task,
            seed,
            QUICK_SB3_STEPS if quick else ZOO[task]["n_timesteps"],
            every,
            out / "sb3-dqn" / task / f"seed{seed}{'-quick' if quick else ''}.json",
        )
        for task in tasks
        for seed in range(seeds)
    }
    run_sb3([] if complete_only else list(jobs.values()), workers, progress)
    steps = []
    for task in tasks:
        evals = [
            json.loads(jobs[task, seed].path.read_text())["evals"] for seed in range(seeds) if jobs[task, seed].current
        ]
        if not evals:
            continue
        steps.append(
            ArmSteps.of(
                task,
                SB3_METHOD,
                evals,
                [e[-1][1] for e in evals],
                solved_return(task),
                anchor=ANCHOR.get(task),
                anchor_final=ANCHOR_FINAL.get(task),
            )
        )
    return steps


def measure(
    parts: Collection[str],
    tasks: Sequence[str],
    seeds: int,
    workers: int,
    out: Path,
    quick: bool = False,
    no_run: bool = False,
    progress: Callable[[str], None] = print,
) -> list[ArmSteps]:
    """Run the missing runs of `parts` on `tasks` (with `no_run`, none) and return every arm's
    steps; unless `quick`, also write them to `out`/EFFICIENCY_FILE, keeping the arms of a part not
    run this time (`parts={"sb3"}` leaves ours as they were)."""
    seeds = 1 if quick else seeds
    suite = [a for a in arms(quick) if quick or a.task in tasks]
    steps = []
    if "ours" in parts:
        if not no_run:
            run_suite(suite, seeds, out, SweepOptions(workers, progress=progress), name="sample efficiency")
        steps += ours(suite, seeds, out, complete_only=no_run)
    if "sb3" in parts:
        steps += sb3(sorted({a.task for a in suite}), seeds, workers, out, quick, progress, no_run)
    if not quick:
        protocol, kept = load(out / EFFICIENCY_FILE) or (PROTOCOL, [])
        fresh = {(s.task, s.method) for s in steps}
        if protocol == PROTOCOL:
            steps += [s for s in kept if (s.task, s.method) not in fresh]
        steps.sort(key=lambda s: (s.task, s.method == SB3_METHOD))  # stable: ours in the suite's order, then SB3
        save(out / EFFICIENCY_FILE, PROTOCOL, steps)
    return steps
