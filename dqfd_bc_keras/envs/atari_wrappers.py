"""The wrappers of Atari's DQN preprocessing (`atari.wrap_atari` puts them together; atari.py's
docstring says how they differ from CleanRL's and SB3's).

    AtariFrames    no-op starts, each action repeated with the last two frames max-pooled, the
                   grey screen area-averaged
    EpisodicLife   a lost life ends the episode; the next reset continues the game
    ClipReward     the reward becomes sign(r)
    StackFrames    the last frames stacked on the last axis, newest last
"""

from __future__ import annotations

from typing import Any, SupportsFloat

import gymnasium as gym
import numpy as np

from dqfd_bc_keras.errors import ConfigError

NOOP = 0
"""The ALE's action 0 in every game's minimal action set."""


def area_weights(n_in: int, n_out: int) -> np.ndarray:
    """The (n_out, n_in) matrix that area-averages a length-n_in line to n_out cells (cv2's
    INTER_AREA): cell i covers [i, i + 1) * n_in / n_out, each pixel counts by its overlap."""
    edges = np.arange(n_out + 1) * (n_in / n_out)
    pixels = np.arange(n_in + 1)
    overlap = np.minimum(edges[1:, None], pixels[None, 1:]) - np.maximum(edges[:-1, None], pixels[None, :-1])
    return np.clip(overlap, 0.0, None) * (n_out / n_in)


class AtariFrames(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """No-op starts, frame skipping with max-pooling, and the frame shrunk to `screen_size`².

    A reset takes 1..`noop_max` NOOP frames (the count drawn from the env's `np_random`, so
    `reset(seed=s)` fixes it); a step repeats the action `frame_skip` frames (fewer if the
    game ends), sums their rewards and max-pools the last two frames (Atari sprites flicker
    between frames), then area-averages the (210, 160) grey screen to `screen_size`².
    `info["noops"]` at a reset is the count taken. An env observing the RAM (a 1-D uint8 Box)
    gets the no-op starts and the skip, and each step observes its last frame's RAM as it is.
    """

    def __init__(self, env: gym.Env, noop_max: int = 30, frame_skip: int = 4, screen_size: int = 84) -> None:
        gym.utils.RecordConstructorArgs.__init__(
            self, noop_max=noop_max, frame_skip=frame_skip, screen_size=screen_size
        )
        gym.Wrapper.__init__(self, env)
        space = env.observation_space
        if not (isinstance(space, gym.spaces.Box) and len(space.shape) in (1, 2) and space.dtype == np.uint8):
            raise ConfigError(
                f"Atari preprocessing needs a grey uint8 screen (obs_type='grayscale') or the RAM "
                f"(obs_type='ram'), got {space}"
            )
        if getattr(env.unwrapped, "_frameskip", 1) != 1:
            raise ConfigError("Atari preprocessing needs the ALE env made with frameskip=1: it skips frames itself")
        meanings = getattr(env.unwrapped, "get_action_meanings", None)
        if noop_max and meanings is not None and meanings()[NOOP] != "NOOP":
            raise ConfigError(f"no-op starts need action {NOOP} to be NOOP, it is {meanings()[NOOP]}")
        self.noop_max, self.frame_skip = int(noop_max), int(frame_skip)
        self.ram = len(space.shape) == 1
        if not self.ram:
            self._rows = area_weights(space.shape[0], screen_size).astype(np.float32)
            self._cols = area_weights(space.shape[1], screen_size).T.astype(np.float32)
            self.observation_space = gym.spaces.Box(0, 255, (screen_size, screen_size), np.uint8)

    def reset(self, **kwargs: Any) -> tuple[np.ndarray, dict[str, Any]]:
        frame, info = self.env.reset(**kwargs)
        noops = int(self.env.unwrapped.np_random.integers(1, self.noop_max + 1)) if self.noop_max else 0
        for _ in range(noops):
            frame, _, terminated, truncated, info = self.env.step(NOOP)
            if terminated or truncated:
                frame, info = self.env.reset(**kwargs)
        info["noops"] = noops
        return self._shrink(frame), info

    def step(self, action: Any) -> tuple[np.ndarray, SupportsFloat, bool, bool, dict[str, Any]]:
        total, last_two = 0.0, list[np.ndarray]()
        for _ in range(self.frame_skip):
            frame, reward, terminated, truncated, info = self.env.step(action)
            total += float(reward)
            last_two = [*last_two[-1:], frame]
            if terminated or truncated:
                break
        frame = last_two[-1] if self.ram else np.max(last_two, axis=0)
        return self._shrink(frame), total, terminated, truncated, info

    def _shrink(self, frame: np.ndarray) -> np.ndarray:
        """The area average in float32 (as cv2 computes it; the two differ by at most one grey level);
        the RAM as it is."""
        if self.ram:
            return frame
        return np.clip(np.rint(self._rows @ frame.astype(np.float32) @ self._cols), 0, 255).astype(np.uint8)


class EpisodicLife(gym.Wrapper):
    """A lost life ends the episode (terminated=True); the next reset continues the game.

    DeepMind's DQN trick (SB3's EpisodicLifeEnv): the learner sees the end of a life as the
    end of its return, while all of the game stays reachable. `info["lives"]` counts them;
    a drop to 0 is left to the game's own end (some games sit at 0 lives for a few frames).
    A reset right after a lost life returns that step's observation and `info` with
    `new_game=False` and ignores its arguments; any other reset is a real one (`new_game=True`).
    """

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.lives = 0
        self._continues: tuple[Any, dict[str, Any]] | None = None

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        if self._continues is not None:
            (obs, info), self._continues = self._continues, None
            return obs, {**info, "new_game": False}
        obs, info = self.env.reset(**kwargs)
        self.lives = int(info["lives"])
        return obs, {**info, "new_game": True}

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        lives = int(info["lives"])
        life_lost = 0 < lives < self.lives
        self.lives = lives
        self._continues = (obs, dict(info)) if life_lost and not (terminated or truncated) else None
        return obs, reward, terminated or life_lost, truncated, info


class ClipReward(gym.Wrapper):
    """The reward becomes sign(r) in {-1, 0, 1} (DQN's clipping); `info["plain_reward"]` is r."""

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        info.setdefault("plain_reward", float(reward))
        return obs, float(np.sign(float(reward))), terminated, truncated, info


class StackFrames(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """The last `frame_stack` frames on the last axis, newest last; a reset fills the stack
    with copies of its frame, so next_obs[..., :-1] == obs[..., 1:] and a reset stack is one
    frame repeated (what lets the replay store each frame once)."""

    def __init__(self, env: gym.Env, frame_stack: int = 4) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, frame_stack=frame_stack)
        gym.Wrapper.__init__(self, env)
        self.frame_stack = int(frame_stack)
        shape = (*(env.observation_space.shape or ()), self.frame_stack)
        self.observation_space = gym.spaces.Box(0, 255, shape, np.uint8)
        self._stack = np.zeros(self.observation_space.shape, np.uint8)

    def reset(self, **kwargs: Any) -> tuple[np.ndarray, dict[str, Any]]:
        frame, info = self.env.reset(**kwargs)
        self._stack = np.repeat(frame[..., None], self.frame_stack, axis=-1)
        return self._stack, info

    def step(self, action: Any) -> tuple[np.ndarray, SupportsFloat, bool, bool, dict[str, Any]]:
        frame, reward, terminated, truncated, info = self.env.step(action)
        self._stack = np.concatenate([self._stack[..., 1:], frame[..., None]], axis=-1)  # a new array each step
        return self._stack, reward, terminated, truncated, info
