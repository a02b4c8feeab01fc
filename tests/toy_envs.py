"""Toy Gymnasium envs registered on import, for the tests of `--env ID` (any Gymnasium env).

`gym.make("toy_envs:ToyChain-v0")` imports this module first, so a subprocess with `tests/`
on its PYTHONPATH finds them as a user's own envs would be found.
"""

import gymnasium as gym
import numpy as np

N_STATES = 5


class Chain(gym.Env):
    """States 0 … 4 as one-hot vectors, start at 0; action 1 steps right, 0 left (floored at 0).
    Reaching state 4 pays 1 and terminates; every other step pays 0."""

    def __init__(self) -> None:
        self.observation_space = gym.spaces.Box(0.0, 1.0, (N_STATES,), np.float32)
        self.action_space = gym.spaces.Discrete(2)
        self.state = 0

    def _obs(self) -> np.ndarray:
        return np.eye(N_STATES, dtype=np.float32)[self.state]

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.state = 0
        return self._obs(), {}

    def step(self, action):
        self.state = max(0, self.state + (1 if action == 1 else -1))
        done = self.state == N_STATES - 1
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


def out_of_range(obs: np.ndarray) -> int:
    return 7


NOT_CALLABLE = 3

gym.register("ToyChain-v0", entry_point="toy_envs:Chain", max_episode_steps=20, reward_threshold=1.0)
gym.register("ToyChainNoLimit-v0", entry_point="toy_envs:Chain")
gym.register("ToyImage-v0", entry_point="toy_envs:Unsupported", kwargs={
    "observation_space": gym.spaces.Box(0, 255, (8, 8, 3), np.uint8), "action_space": gym.spaces.Discrete(2)})
gym.register("ToyDict-v0", entry_point="toy_envs:Unsupported", kwargs={
    "observation_space": gym.spaces.Dict({"x": gym.spaces.Box(-1.0, 1.0, (2,), np.float32)}),
    "action_space": gym.spaces.Discrete(2)})
