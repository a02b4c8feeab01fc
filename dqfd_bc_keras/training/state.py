"""The bookkeeping of a run's episodes, in Python: the running episode's tallies, everything a
checkpoint saves besides the TensorFlow state, and CartPole's early-stopping rule."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.training.records import DemoUpdate, EpisodeRow, EvalRow, Record


@dataclass
class EpisodeStats:
    """Tallies of the running episode, kept by the env step in Python."""

    ret: float = 0.0
    plain: float = 0.0
    length: int = 0
    goals: int = 0

    def add(self, reward: float, info: dict) -> None:
        self.ret += reward
        self.plain += info["plain_reward"]
        self.length += 1
        self.goals = info.get("goals", self.goals)


@dataclass
class TrainingState:
    """Everything of a run that lives in Python; saved with each checkpoint (state.json)."""

    episode: int = 0
    interactions: int = 0
    """The learner's tally of interactions, as of the last checkpoint."""
    returns: list[float] = field(default_factory=list)
    best_average: float = -math.inf
    metrics: list[EpisodeRow] = field(default_factory=list)
    evals: list[EvalRow] = field(default_factory=list)
    demo_updates: list[DemoUpdate] = field(default_factory=list)
    next_eval: int = 0
    next_checkpoint: int = 0
    bc_fits: int = 0
    wall_time: float = 0.0
    stopped_early: bool = False
    expert_scale: float = 1.0
    """w_E of a method with a `decay` (methods.py), after the last episode; 1 for the others."""

    def to_dict(self) -> dict[str, Any]:
        """state.json's object: the records as their files spell them."""
        fields = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        return {**fields, **{name: [record.to_row() for record in fields[name]] for name in RECORDS}}

    @classmethod
    def from_dict(cls, fields: dict[str, Any]) -> TrainingState:
        """The state a state.json holds; keys it does not know are ignored. A value of the wrong type
        or an impossible one (a negative count, a NaN) raises ValueError naming its key: a resume
        reports it rather than fail mid-run, or rewrite the run's files from it."""
        if not isinstance(fields, dict):
            raise ValueError(f"state.json must hold an object, got {type(fields).__name__}")
        known = {f.name: fields[f.name] for f in dataclasses.fields(cls) if f.name in fields}
        for name, value in known.items():
            if name in RECORDS:
                known[name] = _records(name, value)
            elif not VALUES[name][1](value):
                raise ValueError(f"{name} must be {VALUES[name][0]}, got {value!r:.60}")
        return cls(**known)


RECORDS: dict[str, type[Record]] = {"metrics": EpisodeRow, "evals": EvalRow, "demo_updates": DemoUpdate}
"""TrainingState's lists of records and the record of each."""


def _records(name: str, rows: Any) -> list[Any]:
    """The list of records `name` of a state.json, or ValueError naming it and the row at fault."""
    if not isinstance(rows, list) or not all(isinstance(row, dict) for row in rows):
        raise ValueError(f"{name} must be a list of objects, got {rows!r:.60}")
    try:
        return [RECORDS[name].from_row(row) for row in rows]
    except KeyError as error:
        raise ValueError(f"{name}: a row has no {error}") from None
    except (TypeError, ValueError) as error:
        raise ValueError(f"{name}: {error}") from None


def _number(value: Any) -> bool:
    """A JSON number (a bool is none)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _count(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= 0


VALUES: dict[str, tuple[str, Callable[[Any], bool]]] = {
    "episode": ("an integer ≥ 0", _count),
    "interactions": ("an integer ≥ 0", _count),
    "returns": (
        "a list of finite numbers",
        lambda v: isinstance(v, list) and all(_number(r) and math.isfinite(r) for r in v),
    ),
    "best_average": (
        "a number (or -Infinity: no best yet)",
        lambda v: _number(v) and not math.isnan(v) and v < math.inf,
    ),
    "next_eval": ("an integer ≥ 0", _count),
    "next_checkpoint": ("an integer ≥ 0", _count),
    "bc_fits": ("an integer ≥ 0", _count),
    "wall_time": ("a finite number ≥ 0", lambda v: _number(v) and 0 <= v < math.inf),
    "stopped_early": ("true or false", lambda v: isinstance(v, bool)),
    "expert_scale": ("a number in [0, 1]", lambda v: _number(v) and 0 <= v <= 1),
}
"""What each of state.json's values (its records aside) must be, in words and as a test."""


def early_stop(config: Config, returns: list[float]) -> bool:
    """CartPole's rule: the last `early_stop_window` episodes all return ≥ fraction × limit."""
    n = config.early_stop_window
    threshold = config.early_stop_fraction * config.limit
    return n > 0 and len(returns) >= n and min(returns[-n:]) >= threshold
