"""The estimators of σ²: does σ² know where the demonstrations are, and does the
Bayesian loss with a working estimator change the verdicts?

    python -m dqfd_bc_keras.experiments calibrate --out results/calibration.json --figure calibration.png

Calibration: each estimator's σ²(s) − σ0² on four kinds of state.
For each task, the bayes BC model is fitted on the training run's demonstrations (seed s: the
preset's imperfect expert, episodes as `train.py --seed s` records them) with each estimator,
and σ² − σ0² is averaged over the states of
- held-out demonstrations: the same expert, other episodes (on-demo: should be small);
- the trained agent: the shipped model's greedy episodes (models/<task>);
- a random policy;
- 3–6 std away: held-out demonstrated states moved 3–6 demonstration standard deviations in a
  random direction (standardised space).
An estimator that is epistemic should give off-demo states several times the on-demo value:
the goal is a ratio ≥ 5. The largest value any of them can take is
`uncertainty.max_policy_variance(A)`; the share of it shows how far the imitation weight
1/(2σ²) can fall below 1/(2σ0²).
"""

from __future__ import annotations

import dataclasses
import json
import os
from collections.abc import Sequence
from pathlib import Path

import keras
import numpy as np
import tensorflow as tf

from dqfd_bc_keras.choices import ESTIMATORS
from dqfd_bc_keras.core.bc import build_bc_model
from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.core.uncertainty import max_policy_variance
from dqfd_bc_keras.demos import record, rollout
from dqfd_bc_keras.envs.make import actions_of, make_task
from dqfd_bc_keras.evaluation import GreedyPolicy, load_model
from dqfd_bc_keras.experiments.arms import ArmRuns, find_arm
from dqfd_bc_keras.experiments.claims import CLAIMS, judge
from dqfd_bc_keras.experiments.efficiency import ratio_ci
from dqfd_bc_keras.experiments.lab_settings import LAB_SETTINGS
from dqfd_bc_keras.experiments.stats import CensoredSummary, Summary
from dqfd_bc_keras.experiments.suites import SUITES
from dqfd_bc_keras.files import write_text
from dqfd_bc_keras.seeds import demo_seed

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
    random_states = rollout(env, lambda obs: int(rng.integers(actions_of(env))), seeds, task=task, source="random").obs
    env.close()
    mean, std = demos.obs_scale()
    directions = rng.normal(size=held.shape)
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    far = held + directions * rng.uniform(3.0, 6.0, size=(len(held), 1)) * np.maximum(std, 1e-3)
    return dict(zip(STATE_SETS, (held, agent_states, random_states, far.astype(np.float32)), strict=True))


def measure(task: str, seed: int, episodes: int, bc_epochs: int | None = None) -> dict[str, dict[str, float]]:
    """{estimator: {state set: mean σ² − σ0²}} for one fit of each estimator on seed `seed`'s demos."""
    config = Config.for_task(task, seed=seed)
    demos = record(task, config.expert, config.demo_episodes, seed=demo_seed(seed))
    sets = state_sets(task, demos, episodes, seed)
    result = {}
    for uncertainty in ESTIMATORS:
        c = Config.for_task(task, seed=seed, uncertainty=uncertainty)
        keras.utils.set_random_seed(seed)
        bc = build_bc_model(c, demos.meta.obs_dim, demos.meta.n_actions, demos.obs_scale())
        bc.fit_demos(demos.obs, demos.actions, epochs=bc_epochs or c.bc_epochs, batch_size=c.batch_size, seed=seed)
        result[uncertainty] = {
            name: float(np.mean(bc.predictive(tf.constant(states))[1] - c.sigma0_sq)) for name, states in sets.items()
        }
    return result


def calibrated_tasks() -> tuple[str, ...]:
    """The tasks the estimators are calibrated on (each task's `calibrate`, lab_settings.py), a
    user's registered ones included."""
    return tuple(task for task, lab in LAB_SETTINGS.items() if lab.calibrate)


def calibrate(
    tasks: Sequence[str] | None = None, seeds: int = 3, episodes: int = 5, bc_epochs: int | None = None
) -> dict:
    """Every task (default: `calibrated_tasks()`) × seed × estimator, and per task and estimator the
    mean over seeds, the off/on ratios and the share of the largest variance reached."""
    summary: dict = {"goal_ratio": GOAL_RATIO, "seeds": seeds, "episodes": episodes, "n_actions": {}, "tasks": {}}
    for task in calibrated_tasks() if tasks is None else tasks:
        runs = [measure(task, seed, episodes, bc_epochs) for seed in range(seeds)]
        env = make_task(task)
        n_actions = summary["n_actions"][task] = actions_of(env)
        env.close()
        table = {}
        for uncertainty in ESTIMATORS:
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

    return max((u for u in ESTIMATORS if u != "mc_dropout"), key=score)


def table(summary: dict) -> list[str]:
    """Markdown: per task and estimator, mean σ² − σ0² per state set and the off/on ratios."""
    lines = [
        "| task | estimator | " + " | ".join(STATE_SETS) + " | ratio random ÷ on | ratio far ÷ on | goal ≥ 5 |",
        "| --- | --- | " + " | ".join("---:" for _ in STATE_SETS) + " | ---: | ---: | --- |",
    ]
    for task, entries in summary["tasks"].items():
        for uncertainty, entry in entries.items():
            means = " | ".join(f"{entry['mean'][name]:.2g}" for name in STATE_SETS)
            ratio = entry["ratio"]
            lines.append(
                f"| {task} | {uncertainty} | {means} | {ratio['random policy']:.3g} | "
                f"{ratio['3–6 std away']:.3g} | {'met' if meets_goal(entry) else 'not met'} |"
            )
    return lines


def figure(summary: dict, path: Path) -> None:
    """Grouped bars (log scale): σ² − σ0² per state set, one group per estimator, one panel per task."""
    from dqfd_bc_keras.experiments.figures import _colors, _figure

    tasks = list(summary["tasks"])
    with _figure(path, nrows=1, ncols=len(tasks), figsize=(5.5 * len(tasks), 4.2), squeeze=False) as (fig, axes):
        for ax, task in zip(axes[0], tasks, strict=True):
            colors, width = _colors(), 0.8 / len(STATE_SETS)
            for i, name in enumerate(STATE_SETS):
                values = [max(summary["tasks"][task][u]["mean"][name], 1e-6) for u in ESTIMATORS]
                ax.bar(np.arange(len(ESTIMATORS)) + (i - 1.5) * width, values, width, label=name, color=next(colors))
            ax.axhline(
                max_policy_variance(summary["n_actions"][task]), color="grey", ls="--", lw=1, label="largest possible"
            )
            ax.set_yscale("log")
            ax.set_xticks(range(len(ESTIMATORS)), ESTIMATORS)
            ax.set_title(f"{task}: σ² − σ0² by kind of state ({summary['seeds']} fits each)")
        axes[0][0].set_ylabel("mean σ²(s) − σ0²")
        axes[0][-1].legend(fontsize=8)


def main(out: str, figure_path: str | None = None, quick: bool = False) -> dict:
    """Measure, write the JSON to `out` (and the figure), print the table; `quick`: one seed,
    one episode per set, 5 BC epochs, CartPole only (seconds, for the tests)."""
    summary = calibrate(("cartpole",), seeds=1, episodes=1, bc_epochs=5) if quick else calibrate()
    summary["best_other"] = best_other(summary)
    write_text(Path(out), json.dumps(summary, indent=1) + "\n")
    if figure_path:
        figure(summary, Path(figure_path))
    print("\n".join(table(summary)))
    print(f"best other estimator (PREREGISTRATION §8): {summary['best_other']}")
    return summary


# --- the RESULTS.md section ------------------------------------------------------------------
CALIBRATION_FILE = "calibration.json"
"""`calibrate --out SUITE/calibration.json` writes it into the suite directory; the report reads it."""


def verdict_rows(arms: list[ArmRuns]) -> list[str]:
    """Per estimator arm of the `estimators` suite that ran: its claim's verdict against ce beside
    MC dropout's, interactions to threshold and ce's median ÷ its median."""
    rows = []
    for estimator in SUITES["estimators"]:
        config = estimator.config(0)
        found = find_arm(arms, config)
        if found is None:
            continue
        mc = find_arm(arms, dataclasses.replace(config, uncertainty="mc_dropout"))
        ce = find_arm(arms, dataclasses.replace(config, expert_loss="ce", uncertainty="mc_dropout"))
        claim = next((c for c in CLAIMS for s in c.settings if c.id in ("C3", "C4") and s.task == config.task), None)
        verdicts = (
            ["—", "—"]
            if claim is None
            else [judge(claim, bayes, ce).verdict if bayes is not None else "not run" for bayes in (found, mc)]
        )
        steps = CensoredSummary.of(found.values("interactions_to_threshold")).format(0)
        if ce is not None:
            point, low, high = ratio_ci(
                ce.values("interactions_to_threshold"), found.values("interactions_to_threshold")
            )
            ratio = f"{point:.2f} [{low:.2f}, {high:.2f}]"
        else:
            ratio = "—"
        rows.append(
            f"| {found.setting} | {config.uncertainty} | {len(found.runs)}, {len(ce.runs) if ce else 0} | "
            f"{claim.id if claim else 'efficiency'}: **{verdicts[0]}** | {verdicts[1]} | {steps} | {ratio} | "
            f"{Summary.of(found.values('final_eval')).format()} |"
        )
    return rows


def estimators_section(arms: list[ArmRuns], suite_dir: Path, figures_dir: Path, markdown_dir: Path) -> list[str]:
    """Calibration (table, figure, the goal) and the verdicts with each estimator."""
    path = suite_dir / CALIBRATION_FILE
    if not path.is_file():
        return [
            f"Not run: `python -m dqfd_bc_keras.experiments calibrate --out SUITE/{CALIBRATION_FILE}` measures "
            "the estimators into the suite directory SUITE, `run estimators --out SUITE` trains with them."
        ]
    summary = json.loads(path.read_text())
    figure(summary, figures_dir / "calibration.png")
    link = os.path.relpath(figures_dir / "calibration.png", markdown_dir)
    rows = verdict_rows(arms)
    return [
        f"σ²(s) − σ0² of the bayes BC model with each estimator (uncertainty.py), mean over {summary['seeds']} "
        f"fits on each task's demonstrations, on {summary['episodes']} episodes of each kind of state; the goal "
        f"(docs/PREREGISTRATION.md §8) is ≥ {summary['goal_ratio']:g} × the held-out value on random-policy "
        "states and on states 3–6 std away. The largest value any estimator can take is (1 − 1/A)/A "
        "(0.25 for CartPole's two actions, 0.22 for MountainCar's three).",
        "",
        *table(summary),
        "",
        f"Best other estimator (the pre-registered pick): **{summary['best_other']}**.",
        "",
        f"![calibration]({link})",
        "",
        "With each estimator, bayes against ce under the claims' rules (§4) and the seeds of §5, and on the "
        "sample-efficiency protocol (§3): interactions to threshold median [95% CI] (∞ = never), ce's median ÷ "
        "this arm's [95% CI] (> 1: this arm is faster), final evaluation.",
        "",
        "| setting | estimator | seeds (bayes, ce) | verdict | MC dropout's verdict | interactions to threshold "
        "| ce ÷ it | final eval |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
        *(rows or ["| — | no estimator arms have run | | | | | | |"]),
    ]
