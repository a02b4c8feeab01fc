"""Figures of a run (matplotlib, drawn off-screen)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .config import Config
from .envs import get_task
from .files import atomic_path


def plot_learning_curve(metrics: list[dict], evals: list[dict], config: Config, path: Path) -> None:
    """Training returns per episode (plain env's scale), their moving average, and the greedy
    evaluations, against environment steps, with the plain env's "solved" threshold."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    if metrics:
        steps = np.array([row["env_step"] for row in metrics])
        returns = np.array([row["plain_return"] for row in metrics], dtype=float)
        ax.plot(steps, returns, color="tab:blue", alpha=0.3, lw=1, label="training episode")
        window = min(config.dynamic_window, len(returns))
        average = np.convolve(returns, np.ones(window) / window, mode="valid")
        ax.plot(steps[window - 1:], average, color="tab:blue", lw=2, label=f"moving average ({window})")
    if evals:
        ax.plot([e["env_step"] for e in evals], [e["mean_return"] for e in evals], "o-", color="tab:orange",
                label="greedy evaluation")
    spec = get_task(config.task)
    ax.axhline(spec.solved_return, color="grey", ls="--", lw=1, label=f"solved ({spec.solved_return:g})")
    ax.set_xlabel("environment steps")
    ax.set_ylabel(f"return on {spec.env_id}")
    ax.set_title(f"{config.task} · {config.expert_loss} · timeout={config.timeout} · seed {config.seed}")
    ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=100)
    plt.close(fig)
