"""Deterministic scripted demonstrators for CartPole-v1, MountainCar-v0, Acrobot-v1 and
LunarLander-v3, and `make_demonstrator`, which also turns a user's rule (`module:function`) or a
saved `.keras` Q-network or BC model into a demonstrator for any task.

Each rule reads only the leading physical features of the observation, so it also works on
observations from a time-aware wrapper that appends a remaining-time feature at the end.
"""

from __future__ import annotations

import importlib
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import gymnasium as gym
import numpy as np

from .cli import ArgumentParser, positive_int, run
from .envs import get_task, task_spaces
from .errors import ConfigError

FAMILIES = ("cartpole", "mountaincar", "acrobot", "lunarlander")
"""Each family is named after the preset whose plain env its rules play."""
EXPERT_NAMES = ("strong", "imperfect")

Rule = Callable[[np.ndarray], int]


def cartpole_strong(obs: np.ndarray) -> int:
    """Push right iff θ + 0.5·θ̇ + 0.05·x + 0.1·ẋ > 0: PD balance on the pole (500/500) with small cart
    terms that keep the cart from drifting off the track, which matters once epsilon noise is added."""
    x, x_dot, theta, theta_dot = obs[0], obs[1], obs[2], obs[3]
    return int(theta + 0.5 * theta_dot + 0.05 * x + 0.1 * x_dot > 0.0)


def cartpole_imperfect(obs: np.ndarray) -> int:
    """Push right iff θ̇ > 0: damps the pole's swing but ignores its angle, so it drifts over (~200)."""
    return int(obs[3] > 0.0)


def mountaincar_strong(obs: np.ndarray) -> int:
    """Follow the velocity, but at rest push right only if x < −0.49: starting from the right side of
    the valley a first push left builds the swing in fewer steps (threshold measured, ~−106 mean)."""
    position, velocity = obs[0], obs[1]
    return 2 if velocity > 0.0 or (velocity == 0.0 and position < -0.49) else 0


def mountaincar_imperfect(obs: np.ndarray) -> int:
    """Push right iff v ≥ 0: pumps energy by following the velocity but always starts rightwards (~−120)."""
    return 2 if obs[1] >= 0.0 else 0


def acrobot_strong(obs: np.ndarray) -> int:
    """Torque +1 iff ω2 − 0.5·ω1 > 0: pumps energy with the second link's swing, against the
    first's (−78.7 ± 12.3 over 100 episodes, 95% of them at or above −100)."""
    return 2 if obs[5] - 0.5 * obs[4] > 0.0 else 0


def acrobot_imperfect(obs: np.ndarray) -> int:
    """Torque +1 iff ω2 + 0.3·ω1 > 0: the same pump with the first link's term of the wrong sign,
    which swings up more slowly on average (−112.7 ± 38.1, min −281)."""
    return 2 if obs[5] + 0.3 * obs[4] > 0.0 else 0


def lunar_lander_rule(s: np.ndarray, hover_gain: float = 0.5) -> int:
    """Gymnasium's `heuristic` for the discrete LunarLander (gymnasium/envs/box2d/lunar_lander.py),
    transcribed so it needs no Box2D; `hover_gain` is its 0.5 on the altitude error."""
    angle_targ = np.clip(s[0] * 0.5 + s[2] * 1.0, -0.4, 0.4)  # lean towards the pad, not too far
    hover_targ = 0.55 * np.abs(s[0])  # the farther from the pad, the higher
    angle_todo = (angle_targ - s[4]) * 0.5 - s[5] * 1.0
    hover_todo = (hover_targ - s[1]) * hover_gain - s[3] * 0.5
    if s[6] or s[7]:  # a leg touches: stop turning, only brake the fall
        angle_todo = 0.0
        hover_todo = -s[3] * 0.5
    if hover_todo > np.abs(angle_todo) and hover_todo > 0.05:
        return 2
    if angle_todo < -0.05:
        return 3
    if angle_todo > 0.05:
        return 1
    return 0


def lunarlander_strong(obs: np.ndarray) -> int:
    """Gymnasium's own heuristic (252.8 ± 78.5 over 100 episodes, 91% at or above 200)."""
    return lunar_lander_rule(obs)


def lunarlander_imperfect(obs: np.ndarray) -> int:
    """The heuristic with an over-eager altitude loop (gain 0.7 for 0.5), which fires the main
    engine more than it should (129.0 ± 135.0 over 100 episodes, 44% at or above 200)."""
    return lunar_lander_rule(obs, hover_gain=0.7)


RULES: dict[tuple[str, str], Rule] = {
    ("cartpole", "strong"): cartpole_strong,
    ("cartpole", "imperfect"): cartpole_imperfect,
    ("mountaincar", "strong"): mountaincar_strong,
    ("mountaincar", "imperfect"): mountaincar_imperfect,
    ("acrobot", "strong"): acrobot_strong,
    ("acrobot", "imperfect"): acrobot_imperfect,
    ("lunarlander", "strong"): lunarlander_strong,
    ("lunarlander", "imperfect"): lunarlander_imperfect,
}
N_ACTIONS = {"cartpole": 2, "mountaincar": 3, "acrobot": 3, "lunarlander": 4}


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
    _check_choice("family", family, FAMILIES)
    _check_choice("expert name", name, EXPERT_NAMES)
    return Demonstrator(f"{family}/{name}", RULES[family, name], N_ACTIONS[family], _check_epsilon(epsilon),
                        np.random.default_rng(seed))


def check_demonstrator(spec: str) -> None:
    """A `ConfigError` unless `spec` names a demonstrator: strong | imperfect | module:function | *.keras."""
    if spec not in EXPERT_NAMES and not spec.endswith(".keras") and not re.fullmatch(r"[\w.]+:\w+", spec):
        raise ConfigError(f"expert={spec!r} is none of {', '.join(EXPERT_NAMES)}, module:function or "
                          "a .keras model file")


def make_demonstrator(spec: str, task: str, epsilon: float = 0.0, seed: int | None = None,
                      env_kwargs: dict | None = None) -> Demonstrator:
    """The demonstrator `spec` on `task` (made with `env_kwargs`): a scripted expert of the task's
    family (strong | imperfect), a rule `module:function` (an importable function of the
    observation as the networks see it, flattened, → action), or the greedy policy of a saved
    `.keras` Q-network or BC model (checked against the task's spaces)."""
    check_demonstrator(spec)
    n_actions = task_spaces(task, env_kwargs).n_actions  # first: an env we cannot learn on is the error
    family = get_task(task).family
    if spec in EXPERT_NAMES:
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
    """Undiscounted returns of the expert on the plain env; episode i is reset with seed + i."""
    expert = make_expert(family, name, epsilon, seed)
    env = gym.make(get_task(family).env_id)
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


def main(argv: Sequence[str] | None = None) -> int:
    parser = ArgumentParser(prog="python -m dqfd_bc_keras.experts", description="Evaluate the scripted experts on the plain envs.")
    parser.add_argument("--episodes", type=positive_int, default=100)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--epsilon", type=float, default=0.0)
    args = parser.parse_args(argv)
    print("| family | expert | env id | episodes | mean ± std | min | max |")
    print("|---|---|---|---|---|---|---|")
    for family in FAMILIES:
        for name in EXPERT_NAMES:
            r = expert_returns(family, name, args.episodes, args.seed, args.epsilon)
            print(
                f"| {family} | {name} | {get_task(family).env_id} | {args.episodes} "
                f"| {r.mean():.2f} ± {r.std():.2f} | {r.min():.0f} | {r.max():.0f} |"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(run(main))
