"""Demonstrators: the task presets' scripted experts (each family's rules live in its module of
`tasks/`), and `make_demonstrator`, which also turns a user's rule (`module:function`) or a saved
`.keras` Q-network or BC model into a demonstrator for any task.

Each scripted rule reads only the leading physical features of the observation, so it also works
on observations from a time-aware wrapper that appends a remaining-time feature at the end.
"""

from __future__ import annotations

import importlib
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from .envs import get_task, task_spaces
from .errors import ConfigError
from .tasks import EXPERT_NAMES, Rule, check_demonstrator, families, family_preset


def _check_choice(kind: str, value: str, choices: Sequence[str]) -> None:
    if value not in choices:
        raise ConfigError(f"unknown {kind} {value!r}; valid choices: {', '.join(choices)}")


@dataclass(frozen=True)
class Demonstrator:
    """obs -> action: `rule`, replaced with prob. epsilon by a uniformly random action."""

    name: str
    rule: Rule = field(repr=False)
    n_actions: int
    epsilon: float
    rng: np.random.Generator = field(repr=False, compare=False)

    def __call__(self, obs: np.ndarray) -> int:
        if self.rng.random() < self.epsilon:
            return int(self.rng.integers(self.n_actions))
        action = self.rule(np.asarray(obs))
        if not (isinstance(action, (int, np.integer)) and 0 <= action < self.n_actions):
            raise ConfigError(f"demonstrator {self.name} returned {action!r}, not an action in [0, {self.n_actions})")
        return int(action)


def _check_epsilon(epsilon: float) -> float:
    if not 0.0 <= epsilon <= 1.0:
        raise ConfigError(f"epsilon must be in [0, 1], got {epsilon!r}")
    return float(epsilon)


def make_expert(family: str, name: str, epsilon: float = 0.0, seed: int | None = None) -> Demonstrator:
    """Build a validated expert whose random actions come from its own generator seeded with `seed`."""
    _check_choice("family", family, families())
    preset = family_preset(family)
    _check_choice("expert name", name, tuple(preset.experts))
    return Demonstrator(f"{family}/{name}", preset.experts[name], task_spaces(preset.name).n_actions,
                        _check_epsilon(epsilon), np.random.default_rng(seed))


def make_demonstrator(spec: str, task: str, epsilon: float = 0.0, seed: int | None = None,
                      env_kwargs: dict | None = None) -> Demonstrator:
    """The demonstrator `spec` on `task` (made with `env_kwargs`): a scripted expert of the task's
    family (strong | imperfect), a rule `module:function` (an importable function of the
    observation as the networks see it, flattened, → action), or the greedy policy of a saved
    `.keras` Q-network or BC model (checked against the task's spaces)."""
    check_demonstrator(spec, get_task(task))
    n_actions = task_spaces(task, env_kwargs).n_actions  # first: an env we cannot learn on is the error
    family = get_task(task).family
    if spec in EXPERT_NAMES or spec in get_task(task).experts:
        if family is None:
            raise ConfigError(f"{task} has no scripted {spec} expert: give demonstrations with --demos "
                              "FILE.npz or minari:DATASET_ID, or a demonstrator module:function or model.keras")
        return make_expert(family, spec, epsilon, seed)
    if spec.endswith(".keras"):
        from .evaluation import load_policy  # loads Keras: only when a model demonstrates

        rule: Rule = load_policy(spec, None, task, env_kwargs=env_kwargs or {})[0]
    else:
        module, _, name = spec.partition(":")
        try:
            rule = getattr(importlib.import_module(module), name)
        except (ImportError, AttributeError) as error:
            raise ConfigError(f"demonstrator {spec}: cannot import it ({type(error).__name__}: {error})") from None
        if not callable(rule):
            raise ConfigError(f"demonstrator {spec}: {name} is not callable")
    return Demonstrator(spec, rule, n_actions, _check_epsilon(epsilon), np.random.default_rng(seed))


def expert_returns(
    family: str, name: str, episodes: int = 100, seed: int = 0, epsilon: float = 0.0
) -> np.ndarray:
    """Undiscounted returns of the expert on the plain env (`envs.make_plain_env`: frames as
    uint8, the preset's limit where the env has none); episode i is reset with seed + i."""
    from .envs import make_plain_env  # envs imports this module

    expert = make_expert(family, name, epsilon, seed)
    env = make_plain_env(family_preset(family).name)
    returns = np.zeros(episodes, dtype=np.float64)
    try:
        for i in range(episodes):
            obs, _ = env.reset(seed=seed + i)
            done = False
            while not done:
                obs, reward, terminated, truncated, _ = env.step(expert(obs))
                returns[i] += float(reward)
                done = terminated or truncated
    finally:
        env.close()
    return returns


if __name__ == "__main__":
    from .commands.experts import cli

    raise SystemExit(cli())
