"""Writes tests/data/suite.tar.xz: a tiny synthetic suite for the report's golden test.

    .venv/bin/python tests/data/make_suite.py

cartpole/naive: bayes and ce (3 seeds; runs stop early at different episodes, one never does)
and plain DQN (2 seeds); mountaincar-goals/bootstrap: bayes and ce (2 seeds, 40 episodes). Runs
carry demonstrations.json, provenance.json (two code commits, one dirty run, one run trained
outside a git checkout) and one dynamic_demos.json; the suite a sweep log. The run files are
written by `runs/writers.py`, the writer of real runs. Numbers come from a seeded generator, so
the archive only changes when this script does; regenerate the golden RESULTS.md after it
(see tests/test_report.py).
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.envs.episodes import EvalResult
from dqfd_bc_keras.experiments.data import export_archive
from dqfd_bc_keras.runs.writers import (
    write_config,
    write_demonstrations,
    write_dynamic_demos,
    write_evals,
    write_metrics,
)
from dqfd_bc_keras.training.records import DemoSummary, DemoUpdate, EpisodeRow, EvalRow, Losses

ARCHIVE = Path(__file__).with_name("suite.tar.xz")
COMMITS = ("1f0c2a9e8d7b6c5a4f3e2d1c0b9a8f7e6d5c4b3a", "2b3c4d5e6f708192a3b4c5d6e7f8091a2b3c4d5e")
RULES = "9e8d7c6b5a4f3e2d1c0b9a8f7e6d5c4b3a2f1e0d"


def cartpole_lengths(rng: np.random.Generator, solve_at: int | None, episodes: int = 45) -> list[int]:
    """Rising episode lengths; with `solve_at`, 10 episodes of 500 end the run there (early stop)."""
    if solve_at is None:
        return [int(min(480, 20 + 10 * e + rng.integers(0, 40))) for e in range(episodes)]
    climb = [int(min(480, 20 + 500 * e / (solve_at - 10) + rng.integers(0, 40))) for e in range(solve_at - 10)]
    return climb + [500] * 10


def write_run(
    root: Path,
    name: str,
    config: Config,
    rows: list[dict],
    final: list[float],
    rng: np.random.Generator,
    provenance: dict,
    dynamic: bool = False,
) -> None:
    run = root / name / f"seed{config.seed}"
    run.mkdir(parents=True)
    write_config(config, run)
    steps = [int(s) for s in np.cumsum([r["length"] for r in rows])]
    write_metrics(
        run,
        [
            EpisodeRow(
                episode=i + 1,
                env_step=steps[i],
                interactions=steps[i],
                return_=r["return"],
                plain_return=r["plain_return"],
                length=r["length"],
                goals=r["goals"],
                epsilon=0.01,
                losses=Losses(0.0, 0.0, 0.0, 0.0, 0.0),
                demo_size=0,
                wall_time=round(1.5 * (i + 1), 1),
            )
            for i, r in enumerate(rows)
        ],
    )
    write_evals(
        run,
        [
            EvalRow(env_step=s, interactions=s, episode=i, mean_return=float(m), std_return=0.0)
            for i, (s, m) in enumerate(zip((0, steps[len(steps) // 2], steps[-1]), final, strict=True))
        ],
    )
    returns = [float(final[-1])] * 4
    result = EvalResult(
        config.task,
        "q",
        1_010_000,
        returns,
        [200] * 4,
        [1] * 4 if config.task == "mountaincar-goals" else None,
        config.timeout,
    )
    (run / "eval.json").write_text(json.dumps(result.to_dict(), indent=1))
    if config.uses_demos:
        lengths = [int(x) for x in rng.integers(150, 250, config.demo_episodes)]
        plain = [float(-n) if config.task.startswith("mountaincar") else float(n) for n in lengths]
        write_demonstrations(
            run,
            DemoSummary(
                transitions=sum(lengths),
                episodes=len(lengths),
                expert=config.expert,
                episode_returns=plain,
                plain_returns=plain,
                pretrain_steps=config.pretrain_steps,
                source="recorded",
            ),
        )
    if dynamic:
        write_dynamic_demos(
            run,
            [
                DemoUpdate(
                    episode=episode,
                    env_step=steps[episode - 1],
                    interactions=steps[episode - 1],
                    moving_average=average,
                    mode="episodes",
                    new_returns=[500.0] * (new // 500),
                    new_transitions=new,
                    demo_transitions=size,
                    demo_episodes=size // 500,
                    bc_accuracy=0.9,
                )
                for episode, average, new, size in ((12, 300.0, 1500, 2500), (20, 450.0, 2500, 5000))
            ],
        )
    (run / "provenance.json").write_text(json.dumps(provenance, indent=1))


def build(root: Path) -> None:
    rng = np.random.default_rng(0)
    clean = {"code_commit": COMMITS[0], "rules_commit": RULES, "dirty": False, "versions": {"python": "3.11"}}
    outside_git = {**clean, "code_commit": None, "rules_commit": None, "dirty": None}
    for loss, solves in (("bayes", (25, 32, None)), ("ce", (28, None, 40))):
        for seed, solve_at in enumerate(solves):
            lengths = cartpole_lengths(rng, solve_at)
            rows = [{"return": float(n), "plain_return": float(n), "length": n, "goals": 0} for n in lengths]
            provenance = {**clean, "code_commit": COMMITS[1], "dirty": True} if (loss, seed) == ("ce", 2) else clean
            write_run(
                root,
                f"cartpole-naive-{loss}",
                Config.for_task("cartpole", timeout="naive", expert_loss=loss, seed=seed),
                rows,
                [40.0, 300.0, 480.0 if solve_at else 350.0],
                rng,
                provenance,
                dynamic=(loss, seed) == ("bayes", 0),
            )
    for seed in range(2):
        rows = [{"return": 30.0, "plain_return": 30.0, "length": 30, "goals": 0}] * 45
        write_run(
            root,
            "cartpole-naive-none",
            Config.for_task("cartpole", timeout="naive", expert_loss="none", seed=seed),
            rows,
            [20.0, 25.0, 30.0],
            rng,
            outside_git if seed == 1 else clean,
        )
    for loss, rate in (("bayes", 0.5), ("ce", 0.3)):
        for seed in range(2):
            goals = [int(g) for g in rng.binomial(2, rate, 40)]
            rows = [
                {"return": 100.0 * g - 200.0, "plain_return": -200.0 + 40.0 * g, "length": 200, "goals": g}
                for g in goals
            ]
            write_run(
                root,
                f"mountaincar-goals-bootstrap-{loss}",
                Config.for_task("mountaincar-goals", expert_loss=loss, seed=seed),
                rows,
                [-200.0, -150.0, -120.0],
                rng,
                clean,
            )
    sweeps = [
        {
            "suite": "paper",
            "seeds": 3,
            "runs": 10,
            "workers": 2,
            "backend": "local",
            "seconds": 123.4,
            "ended": "2026-12-01 10:00:00",
            **clean,
        },
        {
            "suite": "baselines",
            "seeds": 2,
            "runs": 2,
            "workers": 2,
            "backend": "local",
            "seconds": 45.6,
            "ended": "2026-12-01 10:05:00",
            **clean,
            "code_commit": COMMITS[1],
            "dirty": True,
        },
    ]
    (root / "sweeps.jsonl").write_text("".join(json.dumps(s) + "\n" for s in sweeps))


if __name__ == "__main__":
    with tempfile.TemporaryDirectory() as tmp:
        build(Path(tmp) / "suite")
        names = export_archive(Path(tmp) / "suite", ARCHIVE)
    print(f"wrote {ARCHIVE}: {len(names)} files, {ARCHIVE.stat().st_size:,} bytes")
