"""Does σ² know where the demonstrations are? Each estimator's σ²(s) − σ0² on four kinds of state.

    python -m dqfd_bc_keras.experiments calibrate --out calibration.json --figure calibration.png

For each task, the bayes BC model is fitted on the training run's demonstrations (seed s: the
preset's imperfect expert, episodes as `train.py --seed s` records them) with each estimator,
and σ² − σ0² is averaged over the states of
- held-out demonstrations: the same expert, other episodes (on-demo: should be small);
- the trained agent: the shipped model's greedy episodes (models/<task>);
- a random policy;
- 3–6 std away: held-out demonstrated states moved 3–6 demonstration standard deviations in a
  random direction (standardised space).
An estimator that is epistemic should give off-demo states several times the on-demo value:
the goal (issue I) is a ratio ≥ 5. The largest value any of them can take is
`uncertainty.max_policy_variance(A)`; the share of it shows how far the imitation weight
1/(2σ²) can fall below 1/(2σ0²).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import keras
import numpy as np
import tensorflow as tf

from ..bc import build_bc_model
from ..config import Config
from ..demos import record, rollout
from ..envs import make_task
from ..evaluation import GreedyPolicy, load_model
from ..files import write_text
from ..seeds import demo_seed
from ..uncertainty import UNCERTAINTIES, max_policy_variance

TASKS = ("cartpole", "mountaincar")
STATE_SETS = ("held-out demos", "trained agent", "random policy", "3–6 std away")
OFF_DEMO = ("random policy", "3–6 std away")
"""The sets an epistemic estimator must single out (the trained agent may stay near the demos)."""
GOAL_RATIO = 5.0
HELD_OUT_SEED = 900_000
"""Reset seeds of the held-out and roll-out episodes, apart from every training run's."""
MODELS = Path(__file__).resolve().parents[2] / "models"


def state_sets(task: str, demos, episodes: int, seed: int) -> dict[str, np.ndarray]:
    """The four kinds of state (module docstring), `episodes` episodes each."""
    config = Config.for_task(task)
    seeds = [HELD_OUT_SEED + seed * 1000 + i for i in range(episodes)]
    held = record(task, config.expert, episodes, seed=seeds[0]).obs
    env = make_task(task)
    agent = GreedyPolicy.from_model(load_model(MODELS / task / "q_network.keras"))
    agent_states = rollout(env, agent, seeds, task=task, source="agent").obs
    rng = np.random.default_rng(seed)
    random_states = rollout(env, lambda obs: int(rng.integers(env.action_space.n)), seeds, task=task,
                            source="random").obs
    env.close()
    mean, std = demos.obs_scale()
    directions = rng.normal(size=held.shape)
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    far = held + directions * rng.uniform(3.0, 6.0, size=(len(held), 1)) * np.maximum(std, 1e-3)
    return dict(zip(STATE_SETS, (held, agent_states, random_states, far.astype(np.float32))))


def measure(task: str, seed: int, episodes: int, bc_epochs: int | None = None) -> dict[str, dict[str, float]]:
    """{estimator: {state set: mean σ² − σ0²}} for one fit of each estimator on seed `seed`'s demos."""
    config = Config.for_task(task, seed=seed)
    demos = record(task, config.expert, config.demo_episodes, seed=demo_seed(seed))
    sets = state_sets(task, demos, episodes, seed)
    result = {}
    for uncertainty in UNCERTAINTIES:
        c = Config.for_task(task, seed=seed, uncertainty=uncertainty)
        keras.utils.set_random_seed(seed)
        bc = build_bc_model(c, demos.meta.obs_dim, demos.meta.n_actions, demos.obs_scale())
        bc.fit_demos(demos.obs, demos.actions, epochs=bc_epochs or c.bc_epochs, batch_size=c.batch_size, seed=seed)
        result[uncertainty] = {name: float(np.mean(bc.predictive(tf.constant(states))[1] - c.sigma0_sq))
                               for name, states in sets.items()}
    return result


def calibrate(tasks: Sequence[str] = TASKS, seeds: int = 3, episodes: int = 5, bc_epochs: int | None = None) -> dict:
    """Every task × seed × estimator, and per task and estimator the mean over seeds, the off/on
    ratios and the share of the largest variance reached."""
    summary: dict = {"goal_ratio": GOAL_RATIO, "seeds": seeds, "episodes": episodes, "n_actions": {}, "tasks": {}}
    for task in tasks:
        runs = [measure(task, seed, episodes, bc_epochs) for seed in range(seeds)]
        env = make_task(task)
        n_actions = summary["n_actions"][task] = int(env.action_space.n)
        env.close()
        table = {}
        for uncertainty in UNCERTAINTIES:
            means = {name: float(np.mean([run[uncertainty][name] for run in runs])) for name in STATE_SETS}
            on = means["held-out demos"]
            table[uncertainty] = {
                "mean": means,
                "ratio": {name: means[name] / on if on > 0 else float("inf") for name in STATE_SETS[1:]},
                "share_of_max": {name: means[name] / max_policy_variance(n_actions) for name in STATE_SETS},
                "per_seed": [run[uncertainty] for run in runs],
            }
        summary["tasks"][task] = table
    return summary


def meets_goal(entry: dict) -> bool:
    """Off-demo/on-demo ≥ GOAL_RATIO on both off-demo sets."""
    return all(entry["ratio"][name] >= GOAL_RATIO for name in OFF_DEMO)


def best_other(summary: dict) -> str:
    """The pre-registered pick (docs/PREREGISTRATION.md §8) of the estimator besides the paper's:
    the larger geometric mean of the off-demo ratios over both sets and all tasks."""
    def score(uncertainty: str) -> float:
        ratios = [summary["tasks"][t][uncertainty]["ratio"][name] for t in summary["tasks"] for name in OFF_DEMO]
        return float(np.exp(np.mean(np.log(np.maximum(ratios, 1e-12)))))

    return max((u for u in UNCERTAINTIES if u != "mc_dropout"), key=score)


def table(summary: dict) -> list[str]:
    """Markdown: per task and estimator, mean σ² − σ0² per state set and the off/on ratios."""
    lines = ["| task | estimator | " + " | ".join(STATE_SETS) + " | ratio random ÷ on | ratio far ÷ on | goal ≥ 5 |",
             "| --- | --- | " + " | ".join("---:" for _ in STATE_SETS) + " | ---: | ---: | --- |"]
    for task, entries in summary["tasks"].items():
        for uncertainty, entry in entries.items():
            means = " | ".join(f"{entry['mean'][name]:.2g}" for name in STATE_SETS)
            ratio = entry["ratio"]
            lines.append(f"| {task} | {uncertainty} | {means} | {ratio['random policy']:.3g} | "
                         f"{ratio['3–6 std away']:.3g} | {'met' if meets_goal(entry) else 'not met'} |")
    return lines


def figure(summary: dict, path: Path) -> None:
    """Grouped bars (log scale): σ² − σ0² per state set, one group per estimator, one panel per task."""
    from .figures import _colors, _figure

    tasks = list(summary["tasks"])
    with _figure(path, nrows=1, ncols=len(tasks), figsize=(5.5 * len(tasks), 4.2), squeeze=False) as (fig, axes):
        for ax, task in zip(axes[0], tasks):
            colors, width = _colors(), 0.8 / len(STATE_SETS)
            for i, name in enumerate(STATE_SETS):
                values = [max(summary["tasks"][task][u]["mean"][name], 1e-6) for u in UNCERTAINTIES]
                ax.bar(np.arange(len(UNCERTAINTIES)) + (i - 1.5) * width, values, width, label=name,
                       color=next(colors))
            ax.axhline(max_policy_variance(summary["n_actions"][task]), color="grey", ls="--", lw=1,
                       label="largest possible")
            ax.set_yscale("log")
            ax.set_xticks(range(len(UNCERTAINTIES)), UNCERTAINTIES)
            ax.set_title(f"{task}: σ² − σ0² by kind of state ({summary['seeds']} fits each)")
        axes[0][0].set_ylabel("mean σ²(s) − σ0²")
        axes[0][-1].legend(fontsize=8)


def main(out: str, figure_path: str | None = None, quick: bool = False) -> dict:
    """Measure, write the JSON to `out` (and the figure), print the table; `quick`: one seed,
    one episode per set, 5 BC epochs, CartPole only (seconds, for the tests)."""
    summary = (calibrate(("cartpole",), seeds=1, episodes=1, bc_epochs=5) if quick else calibrate())
    summary["best_other"] = best_other(summary)
    write_text(Path(out), json.dumps(summary, indent=1) + "\n")
    if figure_path:
        figure(summary, Path(figure_path))
    print("\n".join(table(summary)))
    print(f"best other estimator (PREREGISTRATION §8): {summary['best_other']}")
    return summary
