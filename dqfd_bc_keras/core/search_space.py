"""Where a hyperparameter search may look: one `Dimension` per Config field, the shared ones here
and each method's beside it (`Method.space` in methods.py, over the fields it `reads`).

The ranges bracket each default by about an order of magnitude where the field is a scale (log),
and by what the algorithm can use where it is a count; they are ours, chosen before any study ran.
Nothing here imports Optuna: `tuning/space.py` turns a dimension into a trial's suggestion.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from dqfd_bc_keras.errors import ConfigError

if TYPE_CHECKING:
    from dqfd_bc_keras.core.methods import Method


@dataclass(frozen=True)
class Span:
    """low ≤ value ≤ high, an int or a float as the Config field is; `log`: sampled on a log scale."""

    low: float
    high: float
    log: bool = False

    def __post_init__(self) -> None:
        if not self.low < self.high or (self.log and self.low <= 0):
            raise ConfigError(
                f"a range needs low < high{' and low > 0 on a log scale' if self.log else ''}, "
                f"got low={self.low}, high={self.high}"
            )

    def as_json(self) -> dict:
        return {"low": self.low, "high": self.high, **({"log": True} if self.log else {})}


@dataclass(frozen=True)
class Choice:
    """One of `values` (JSON values: a list stands for a tuple field's tuple)."""

    values: tuple

    def __post_init__(self) -> None:
        if len(self.values) < 2:
            raise ConfigError(f"a choice needs at least two values, got {list(self.values)}")

    def as_json(self) -> dict:
        return {"choices": list(self.values)}


Dimension = Span | Choice
Space = dict[str, Dimension]


def applies_always(method: Method) -> bool:
    return True


def has_expert_loss(method: Method) -> bool:
    return method.term is not None


def samples_demos_by_priority(method: Method) -> bool:
    """D_demo's share of a batch follows the priorities (ε_d) for every method with demonstrations
    but SQIL, which draws half of each batch from each replay."""
    return method.needs_demos and not method.sqil_rewards


SHARED: dict[str, tuple[Dimension, Callable[[Method], bool]]] = {
    "learning_rate": (Span(1e-4, 3e-3, log=True), applies_always),
    "n_step": (Span(1, 20), applies_always),
    "batch_size": (Choice((32, 64, 128)), applies_always),
    "target_update_period": (Span(50, 2_000, log=True), applies_always),
    "train_freq": (Span(1, 4), applies_always),
    "epsilon_end": (Span(0.0, 0.1), applies_always),
    "epsilon_fraction": (Span(0.02, 0.5, log=True), applies_always),
    "lambda_expert": (Span(0.1, 10.0, log=True), has_expert_loss),
    "priority_eps_demo": (Span(0.01, 10.0, log=True), samples_demos_by_priority),
}
"""The fields every method's search varies (each where it applies to the method: λ2 where there is
a J_E; ε_d, which sets the demonstrations' share of each prioritized batch, where there are
demonstrations sampled by priority; the package has no fixed demonstration ratio). The update frequency is
`train_freq`; the ε schedule, where it ends and how fast it gets there."""


def method_space(method: Method) -> Space:
    """The default search space of `method`: the shared fields that apply to it, then its own."""
    shared = {name: dimension for name, (dimension, applies) in SHARED.items() if applies(method)}
    return {**shared, **dict(method.space)}


def check_own(name: str, space: Sequence[tuple[str, Dimension]], reads: Sequence[str]) -> None:
    """A method's own space ranges over fields it reads, and nothing the shared space has."""
    for field, _ in space:
        if field not in reads:
            raise ConfigError(f"method {name!r}: its space names {field!r}, which is not among the fields it reads")
        if field in SHARED:
            raise ConfigError(f"method {name!r}: {field!r} is in the shared space already (search_space.SHARED)")
