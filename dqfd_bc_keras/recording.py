"""Recording demonstrations: any demonstrator (a scripted expert, a rule `module:function`, a
saved `.keras` model, the agent's greedy policy, the agent itself while it trains) played on a
task env, its complete episodes kept as a dataset.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from .demo_data import ARRAYS, DemoDataset, DemoMeta
from .envs import get_task, make_task, task_spaces
from .errors import ConfigError
from .experts import make_demonstrator


def record(
    task: str,
    expert: str,
    episodes: int,
    seed: int = 0,
    epsilon: float = 0.0,
    timeout: str = "bootstrap",
    max_steps: int | None = None,
    env_kwargs: dict[str, Any] | None = None,
) -> DemoDataset:
    """Run the demonstrator `expert` (`experts.make_demonstrator`: strong | imperfect |
    module:function | model.keras) for `episodes` episodes of `task` made with `env_kwargs`,
    `max_steps` steps at most; episode i resets with seed + i."""
    if episodes < 1:
        raise ConfigError(f"episodes must be ≥ 1, got {episodes}")
    policy = make_demonstrator(expert, task, epsilon=epsilon, seed=seed, env_kwargs=env_kwargs)
    env = make_task(task, timeout=timeout, max_steps=max_steps, env_kwargs=env_kwargs)
    dataset = rollout(env, policy, [seed + i for i in range(episodes)], task=task, source=expert,
                      epsilon=epsilon, seed=seed, env_kwargs=env_kwargs)
    env.close()
    return dataset


class EpisodeRecorder:
    """Transitions of complete episodes as they are played, turned into a dataset on demand.

    One recorder serves scripted demonstrations, greedy roll-outs and the agent's own training
    episodes (dynamic demonstrations), so every D_demo episode has the same layout and meta.
    """

    def __init__(self, env, *, task: str, source: str, epsilon: float = 0.0, seed: int = 0,
                 env_kwargs: dict[str, Any] | None = None) -> None:
        self.task, self.source, self.epsilon, self.seed = task, source, float(epsilon), int(seed)
        self.env_kwargs = dict(env_kwargs or {})
        shape = env.observation_space.shape
        self.frames = len(shape) > 1  # envs.make_task flattens all but frames
        self.obs_dim, self.n_actions = int(np.prod(shape)), int(env.action_space.n)
        self.obs_shape = [int(n) for n in shape] if self.frames else None
        self.timeout = env.get_wrapper_attr("mode")
        self.clear()

    def clear(self) -> None:
        """Forget every recorded episode (and the one being played)."""
        self.columns: dict[str, list] = {name: [] for name in ARRAYS}
        self.returns: list[float] = []
        self.plain_returns: list[float] = []
        self.open = 0

    def reset(self, obs: np.ndarray) -> None:
        """A new episode starts in `obs`; an unfinished one before it is dropped."""
        for column in self.columns.values():
            del column[len(column) - self.open:]
        self.obs, self.open, self.ret, self.plain = obs, 0, 0.0, 0.0

    def step(self, action: int, next_obs: np.ndarray, reward: float, terminated: bool, truncated: bool,
             info: dict) -> None:
        values = (self.obs, action, reward, next_obs, terminated, truncated, len(self.returns))
        for name, value in zip(ARRAYS, values):
            self.columns[name].append(value)
        self.obs, self.open = next_obs, self.open + 1
        self.ret += float(reward)
        self.plain += info["plain_reward"]
        if terminated or truncated:
            self.returns.append(self.ret)
            self.plain_returns.append(self.plain)
            self.open = 0

    def dataset(self) -> DemoDataset:
        """The complete episodes recorded so far (an episode still being played is left out)."""
        if not self.returns:
            raise ConfigError("no complete episode has been recorded")
        end = len(self.columns["actions"]) - self.open
        meta = DemoMeta(
            task=self.task, env_id=get_task(self.task).env_id, timeout=self.timeout, obs_dim=self.obs_dim,
            n_actions=self.n_actions, expert=self.source, epsilon=self.epsilon, seed=self.seed,
            episode_returns=list(self.returns), plain_returns=list(self.plain_returns),
            env_kwargs=dict(self.env_kwargs), observation=task_spaces(self.task, self.env_kwargs).layout.text(),
            obs_shape=self.obs_shape,
        )
        dtypes = {name: dtype for name, (dtype, _) in ARRAYS.items()} | {"obs": meta.obs_dtype, "next_obs": meta.obs_dtype}
        arrays = {name: np.asarray(self.columns[name][:end], dtype=dtypes[name]) for name in ARRAYS}
        return DemoDataset(**arrays, meta=meta)


def rollout(
    env, policy: Callable[[np.ndarray], int], seeds: Sequence[int], *, task: str, source: str,
    epsilon: float = 0.0, seed: int = 0, env_kwargs: dict[str, Any] | None = None,
) -> DemoDataset:
    """One complete episode of `policy` on the task env `env` per seed, as a dataset.

    `source` names the demonstrator in the metadata (a scripted expert, or the agent's
    greedy policy for dynamic demonstrations); `env_kwargs` are those `env` was made with.
    """
    recorder = EpisodeRecorder(env, task=task, source=source, epsilon=epsilon, seed=seed, env_kwargs=env_kwargs)
    for episode_seed in seeds:
        obs, _ = env.reset(seed=int(episode_seed))
        recorder.reset(obs)
        done = False
        while not done:
            action = policy(obs)
            obs, reward, terminated, truncated, info = env.step(action)
            recorder.step(action, obs, reward, terminated, truncated, info)
            done = terminated or truncated
    return recorder.dataset()
