"""The bookkeeping of a run's episodes, in Python: the running episode's tallies, everything a
checkpoint saves besides the TensorFlow state, and CartPole's early-stopping rule."""

from __future__ import annotations

import dataclasses
import math
import typing
from dataclasses import dataclass, field
from typing import Any

from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.training.records import DemoUpdate, EpisodeRow, EvalRow


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

    def to_dict(self) -> dict[str, Any]:
        """state.json's object: the records as their files spell them."""
        fields = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        return {**fields, **{name: [record.to_row() for record in fields[name]] for name in RECORDS}}

    @classmethod
    def from_dict(cls, fields: dict[str, Any]) -> TrainingState:
        """The state a state.json holds; keys it does not know are ignored. A value of the wrong
        type raises TypeError naming its key (a resume reports it rather than fail mid-run)."""
        if not isinstance(fields, dict):
            raise TypeError(f"state.json must hold an object, got {type(fields).__name__}")
        known = {f.name: fields[f.name] for f in dataclasses.fields(cls) if f.name in fields}
        hints = typing.get_type_hints(cls)
        for name, value in known.items():
            if name not in RECORDS and not _is(value, hints[name]):
                kind = hints[name]
                shown = kind.__name__ if isinstance(kind, type) else kind
                raise TypeError(f"{name} must be {shown}, got {value!r:.60}")
        for name, record in RECORDS.items():
            rows = known.get(name, [])
            if not isinstance(rows, list) or not all(isinstance(row, dict) for row in rows):
                raise TypeError(f"{name} must be a list of objects, got {rows!r:.60}")
            known[name] = [record.from_row(row) for row in rows]
        return cls(**known)


RECORDS = {"metrics": EpisodeRow, "evals": EvalRow, "demo_updates": DemoUpdate}
"""TrainingState's lists of records and the record of each."""


def _is(value: Any, kind: Any) -> bool:
    """Whether a JSON value is of type `kind` (int, float, bool or list[float]; an int counts as a
    float, a bool as nothing but a bool)."""
    if typing.get_origin(kind) is list:
        return isinstance(value, list) and all(_is(v, typing.get_args(kind)[0]) for v in value)
    if kind is bool or isinstance(value, bool):
        return kind is bool and isinstance(value, bool)
    return isinstance(value, int) if kind is int else isinstance(value, (int, float))


def early_stop(config: Config, returns: list[float]) -> bool:
    """CartPole's rule: the last `early_stop_window` episodes all return ≥ fraction × limit."""
    n = config.early_stop_window
    threshold = config.early_stop_fraction * config.limit
    return n > 0 and len(returns) >= n and min(returns[-n:]) >= threshold
