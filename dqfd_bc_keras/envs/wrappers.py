"""The Gymnasium wrappers of a task env: the paper's reward shaping, the time-limit modes (the
bootstrap fix is `TimeLimitMode`), the time feature, and the count of interactions.

    FallPenalty (CartPole) or GoalCount (MountainCar goal variant)   reward shaping
    TimeLimitMode                                                    the step limit, in one of three modes
    TimeFeature                                                      time-aware mode's observation
    ForgetLastAction                                                 MinAtar: an episode independent of the last
    CountInteractions                                                every env a learner's data comes from

`envs.make_task` stacks them; each one knows nothing of learning.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np

from dqfd_bc_keras.choices import TIMEOUT_MODES
from dqfd_bc_keras.envs.minatar_pixels import minatar_game
from dqfd_bc_keras.errors import ConfigError


class FallPenalty(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """CartPole: the step on which the pole falls pays `penalty` (paper: −100) instead of +1.

    Place it inside `TimeLimitMode`: it then sees only the physics' terminations, so a
    truncation at the time limit never gets the penalty.
    """

    def __init__(self, env: gym.Env, penalty: float = -100.0) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, penalty=penalty)
        gym.Wrapper.__init__(self, env)
        self.penalty = float(penalty)

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        info.setdefault("plain_reward", float(reward))
        if terminated:
            reward = self.penalty
        return obs, reward, terminated, truncated, info


class GoalCount(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """MountainCar, the paper's Figs. 9–11 metric: count how often the car reaches the flag.

    Reaching the flag pays `goal_reward` (+100) instead of −1, puts the car back at a fresh
    start state (position uniform in [−0.6, −0.4], velocity 0, as `reset` would) and does
    not end the episode, which runs on to its step limit. `info["goals"]` is the running
    count; the plain reward stops at the first goal, where MountainCar-v0 would have ended.
    """

    def __init__(self, env: gym.Env, goal_reward: float = 100.0) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, goal_reward=goal_reward)
        gym.Wrapper.__init__(self, env)
        self.goal_reward = float(goal_reward)
        self.goals = 0

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        self.goals = 0
        info["goals"] = 0
        return obs, info

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        info.setdefault("plain_reward", 0.0 if self.goals else float(reward))
        if terminated:
            self.goals += 1
            reward = self.goal_reward
            car: Any = self.env.unwrapped  # MountainCar's, whose `state` no Env declares
            car.state = np.array([car.np_random.uniform(low=-0.6, high=-0.4), 0.0])
            obs = np.array(car.state, dtype=np.float32)
            terminated = False
        info["goals"] = self.goals
        return obs, reward, terminated, truncated, info


class TimeLimitMode(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """End episodes after `max_steps` steps; `mode` (one of `TIMEOUT_MODES`) says how.

    At the limit, unless the physics terminated on that same step:
    `bootstrap` → truncated=True, terminated=False; `naive` and `time-aware` → terminated=True
    (`make_task` adds `TimeFeature` in time-aware mode, so that there the state shows the
    time left). `info["time_limit"]` is True on the step where the limit was hit.
    """

    def __init__(self, env: gym.Env, max_steps: int, mode: str = "bootstrap") -> None:
        if mode not in TIMEOUT_MODES:
            raise ConfigError(f"unknown timeout mode {mode!r}; expected one of {TIMEOUT_MODES}")
        if int(max_steps) < 1:
            raise ConfigError(f"max_steps must be ≥ 1, got {max_steps}")
        gym.utils.RecordConstructorArgs.__init__(self, max_steps=max_steps, mode=mode)
        gym.Wrapper.__init__(self, env)
        self.max_steps = int(max_steps)
        self.mode = mode
        self._t = 0

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        self._t = 0
        return self.env.reset(**kwargs)

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        info.setdefault("plain_reward", float(reward))  # no shaping wrapper inside: unchanged
        self._t += 1
        if self._t >= self.max_steps and not terminated:
            info["time_limit"] = True
            if self.mode == "bootstrap":
                truncated = True
            else:
                terminated = True
        return obs, reward, terminated, truncated, info


class TimeFeature(gym.ObservationWrapper, gym.utils.RecordConstructorArgs):
    """Append the remaining-time fraction max(0, 1 − t/max_steps) to the observation.

    1 at reset, 0 at the limit (Pardo et al. 2018). Also used to evaluate a time-aware agent
    on the plain env, whose own limit may differ from the one it was trained with.
    """

    def __init__(self, env: gym.Env, max_steps: int) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, max_steps=max_steps)
        gym.ObservationWrapper.__init__(self, env)
        self.max_steps = int(max_steps)
        self._t = 0
        space = env.observation_space
        assert isinstance(space, gym.spaces.Box)  # vectors: frames take no time feature (`network_input`)
        self.observation_space = gym.spaces.Box(
            low=np.append(space.low, 0.0).astype(np.float32),
            high=np.append(space.high, 1.0).astype(np.float32),
            dtype=np.float32,
        )

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        self._t = 0
        return super().reset(**kwargs)

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        self._t += 1
        return super().step(action)

    def observation(self, observation: np.ndarray) -> np.ndarray:
        remaining = max(0.0, 1.0 - self._t / self.max_steps)
        return np.append(observation, remaining).astype(np.float32)


class ForgetLastAction(gym.Wrapper):
    """MinAtar: each reset also resets the sticky action's memory.

    MinAtar repeats the previous action with probability 0.1, and its `reset` keeps that previous
    action from the last episode: an episode's first step then depends on how the one before it
    ended, so `reset(seed=s)` alone does not fix an episode. This makes it what a fresh env does
    (the no-op, MinAtar's initial `last_action`)."""

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        minatar_game(self.env).last_action = 0
        return self.env.reset(**kwargs)


@dataclass
class Tally:
    """A count shared by the envs of one learner: the interactions its data came from."""

    count: int = 0


class CountInteractions(gym.Wrapper):
    """Adds each `step` to a shared `Tally`.

    Every env whose transitions a learner may train on (the training loop's, the dynamic
    demonstrations' roll-outs, random play that scales the inputs) is wrapped with the same
    tally, so the total of interactions is counted in one place however the data arrives.
    """

    def __init__(self, env: gym.Env, tally: Tally) -> None:
        super().__init__(env)
        self.tally = tally

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        self.tally.count += 1
        return self.env.step(action)
