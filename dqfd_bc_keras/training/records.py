"""What a run records, typed: one row per episode, one per evaluation, one per dynamic-demonstration
update, and the demonstrations it started from. `runs/directory.py` writes them, the lab parses them back.

A record's columns are its field names (a trailing `_` dropped: `return_` is the column `return`),
so the CSV headers and JSON keys are spelled here and only here. Every file holds every column; a
field typed `… | None` may be empty (an empty CSV cell, a JSON null), and only such a field has a
default. No TensorFlow, no numpy: reading a run's files needs neither.
"""

from __future__ import annotations

import dataclasses
import functools
import types
import typing
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, TypeVar

R = TypeVar("R", bound="Record")


class Record:
    """Columns, rows and parsing for a frozen dataclass of numbers, strings and lists of numbers;
    a field that is itself a Record contributes its own columns in its place."""

    @classmethod
    def columns(cls) -> tuple[str, ...]:
        """The column names in order: what a CSV header or a JSON object of the record holds."""
        return tuple(
            column
            for name, kind in _fields(cls)  # type: ignore[arg-type]  # a class is hashable: python/mypy#20409
            for column in (kind.columns() if _is_record(kind) else (_column(name),))
        )

    def to_row(self) -> dict[str, Any]:
        """Column → value, in column order (values as they are: the writer formats them)."""
        row: dict[str, Any] = {}
        for name, kind in _fields(type(self)):  # type: ignore[arg-type]  # a class is hashable: python/mypy#20409
            value = getattr(self, name)
            row.update(value.to_row() if _is_record(kind) else {_column(name): value})
        return row

    @classmethod
    def from_row(cls: type[R], row: Mapping[str, Any]) -> R:
        """Parse a CSV row (strings) or a JSON object (numbers): each value converted to its
        field's type, an empty cell to None where the field may be None, unknown columns ignored.
        A missing column raises KeyError naming it; a bad value ValueError."""
        return cls(**{name: parse(row) for name, parse in _parsers(cls)})  # type: ignore[arg-type]  # python/mypy#20409

    def __getitem__(self, column: str) -> Any:
        """The value of `column` (as the file spells it), for code that picks a column by name."""
        path = _paths(type(self)).get(column)  # type: ignore[arg-type]  # a class is hashable: python/mypy#20409
        if path is None:
            raise KeyError(column)
        value: Any = self
        for name in path:
            value = getattr(value, name)
        return value


@functools.cache
def _fields(cls: type) -> list[tuple[str, Any]]:
    """(name, type) of each field of record class `cls`, resolved once per class: `get_type_hints`
    costs far more than parsing a row, and the lab parses hundreds of thousands of them."""
    hints = typing.get_type_hints(cls)
    return [(f.name, hints[f.name]) for f in dataclasses.fields(cls)]


def _column(name: str) -> str:
    return name.removesuffix("_")


def _is_record(kind: Any) -> bool:
    return isinstance(kind, type) and issubclass(kind, Record)


@functools.cache
def _paths(cls: type) -> dict[str, tuple[str, ...]]:
    """column → the attribute names that lead to it from a record of class `cls` (nested records
    flattened, as `columns` and `to_row` flatten them)."""
    paths: dict[str, tuple[str, ...]] = {}
    for name, kind in _fields(cls):
        if _is_record(kind):
            paths.update({column: (name, *path) for column, path in _paths(kind).items()})
        else:
            paths[_column(name)] = (name,)
    return paths


@functools.cache
def _parsers(cls: type) -> list[tuple[str, Callable[[Mapping[str, Any]], Any]]]:
    """(name, row → value) of each field of record class `cls`, built once per class: the lab parses
    millions of cells, and reading a field's type for each of them cost more than the parsing."""
    return [(name, kind.from_row if _is_record(kind) else _cell(_column(name), kind)) for name, kind in _fields(cls)]


def _cell(column: str, kind: Any) -> Callable[[Mapping[str, Any]], Any]:
    """row → its `column` as `kind` (int, float, str, list[float], or any of them | None)."""
    optional = isinstance(kind, types.UnionType)
    base = next(k for k in typing.get_args(kind) if k is not type(None)) if optional else kind
    convert: Callable[[Any], Any] = base
    if typing.get_origin(base) is list:
        convert = functools.partial(_floats, column)
    elif base is int:
        convert = _int

    def parse(row: Mapping[str, Any]) -> Any:
        value = row[column]
        if value is None or value == "":
            if optional:
                return None
            raise ValueError(f"{column} has no value")
        return convert(value)

    return parse


def _floats(column: str, value: Any) -> list[float]:
    if not isinstance(value, list):
        raise ValueError(f"{column} must be a list, got {value!r}")
    return [float(v) for v in value]


def _int(value: Any) -> int:
    return int(float(value)) if isinstance(value, str) else int(value)


@dataclass(frozen=True)
class Losses(Record):
    """The agent's loss terms, each a mean over the episode's gradient steps (NaN: none taken)."""

    loss: float
    """J(Q), the weighted sum of the terms below."""
    td: float
    n_step: float
    expert: float
    l2: float


@dataclass(frozen=True, kw_only=True)
class EpisodeRow(Record):
    """metrics.csv: one training episode, as it ended."""

    episode: int
    env_step: int
    """The learner's env steps so far (what ε and the budget count)."""
    interactions: int
    """Every interaction so far, dynamic-demonstration roll-outs included."""
    return_: float
    """Under the task's rewards (what the learner sees)."""
    plain_return: float
    """Under the plain env's rewards (what the field reports)."""
    length: int
    goals: int
    epsilon: float
    losses: Losses
    demo_size: int
    """Transitions in D_demo after the episode."""
    wall_time: float
    """Seconds of training so far."""
    imitation_weight_demo: float | None = None
    """The Bayesian likelihood's weight 1/(2σ²(s)) averaged over D_demo's rows after the episode
    (None: none recorded. The method reads no σ², or the run is one of docs/data's archived runs
    that did not log the weights: their value is not known.)"""
    imitation_weight_agent: float | None = None
    """The same over D_replay's rows, the agent's own states (None also while D_replay is empty)."""


@dataclass(frozen=True, kw_only=True)
class EvalRow(Record):
    """evals.csv: one greedy evaluation on the plain env, logged at one grid point of interactions."""

    env_step: int
    interactions: int
    episode: int
    mean_return: float
    std_return: float
    mean_goals: float | None = None
    """None where the task counts no goals (an empty cell)."""


@dataclass(frozen=True, kw_only=True)
class DemoUpdate(Record):
    """dynamic_demos.json: one update of D_demo with the agent's best episodes."""

    episode: int
    env_step: int
    interactions: int
    moving_average: float
    mode: str
    """`episodes` or `rollouts` (Config.dynamic_demos)."""
    new_returns: list[float]
    new_transitions: int
    demo_transitions: int
    demo_episodes: int
    bc_accuracy: float


DEMO_SOURCES = ("recorded", "file", "minari", "python")
"""Where a run's demonstrations come from: recorded from its `expert` at the start, a file of ours
given to it (`train.py --demos FILE`), a Minari dataset (`--demos minari:ID`), or a `DemoDataset`
object given from Python (`DQfD(env, demos=dataset)`)."""


@dataclass(frozen=True, kw_only=True)
class DemoSummary(Record):
    """demonstrations.json: the D_demo a run started from, before any dynamic demonstration."""

    transitions: int
    episodes: int
    expert: str
    """The demonstrator its metadata names (for a Minari dataset, `minari:ID`)."""
    episode_returns: list[float]
    plain_returns: list[float]
    """Return of each episode under the plain env's rewards."""
    pretrain_steps: int
    source: str
    """One of DEMO_SOURCES."""

    def __post_init__(self) -> None:
        if not self.plain_returns:
            raise ValueError("no episode in plain_returns")
        if self.source not in DEMO_SOURCES:
            raise ValueError(f"source {self.source!r} is not one of {DEMO_SOURCES}")
