"""DQfD-BC's dynamic demonstrations (ALGORITHM.md §5): D_demo grows with the agent's best
episodes, and π_bc is refitted on it."""

from __future__ import annotations

import gymnasium as gym
import numpy as np

from dqfd_bc_keras.core.agent import DQfDAgent
from dqfd_bc_keras.core.bc import BCModel
from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.demos.dataset import DemoDataset, concatenate
from dqfd_bc_keras.demos.recording import rollout
from dqfd_bc_keras.evaluation import GreedyPolicy
from dqfd_bc_keras.seeds import ROLLOUT, episode_seed
from dqfd_bc_keras.training.demonstrations import fit_bc
from dqfd_bc_keras.training.records import DemoUpdate
from dqfd_bc_keras.training.state import TrainingState


class DynamicDemos:
    """DQfD-BC's dynamic demonstrations (§5): D_demo grows with the agent's best episodes.

    The paper: "when the final cumulative reward for each episode reaches a new high score,
    transition samples are … inserted into the demonstration dataset". Two readings
    (`Config.dynamic_demos`): `episodes` inserts the agent's own training episodes since the
    last update whose return reaches the new best moving average (no extra interaction);
    `rollouts` plays M fresh greedy episodes on a separate env (ALGORITHM.md §5; each of their
    steps is an interaction and is counted).
    """

    def __init__(self, config: Config, data: DemoDataset, env: gym.Env) -> None:
        self.config, self.env = config, env
        self.episodes = data.episodes()
        self.demo_average = data.mean_return
        self.recent: list[DemoDataset] = []
        """`episodes` mode: the agent's training episodes since the last update (at most W)."""

    def observe(self, episode: DemoDataset) -> None:
        """A training episode just ended (`episodes` mode)."""
        self.recent = (self.recent + [episode])[-self.config.dynamic_window :]

    @property
    def dataset(self) -> DemoDataset:
        return concatenate(self.episodes, source=self.episodes[0].meta.expert)

    def due(self, state: TrainingState) -> bool:
        """The moving average of the last W returns reaches a new best, at least the demos' average."""
        W = self.config.dynamic_window
        if len(state.returns) < W:
            return False
        average = float(np.mean(state.returns[-W:]))
        if average > state.best_average and average >= self.demo_average:
            state.best_average = average
            return True
        return False

    def new_episodes(self, agent: DQfDAgent, state: TrainingState) -> list[DemoDataset]:
        """The episodes this update inserts: M greedy roll-outs, or the recent training episodes
        whose return reaches the new best average."""
        c = self.config
        if c.dynamic_demos == "rollouts":
            seeds = [episode_seed(c.seed, state.episode * 100 + i, ROLLOUT) for i in range(c.dynamic_rollouts)]
            return rollout(
                self.env,
                GreedyPolicy.from_model(agent.q_network),
                seeds,
                task=c.task,
                source="agent",
                seed=c.seed,
                env_kwargs=c.env_kwargs,
            ).episodes()
        chosen = [e for e in self.recent if e.meta.episode_returns[0] >= state.best_average]
        self.recent = []
        return chosen

    def update(
        self, agent: DQfDAgent, bc: BCModel, state: TrainingState, env_step: int, interactions: int
    ) -> DemoUpdate | None:
        """Insert the new episodes into D_demo (lowest returns dropped past capacity) and refit
        π_bc, at `env_step` and `interactions` (the episode's last); None when there is nothing
        new to insert."""
        c = self.config
        new = self.new_episodes(agent, state)
        if not new:
            return None
        self.episodes += new
        self.episodes.sort(key=lambda e: -e.meta.episode_returns[0])  # stable: older first among ties
        while sum(len(e) for e in self.episodes) > c.demo_capacity and len(self.episodes) > 1:
            self.episodes.pop()
        data = self.dataset
        state.bc_fits += 1
        accuracy = fit_bc(c, bc, data, c.bc_refit_epochs, fit_index=state.bc_fits)
        agent.set_demos(data.obs, data.actions, data.rewards, data.next_obs, data.terminated, data.truncated)
        agent.refresh_expert_targets()
        return DemoUpdate(
            episode=state.episode,
            env_step=env_step,
            interactions=interactions,
            moving_average=state.best_average,
            mode=c.dynamic_demos,
            new_returns=[e.meta.episode_returns[0] for e in new],
            new_transitions=sum(len(e) for e in new),
            demo_transitions=len(data),
            demo_episodes=len(self.episodes),
            bc_accuracy=accuracy,
        )
