"""The task registry's types and functions (the package's presets are in the family modules)."""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Protocol, SupportsIndex

import numpy as np

from dqfd_bc_keras.choices import EXPERT_NAMES
from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.plugins import PluginError, import_module, parse


class Rule(Protocol):
    """A demonstrator's rule: a preset's scripted expert, or a user's own (`--expert module:function`,
    a function given to `record` or `DQfD`). It takes the observation as the networks see it
    (flattened; frames as they are) and answers an action in [0, n): an int, a numpy integer or a
    0-d integer array (not a bool); `demos.recording.Demonstrator` checks the answer."""

    def __call__(self, obs: np.ndarray, /) -> SupportsIndex: ...


NOT_REMADE = ("python callable ", "demonstrations from ")
"""How a config names demonstrations that no later process can make again (a Python function
recorded in the process that ran, a dataset given from Python): accepted as an `expert`, never
made again; such a run's D_demo is kept in its checkpoints (runs.GIVEN_DEMOS)."""
DEFAULT_EXPERT = "imperfect"
"""Config's default `expert`; a preset without an expert of that name demonstrates with its first one."""
ENV_DEFAULTS: Mapping[str, object] = {
    "demo_episodes": 10,
    "total_steps": 100_000,
    "eval_every": 5_000,
    "early_stop_window": 0,
}
"""The Config defaults of any Gymnasium env that is not a preset (`--env ID`): no early stop,
10 demonstrated episodes, 100k steps, an evaluation every 5k. Ours, not the paper's."""


@dataclass(frozen=True)
class TaskSpec:
    """A task: which plain env, which shaping, which step limit, its defaults and its experts."""

    name: str
    env_id: str
    """The plain Gymnasium env; evaluation scores on it, unmodified."""
    family: str | None = None
    """The family whose scripted experts play it (the name demonstrators carry); None: no experts."""
    max_steps: int | None = None
    """The step limit; None only for an env without a `TimeLimit` of its own (set `max_steps`)."""
    fall_penalty: float | None = None
    """Reward added on a termination that is a failure (CartPole's fall), ALGORITHM.md §6."""
    goal_reward: float | None = None
    """Reward added on reaching the goal (the MountainCar goal-count variant), §6."""
    solved_return: float | None = None
    """The plain env's "solved" threshold (its spec's `reward_threshold`); None when it has none."""
    defaults: Mapping[str, object] = field(default_factory=dict)
    """The preset's Config defaults where they differ from Config's shared ones."""
    method_defaults: Mapping[str, Mapping[str, object]] = field(default_factory=dict)
    """Expert loss → its own defaults on this preset, over `defaults`, read when that method runs: where a
    tuned set beat the preset's defaults on fresh seeds (docs/PREREGISTRATION.md §16, docs/TASKS.md)."""
    experts: Mapping[str, Rule] = field(default_factory=dict, repr=False)
    """Scripted demonstrators by name (strong, imperfect)."""
    keys: Mapping[str, int] = field(default_factory=dict)
    """The keys a person plays with (`demos play`): pygame key names, "+"-joined for keys held
    together, "" for no key pressed → action (demos/keys.py)."""
    fps: float | None = None
    """Steps per second a person plays at (`demos play --fps`); None: the env's own rate."""
    quick: Mapping[str, object] = field(default_factory=dict)
    """What `train.py --quick` sets on this task besides `config.QUICK` (an Atari game's step limit)."""
    doc: str = ""

    @property
    def gym_id(self) -> str:
        """The id under which the preset is registered with Gymnasium."""
        return f"{ID_NAMESPACE}/{self.name}-v0"

    @property
    def goal_count(self) -> bool:
        return self.goal_reward is not None


ID_NAMESPACE = "dqfd_bc_keras"
TASKS: dict[str, TaskSpec] = {}
"""Every registered preset by name, in the order registered."""


def register_task(spec: TaskSpec) -> TaskSpec:
    """Add a preset (a user's own, from their module); returns it as registered: a preset with
    scripted experts but none called `DEFAULT_EXPERT`, whose defaults name no `expert`, gets its
    first expert as its default demonstrator (a preset with one expert just uses it)."""
    if not isinstance(spec, TaskSpec):
        raise ConfigError(f"register_task() takes a TaskSpec, got {type(spec).__name__}")
    if spec.experts and DEFAULT_EXPERT not in spec.experts and "expert" not in spec.defaults:
        spec = dataclasses.replace(spec, defaults={**spec.defaults, "expert": next(iter(spec.experts))})
    TASKS[spec.name] = spec
    return spec


def find_preset(name: str) -> TaskSpec | None:
    """The preset `name`, or `module:preset` after importing `module` (which registers it); None if
    `name` is no preset (it may still be a Gymnasium id)."""
    if name in TASKS:
        return TASKS[name]
    parsed = parse(name)
    if parsed is None:
        return None
    module, bare = parsed
    if bare not in TASKS:
        try:
            import_module(module, f"task {name!r}")
        except PluginError:
            return None  # `envs.env_task` reports it, as it does for a Gymnasium id's module
    return TASKS.get(bare)


def check_demonstrator(spec: str, task: TaskSpec) -> None:
    """A `ConfigError` unless `spec` names a demonstrator for `task`: a scripted expert's name,
    a rule `module:function` or a `.keras` model file (what each is, is checked when it is made)."""
    scripted = tuple(dict.fromkeys((*EXPERT_NAMES, *task.experts)))
    if (
        spec not in scripted
        and not spec.endswith(".keras")
        and not re.fullmatch(r"[\w.]+:\w+", spec)
        and not spec.startswith(NOT_REMADE)
    ):
        raise ConfigError(f"expert={spec!r} is none of {', '.join(scripted)}, module:function or a .keras model file")


def family_preset(family: str) -> TaskSpec:
    """The first preset of `family` with scripted experts: it names the family's plain env and experts."""
    for spec in TASKS.values():
        if spec.family == family and spec.experts:
            return spec
    raise ConfigError(f"unknown family {family!r}; families with scripted experts: {', '.join(families())}")


def families() -> list[str]:
    """Every family with scripted experts, in the order registered."""
    return list(dict.fromkeys(s.family for s in TASKS.values() if s.family and s.experts))
