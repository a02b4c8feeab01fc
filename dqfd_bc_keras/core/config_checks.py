"""What each Config field takes, in one place: its type, read from the dataclass annotation (and
`--set`'s text read as that type), the names a string setting may take, and each number's range,
in one table.

`Config.validate` applies them wherever a Config is made (the constructor, `for_task`, `from_dict`
for a config.json, `with_overrides` for `--set`, `DQfD(...)`), so a bad value from any source is
one `ConfigError` naming the field, what it got and what it takes. A bool is no integer, and an
integral float (64.0) no integer either: a float where a count goes is a computation gone wrong
(`n / 2`), and JSON written by a run never holds one."""

from __future__ import annotations

import functools
import json
import math
import numbers
import typing
from collections.abc import Callable
from typing import Any

from dqfd_bc_keras.choices import DYNAMIC_MODES, PRIOR_CENTERS, TARGETS, TD_LOSSES, TIMEOUT_MODES, TORSOS, UNCERTAINTIES
from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.seeds import MAX_SEED

Config = Any
"""A `core.config.Config`: that module imports this one, so this one names it without importing it."""


def check(config: Config) -> None:
    """Raise ConfigError for the first field of the wrong type, name outside its choices or number
    out of its range; each typed field is set to its plain Python value (an int given to a float
    field as a float, a list given to a tuple field as a tuple, a numpy integer as an int)."""
    annotations = _annotations(type(config))  # type: ignore[arg-type]  # a class is hashable: python/mypy#20409
    for name, kind in annotations.items():
        setattr(config, name, typed(name, kind, getattr(config, name)))
    if not config.method.q_learning:
        raise ConfigError(
            f"expert_loss={config.expert_loss!r} trains no Q-network: behavioural cloning alone is "
            "run by the lab's imitation arms (python -m dqfd_bc_keras.experiments grid)"
        )
    for name, allowed in CHOICES.items():
        if getattr(config, name) not in allowed:
            raise ConfigError(f"{name}={getattr(config, name)!r} is not one of {allowed}")
    for name, ok, expected in ranges(config):
        if not ok:
            raise ConfigError(f"{name} must be {expected}, got {getattr(config, name)!r}")


def typed(name: str, kind: Any, value: Any) -> Any:
    """`value` as a field `name` annotated `kind` holds it, or a ConfigError saying what it takes."""
    held = _as(kind, value)
    if held is _WRONG:
        raise ConfigError(f"{name} must be {_words(kind)}, got {value!r:.100}")
    return held


@functools.cache
def _annotations(cls: type) -> dict[str, Any]:
    """Each field's type, resolved once (the module's `from __future__ import annotations` leaves strings)."""
    return typing.get_type_hints(cls)


KINDS: dict[type, tuple[str, str, Callable[[Any], bool]]] = {
    bool: ("True or False", "booleans", lambda v: isinstance(v, bool)),
    int: ("an integer", "integers", lambda v: isinstance(v, numbers.Integral) and not isinstance(v, bool)),
    float: (
        "a finite number",
        "finite numbers",
        lambda v: isinstance(v, numbers.Real) and not isinstance(v, bool) and math.isfinite(v),
    ),
    str: ("a string", "strings", lambda v: isinstance(v, str)),
}
"""Each plain type of a field: its name in a message (one, many) and whether a value is of it."""
JSON_OBJECT = (
    "a JSON object of keyword arguments (string keys; values null, true, false, finite numbers, "
    "strings, lists, tuples or objects)"
)
_WRONG = object()
"""What `_as` answers for a value not of the kind."""


def _as(kind: Any, value: Any) -> Any:
    """`value` as `kind` (a plain type, `X | None`, `tuple[X, ...]` or `dict[str, Any]`), else _WRONG."""
    args = typing.get_args(kind)
    if type(None) in args:
        return None if value is None else _as(next(a for a in args if a is not type(None)), value)
    if typing.get_origin(kind) is tuple:
        items = [_as(args[0], item) for item in value] if isinstance(value, (list, tuple)) else [_WRONG]
        return _WRONG if any(item is _WRONG for item in items) else tuple(items)
    if typing.get_origin(kind) is dict:
        return value if _is_json_object(value) else _WRONG
    return kind(value) if KINDS[kind][2](value) else _WRONG


def _words(kind: Any) -> str:
    """What a field of type `kind` takes, in words."""
    args = typing.get_args(kind)
    if type(None) in args:
        return f"{_words(next(a for a in args if a is not type(None)))} or None"
    if typing.get_origin(kind) is tuple:
        return f"a list of {KINDS[args[0]][1]}"
    if typing.get_origin(kind) is dict:
        return JSON_OBJECT
    return KINDS[kind][0]


def _is_json_object(value: Any) -> bool:
    """Whether JSON writes `value` as an object and reads it back as itself: string keys, values of
    JSON's kinds (a tuple would come back a list), no NaN or infinity (no JSON has them)."""
    try:
        return isinstance(value, dict) and json.loads(json.dumps(value, allow_nan=False)) == value
    except (TypeError, ValueError):  # an object JSON cannot write, NaN, a circular reference
        return False


def parsed(key: str, annotation: str, text: str) -> object:
    """`--set key=text` as the type the dataclass annotation `annotation` names (`none` for None
    where it allows None): the value is then checked with the rest, as `typed` checks any."""
    optional = annotation.endswith("| None")
    if optional and text.lower() == "none":
        return None
    base = annotation.removesuffix(" | None")
    if base.startswith("dict"):
        try:
            value = json.loads(text)
        except json.JSONDecodeError:
            value = None
        if not isinstance(value, dict):
            raise ConfigError(f"--set {key}={text!r}: expected a JSON object, e.g. {key}='{{\"use_lidar\": false}}'")
        return value
    try:
        if base == "bool":
            if text.lower() not in ("true", "false", "1", "0"):
                raise ValueError(text)
            return text.lower() in ("true", "1")
        if base.startswith("tuple"):
            return tuple(int(part) for part in text.split(",") if part)
        return {"int": int, "float": float, "str": str}[base](text)
    except ValueError:
        raise ConfigError(f"--set {key}={text!r}: expected {annotation}") from None


CHOICES = {
    "timeout": TIMEOUT_MODES,
    "target": TARGETS,
    "td_loss": TD_LOSSES,
    "prior_center": PRIOR_CENTERS,
    "dynamic_demos": DYNAMIC_MODES,
    "uncertainty": UNCERTAINTIES,
    "torso": TORSOS,
}
"""The names each string setting may take (expert_loss's are the methods' registry, expert's the task's)."""


def ranges(c: Config) -> list[tuple[str, bool, str]]:
    """(field, whether its value is in range, the range in words), in the order checked."""
    return [
        ("seed", 0 <= c.seed <= MAX_SEED, f"in [0, {MAX_SEED}]"),
        ("gamma", 0.0 <= c.gamma <= 1.0, "in [0, 1]"),
        ("n_step", c.n_step >= 1, "≥ 1"),
        ("lambda_n", c.lambda_n >= 0, "≥ 0"),
        ("lambda_expert", c.lambda_expert >= 0, "≥ 0"),
        ("lambda_l2", c.lambda_l2 >= 0, "≥ 0"),
        ("margin", c.margin >= 0, "≥ 0"),
        ("batch_size", c.batch_size >= 1, "≥ 1"),
        ("mc_passes", c.mc_passes >= 1, "≥ 1"),
        ("ensemble_members", c.ensemble_members >= 2, "≥ 2 (a variance needs two members)"),
        (
            "mc_dropout",
            c.mc_dropout or c.uncertainty == "mc_dropout",
            "True when uncertainty is not mc_dropout (False ablates the MC-dropout estimator)",
        ),
        ("expert_epsilon", 0.0 <= c.expert_epsilon <= 1.0, "in [0, 1]"),
        ("sigma0_sq", c.sigma0_sq > 0, "> 0"),
        ("temperature", c.temperature > 0, "> 0"),
        ("prior_scale", c.prior_scale > 0, "> 0"),
        ("bc_prior_scale", c.bc_prior_scale > 0, "> 0"),
        ("bc_dropout", 0.0 <= c.bc_dropout < 1.0, "in [0, 1)"),
        ("learning_rate", c.learning_rate > 0, "> 0"),
        ("bc_learning_rate", c.bc_learning_rate > 0, "> 0"),
        ("bc_epochs", c.bc_epochs >= 1, "≥ 1 (the first fit of the BC model)"),
        ("target_update_period", c.target_update_period >= 1, "≥ 1"),
        ("pretrain_steps", c.pretrain_steps >= 0, "≥ 0"),
        ("replay_capacity", c.replay_capacity >= c.n_step, "≥ n_step"),
        (
            "demo_capacity",
            not c.uses_demos or c.demo_capacity >= c.limit,  # no D_demo without demos
            f"≥ the episode limit {c.limit}",
        ),
        ("priority_alpha", c.priority_alpha >= 0, "≥ 0"),
        ("priority_beta0", 0.0 <= c.priority_beta0 <= 1.0, "in [0, 1]"),
        ("beta_anneal_steps", c.beta_anneal_steps >= 1, "≥ 1"),
        ("priority_eps_agent", c.priority_eps_agent > 0, "> 0"),
        ("priority_eps_demo", c.priority_eps_demo > 0, "> 0"),
        ("max_steps", c.max_steps is None or c.max_steps >= 1, "≥ 1 or None"),
        ("demo_episodes", c.demo_episodes >= 1, "≥ 1"),
        ("dynamic_window", c.dynamic_window >= 1, "≥ 1"),
        ("dynamic_rollouts", c.dynamic_rollouts >= 1, "≥ 1"),
        ("bc_refit_epochs", c.bc_refit_epochs >= 0, "≥ 0"),
        ("total_steps", c.total_steps >= 1, "≥ 1"),
        ("train_freq", c.train_freq >= 1, "≥ 1"),
        ("epsilon_start", c.epsilon_start is None or 0 <= c.epsilon_start <= 1, "in [0, 1] or None"),
        ("epsilon_end", 0.0 <= c.epsilon_end <= 1.0, "in [0, 1]"),
        ("epsilon_fraction", 0.0 < c.epsilon_fraction <= 1.0, "in (0, 1]"),
        ("early_stop_window", c.early_stop_window >= 0, "≥ 0"),
        ("early_stop_fraction", 0.0 < c.early_stop_fraction <= 1.0, "in (0, 1] (of the episode limit)"),
        ("eval_every", c.eval_every >= 1, "≥ 1"),
        ("eval_episodes", c.eval_episodes >= 1, "≥ 1"),
        ("final_eval_episodes", c.final_eval_episodes >= 1, "≥ 1"),
        ("checkpoint_every", c.checkpoint_every >= 1, "≥ 1"),
        ("hidden", len(c.hidden) >= 1 and min(c.hidden) >= 1, "a non-empty list of positive sizes"),
        ("bc_hidden", len(c.bc_hidden) >= 1 and min(c.bc_hidden) >= 1, "a non-empty list of positive sizes"),
    ]
