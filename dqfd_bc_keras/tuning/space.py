"""A study's search space: the method's (`search_space.method_space`) less the fields the command
fixes, with a user's `--space FILE.json` over it; and a trial's params drawn from it.

`--space FILE.json` is a JSON object with one entry per field: `{"low": L, "high": H}` (with
`"log": true` for a log scale) ranges over the field, `{"choices": [...]}` picks among values,
a plain value fixes the field for every trial, and `null` takes the field out of the search (it
keeps its preset's default).
"""

from __future__ import annotations

import functools
import json
import typing
from pathlib import Path
from typing import TYPE_CHECKING, Any

from dqfd_bc_keras.core.config import Config, unknown_field
from dqfd_bc_keras.core.methods import get_method
from dqfd_bc_keras.core.search_space import Choice, Dimension, Space, Span, method_space
from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.files import read_json

if TYPE_CHECKING:
    import optuna


def read_space(path: str | Path) -> tuple[Space, dict[str, Any], set[str]]:
    """`--space FILE.json` as (dimensions, fixed values, fields taken out), each field checked as
    `--set` checks a key (a misspelt one gets the nearest field's name)."""
    data = read_json(path, "space file")
    if not isinstance(data, dict):
        raise ConfigError(f"--space {path}: expected a JSON object of fields, got {data!r:.80}")
    dimensions: Space = {}
    fixed: dict[str, Any] = {}
    dropped: set[str] = set()
    for field, entry in data.items():
        if field == "task" or field not in Config.__dataclass_fields__:
            why = "the task is chosen with --task or --env" if field == "task" else unknown_field(field)
            raise ConfigError(f"--space {path}: {why}")
        if entry is None:
            dropped.add(field)
        elif isinstance(entry, dict) and ("choices" in entry or "low" in entry or "high" in entry):
            dimensions[field] = _dimension(f"--space {path}: {field}", entry)
        else:
            fixed[field] = entry
    return dimensions, fixed, dropped


def _dimension(where: str, entry: dict) -> Dimension:
    keys = set(entry)
    try:
        if keys == {"choices"}:
            if not isinstance(entry["choices"], list):
                raise ConfigError(f"choices must be a list, got {entry['choices']!r:.60}")
            return Choice(tuple(tuple(v) if isinstance(v, list) else v for v in entry["choices"]))
        if keys in ({"low", "high"}, {"low", "high", "log"}):
            low, high, log = entry["low"], entry["high"], entry.get("log", False)
            if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in (low, high)):
                raise ConfigError(f"low and high must be numbers, got {low!r} and {high!r}")
            if not isinstance(log, bool):
                raise ConfigError(f"log must be true or false, got {log!r}")
            return Span(low, high, log)
    except ConfigError as error:
        raise ConfigError(f"{where}: {error}") from None
    raise ConfigError(
        f'{where}: expected {{"low": L, "high": H}} (with "log": true for a log scale) or {{"choices": [...]}}, '
        f"got keys {sorted(keys)}"
    )


def study_space(expert_loss: str, fixed: dict[str, Any], space_file: str | Path | None) -> tuple[Space, dict[str, Any]]:
    """The space a study searches and the fields it fixes: the method's space less the fields
    `fixed` (the command's `--set` and flags) names, then `space_file`'s entries over it."""
    space = {name: dimension for name, dimension in method_space(get_method(expert_loss)).items() if name not in fixed}
    fixed = dict(fixed)
    if space_file is not None:
        dimensions, pinned, dropped = read_space(space_file)
        both = sorted(set(dimensions) & set(fixed))
        if both:
            raise ConfigError(f"--space {space_file}: {both[0]} is fixed by the command (--set or a flag) and searched")
        space = {name: d for name, d in space.items() if name not in dropped and name not in pinned}
        space.update(dimensions)
        fixed.update(pinned)
    return space, fixed


def check_space(task: str, space: Space, fixed: dict[str, Any]) -> None:
    """Refuse, before any trial, a range whose end (or a choice) is a value the field cannot hold."""
    for field, dimension in space.items():
        ends = dimension.values if isinstance(dimension, Choice) else (dimension.low, dimension.high)
        if isinstance(dimension, Span) and _is_int(field) and not all(float(v).is_integer() for v in ends):
            raise ConfigError(f"the space's {field}: an integer field's range needs integer ends, got {list(ends)}")
        for value in ends:
            try:
                Config.for_task(task, **{**fixed, field: list(value) if isinstance(value, tuple) else value})
            except ConfigError as error:
                raise ConfigError(f"the space's {field}={value!r}: {error}") from None


@functools.cache
def _is_int(field: str) -> bool:
    kind = typing.get_type_hints(Config)[field]
    return kind is int or kind == (int | None)


def suggest(trial: optuna.Trial, space: Space) -> dict[str, Any]:
    """A trial's params: each field of `space` drawn by the study's sampler (integers as integers;
    a choice among tuples drawn by its JSON text, Optuna's categories being scalars)."""
    params: dict[str, Any] = {}
    for field, dimension in space.items():
        if isinstance(dimension, Choice):
            if all(isinstance(v, (str, int, float, bool)) or v is None for v in dimension.values):
                params[field] = trial.suggest_categorical(field, list(dimension.values))
            else:
                texts = [json.dumps(list(v) if isinstance(v, tuple) else v) for v in dimension.values]
                params[field] = json.loads(trial.suggest_categorical(field, texts))
        elif _is_int(field):
            params[field] = trial.suggest_int(field, int(dimension.low), int(dimension.high), log=dimension.log)
        else:
            params[field] = trial.suggest_float(field, float(dimension.low), float(dimension.high), log=dimension.log)
    return params


def as_json(space: Space) -> dict[str, dict]:
    """The space as `--space` writes it (a study records the space it searched)."""
    return {field: dimension.as_json() for field, dimension in space.items()}


def params_text(params: dict[str, Any]) -> str:
    """Params on one line, floats to 4 significant digits: `learning_rate=0.001126, n_step=2`."""
    return ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in params.items())
