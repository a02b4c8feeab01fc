"""What the lab judges each task by, keyed by task name: the core's task registry knows nothing of it.

A task without settings of its own has `NO_SETTINGS`: in no suite, no teacher rule, no ablations,
the default sample-efficiency goal. A user's task gets its own from their module:

    from dqfd_bc_keras.experiments.lab_settings import LabSettings, register_lab_settings

    register_lab_settings("short-pole", LabSettings(target_ratio=3.0))
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.tasks import find_preset


@dataclass(frozen=True)
class LabSettings:
    """What the lab judges a task by; every field optional."""

    efficiency_demos: int | None = None
    """Demonstrated episodes of the imperfect expert in the sample-efficiency suite; None: not in it."""
    target_ratio: float = 10.0
    """The sample-efficiency goal: SB3's median interactions to threshold ÷ ours ≥ this."""
    teacher_return: float | None = None
    """The imperfect expert's mean plain return over 100 episodes (seeds 0–99), which the efficiency
    report compares our final returns with; pinned by tests/test_efficiency.py."""
    grid_teachers: Mapping[tuple[str, float], float] = field(default_factory=dict)
    """(expert, ε) → mean plain return over 100 episodes of each teacher of the quality × quantity
    grid (`python -m dqfd_bc_keras.demos.experts --episodes 100 --epsilon ε`), pinned by tests/test_grid.py."""
    ablation_metric: str | None = None
    """The metric the ablations are judged on (ablations.py's ABLATION_MARGINS); None: no ablations."""
    calibrate: bool = False
    """Whether the σ² estimators are calibrated on this task (estimators.py)."""


NO_SETTINGS = LabSettings()
LAB_SETTINGS: dict[str, LabSettings] = {
    "cartpole": LabSettings(
        efficiency_demos=5,
        target_ratio=10.0,
        ablation_metric="mean_train_return",
        calibrate=True,
        grid_teachers={
            ("strong", 0.0): 500.0,
            ("imperfect", 0.0): 198.06,
            ("strong", 0.2): 495.54,
            ("strong", 0.5): 169.67,
        },
    ),
    "mountaincar": LabSettings(
        efficiency_demos=10,
        target_ratio=10.0,
        calibrate=True,
        grid_teachers={
            ("strong", 0.0): -106.39,
            ("imperfect", 0.0): -120.02,
            ("strong", 0.2): -145.22,
            ("strong", 0.5): -189.23,
        },
    ),
    "mountaincar-goals": LabSettings(ablation_metric="goals_first30"),
    "acrobot": LabSettings(efficiency_demos=10, target_ratio=5.0, teacher_return=-112.68),
    "lunarlander": LabSettings(efficiency_demos=10, target_ratio=5.0, teacher_return=129.03),
    "minatar-breakout": LabSettings(target_ratio=5.0, grid_teachers={("strong", 0.0): 79.93, ("imperfect", 0.0): 8.58}),
    "minatar-freeway": LabSettings(grid_teachers={("strong", 0.0): 65.85, ("imperfect", 0.0): 15.72}),
}
"""Every task with settings by name, the package's presets first, in the order they are registered."""


def register_lab_settings(task: str, settings: LabSettings) -> LabSettings:
    """Give `task` (a preset's registered name, or a Gymnasium id) its lab settings, from a user's module."""
    if not isinstance(settings, LabSettings):
        raise ConfigError(f"register_lab_settings() takes LabSettings, got {type(settings).__name__}")
    LAB_SETTINGS[task] = settings
    return settings


def lab_settings(task: str) -> LabSettings:
    """The settings of `task` as a config names it (`module:preset` imports `module` first, which
    registers them); NO_SETTINGS where none are registered."""
    preset = find_preset(task)
    return LAB_SETTINGS.get(task if preset is None else preset.name, NO_SETTINGS)
