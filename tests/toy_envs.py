"""Toy Gymnasium envs registered on import, for the tests of `--env ID` (any Gymnasium env).

`gym.make("toy_envs:ToyChain-v0")` imports this module first, so a subprocess with `tests/`
on its PYTHONPATH finds them as a user's own envs would be found.
"""

import gymnasium as gym
import numpy as np

N_STATES = 5


class Chain(gym.Env):
    """States 0 … size − 1, start at 0; action 1 steps right, 0 left (floored at 0). Reaching
    the last state pays 1 and terminates; every other step pays 0.

    `observe` picks what the agent sees: "flat", the state one-hot (size,); "grid", the one-hot
    as a (size, 2) Box whose second column is 1 − the first; "dict", {"cell": Discrete(size),
    "mission": Text, "visits": MultiBinary(size)} (sorted: cell, mission, visits).
    """

    def __init__(self, size: int = N_STATES, observe: str = "flat") -> None:
        self.size, self.observe = size, observe
        self.observation_space = {
            "flat": gym.spaces.Box(0.0, 1.0, (size,), np.float32),
            "grid": gym.spaces.Box(0.0, 1.0, (size, 2), np.float32),
            "dict": gym.spaces.Dict(
                {
                    "cell": gym.spaces.Discrete(size),
                    "mission": gym.spaces.Text(20),
                    "visits": gym.spaces.MultiBinary(size),
                }
            ),
        }[observe]
        self.action_space = gym.spaces.Discrete(2)
        self.state = 0

    def _obs(self):
        one_hot = np.eye(self.size, dtype=np.float32)[self.state]
        if self.observe == "grid":
            return np.stack([one_hot, 1.0 - one_hot], axis=1)
        if self.observe == "dict":
            self.visits[self.state] = 1
            return {"cell": self.state, "mission": "walk right", "visits": self.visits.copy()}
        return one_hot

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.state = 0
        self.visits = np.zeros(self.size, np.int8)
        return self._obs(), {}

    def step(self, action):
        self.state = max(0, self.state + (1 if action == 1 else -1))
        done = self.state == self.size - 1
        return self._obs(), float(done), done, False, {}


class Unsupported(gym.Env):
    """A valid env with spaces our networks cannot take."""

    def __init__(self, observation_space: gym.Space, action_space: gym.Space) -> None:
        self.observation_space, self.action_space = observation_space, action_space

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return self.observation_space.sample(), {}

    def step(self, action):
        return self.observation_space.sample(), 0.0, True, False, {}


def go_right(obs: np.ndarray) -> int:
    """The chain's optimal demonstrator."""
    return 1


def go_left(obs: np.ndarray) -> int:
    """The chain's worst demonstrator: it never leaves state 0."""
    return 0


def out_of_range(obs: np.ndarray) -> int:
    return 7


NOT_CALLABLE = 3

gym.register("ToyChain-v0", entry_point="toy_envs:Chain", max_episode_steps=20, reward_threshold=1.0)
gym.register("ToyChainNoLimit-v0", entry_point="toy_envs:Chain")
gym.register("ToyDictChainNoLimit-v0", entry_point="toy_envs:Chain", kwargs={"observe": "dict"})
gym.register("ToyOldApiChain-v0", entry_point="toy_envs:OldApiChain", max_episode_steps=20)
gym.register("ToyVectorReward-v0", entry_point="toy_envs:VectorReward", max_episode_steps=20)
gym.register("ToyGridChain-v0", entry_point="toy_envs:Chain", max_episode_steps=20, kwargs={"observe": "grid"})
gym.register("ToyDictChain-v0", entry_point="toy_envs:Chain", max_episode_steps=20, kwargs={"observe": "dict"})
gym.register(
    "ToyImage-v0",
    entry_point="toy_envs:Unsupported",
    kwargs={  # frames inside a Dict: still refused
        "observation_space": gym.spaces.Dict(
            {
                "pixels": gym.spaces.Box(0, 255, (84, 84, 3), np.uint8),
                "speed": gym.spaces.Box(-1.0, 1.0, (1,), np.float32),
            }
        ),
        "action_space": gym.spaces.Discrete(2),
    },
)
gym.register(
    "ToyTextOnly-v0",
    entry_point="toy_envs:Unsupported",
    kwargs={
        "observation_space": gym.spaces.Dict({"mission": gym.spaces.Text(5)}),
        "action_space": gym.spaces.Discrete(2),
    },
)


def breakout_rule(obs: np.ndarray) -> int:
    """An Atari demonstrator for the tests (`--expert toy_envs:breakout_rule`): FIRE, then left or
    right by the newest frame's brightness, a deterministic function of the frame."""
    return 1 if obs[..., -1].sum() % 3 == 0 else 2 + int(obs[..., -1].sum() % 2)


def dies(obs: np.ndarray) -> int:
    """A demonstrator whose process dies the moment it is asked to act (`expert=toy_envs:dies`):
    the sweep's test of a worker that dies in the middle of a run."""
    import os

    os._exit(3)


def pole_rule(obs: np.ndarray) -> int:
    """CartPole: push the way the pole falls (its angular velocity's sign); about 200 of 500."""
    return int(obs[3] > 0)


class OldApiChain(Chain):
    """The chain written for gym 0.21: `reset()` takes no seed (`seed(s)` does) and returns the
    observation alone; `step` returns (obs, reward, done, info), its reward `np.array([r])`; the
    episode is cut after `cut` steps with `info["TimeLimit.truncated"]`, that API's convention."""

    def __init__(self, size: int = N_STATES, cut: int = 8) -> None:
        super().__init__(size)
        self.cut, self.seeded = cut, []

    def seed(self, seed=None):
        self.seeded.append(seed)
        return [seed]

    def reset(self):
        self.t = 0
        return super().reset()[0]

    def step(self, action):
        obs, reward, terminated, _, info = super().step(action)
        self.t += 1
        cut = self.t >= self.cut and not terminated
        return obs, np.array([reward], np.float32), terminated or cut, {"TimeLimit.truncated": cut} if cut else info


class LegacyChain:
    """The chain as a class of one's own for gym 0.21, not a `gymnasium.Env` (as a class of the old
    `gym` package is not): `reset()` returns the observation alone, `step` a 4-tuple with the reward
    as `np.array([r])`; Gymnasium's spaces."""

    observation_space = gym.spaces.Box(0.0, 1.0, (N_STATES,), np.float32)
    action_space = gym.spaces.Discrete(2)

    def __init__(self) -> None:
        self.position = 0

    def reset(self):
        self.position = 0
        return np.eye(N_STATES, dtype=np.float32)[0]

    def step(self, action):
        self.position = min(max(self.position + (1 if action == 1 else -1), 0), N_STATES - 1)
        done = self.position == N_STATES - 1
        return np.eye(N_STATES, dtype=np.float32)[self.position], np.array([float(done)]), done, {}


def legacy_chain() -> LegacyChain:
    """A factory of it, as `--env toy_envs:legacy_chain` takes one."""
    return LegacyChain()


class VectorReward(Chain):
    """The chain paying a reward of two values: no loop can know which one is the reward."""

    def step(self, action):
        obs, reward, terminated, truncated, info = super().step(action)
        return obs, np.array([reward, 0.0]), terminated, truncated, info


def wrapped_chain(size: int = N_STATES) -> gym.Env:
    """A factory, as a CLI user adds a wrapper (`--env toy_envs:wrapped_chain`): the chain in a
    wrapper of the user's, cut by a `TimeLimit` of 12 steps it keeps inside."""
    return gym.wrappers.TimeLimit(gym.wrappers.TransformReward(Chain(size), lambda r: 10.0 * r), 12)
