"""The interaction loop of Algorithm 1 (step 3), compiled: one TensorFlow graph call per episode.

`Interaction.play` is a `tf.while_loop` that acts ε-greedily with Q, steps the real Gymnasium env
through `tf.numpy_function`, stores the transition, and takes the gradient step, so the policy
that acts is always the one after the latest update.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import tensorflow as tf

from dqfd_bc_keras.core.agent import DQfDAgent
from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.demos.recording import EpisodeRecorder
from dqfd_bc_keras.training.state import EpisodeStats


class Interaction(tf.Module):
    """The interaction loop of Algorithm 1 (step 3) for one env, compiled into one graph per episode."""

    def __init__(self, agent: DQfDAgent, env: gym.Env, config: Config, record: bool = False) -> None:
        """`record`: keep the transitions of the running episode (dynamic demonstrations from
        the agent's own episodes)."""
        super().__init__()
        self.agent, self.env, self.config = agent, env, config
        self.env_steps = tf.Variable(0, dtype=tf.int64, trainable=False, name="env_steps")
        self.rng = tf.random.Generator.from_seed(config.seed + 1)
        self.decay_steps = tf.Variable(
            config.epsilon_fraction * config.total_steps, dtype=tf.float32, trainable=False, name="decay_steps"
        )
        """ε's decay length, a variable: a budget raised after tracing (`Learner.extend`) stretches it."""
        self.episode = EpisodeStats()
        self.obs: np.ndarray | None = None
        """The running episode's observation between two graph calls (None between episodes): an
        exception there (a callback's, Ctrl-C) leaves it, and the next `train_episodes` goes on from it."""
        self.recorder = (
            EpisodeRecorder(env, task=config.task, source="agent", seed=config.seed, env_kwargs=config.env_kwargs)
            if record
            else None
        )
        self.play = tf.function(
            self._play,
            autograph=False,
            input_signature=[tf.TensorSpec(agent.net_input.shape, agent.net_input.dtype), tf.TensorSpec([], tf.int64)],
        )

    @tf.function(input_signature=[], autograph=False)
    def epsilon(self) -> tf.Tensor:
        """ε, linear from its start to `epsilon_end` over `epsilon_fraction` of the budget (a graph of
        its own: read after every episode, it cost more as eager ops)."""
        c = self.config
        start = c.initial_epsilon
        progress = tf.cast(self.env_steps, tf.float32) / self.decay_steps
        return tf.maximum(c.epsilon_end, start - (start - c.epsilon_end) * progress)

    def reset(self, seed: int) -> np.ndarray:
        """Start an episode (reset seed `seed`); returns s_0."""
        obs, _ = self.env.reset(seed=seed)
        self.episode = EpisodeStats()
        if self.recorder is not None:
            self.recorder.clear()
            self.recorder.reset(obs, seed)
        return obs

    def _env_step(self, action: np.ndarray) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """The Python side of `tf.numpy_function`: step the env, keep the episode's tallies.

        Returns one float32 vector [s' (d), r, terminated, truncated]: one array crosses the
        boundary instead of four. Frames cross as they are (uint8), beside [r, terminated, truncated].
        """
        obs, step_reward, terminated, truncated, info = self.env.step(int(action))
        reward = float(step_reward)
        self.episode.add(reward, info)
        if self.recorder is not None:
            self.recorder.step(int(action), obs, reward, terminated, truncated, info)
        if self.agent.net_input.image:
            return obs, np.array((reward, terminated, truncated), np.float32)
        return np.append(obs, (reward, terminated, truncated)).astype(np.float32)

    def _play(self, obs: tf.Tensor, max_steps: tf.Tensor) -> tuple[tf.Tensor, tf.Tensor]:
        """Act, store and learn until the episode ends or `max_steps` env steps; returns (obs, done)."""
        agent, c, d = self.agent, self.config, self.agent.obs_dim

        def step(obs: tf.Tensor, done: tf.Tensor, steps: tf.Tensor) -> tuple[tf.Tensor, tf.Tensor, tf.Tensor]:
            # ε-greedy: one draw decides whether to explore, the other which action.
            u = self.rng.uniform([2])
            random_action = tf.minimum(tf.cast(u[1] * agent.n_actions, tf.int32), agent.n_actions - 1)
            action = tf.where(u[0] < self.epsilon(), random_action, agent.greedy_actions(obs[None])[0])
            if agent.net_input.image:
                next_obs, step = tf.numpy_function(self._env_step, [action], [tf.uint8, tf.float32], stateful=True)
                next_obs, step = tf.ensure_shape(next_obs, agent.net_input.shape), tf.ensure_shape(step, [3])
            else:
                step = tf.ensure_shape(tf.numpy_function(self._env_step, [action], tf.float32, stateful=True), [d + 3])
                next_obs, step = step[:d], step[d:]
            reward, terminated, truncated = step[0], step[1] > 0, step[2] > 0
            agent.store(obs, action, reward, next_obs, terminated, truncated)
            self.env_steps.assign_add(1)
            learns = tf.logical_and(self.env_steps % c.train_freq == 0, agent.replay.size >= c.batch_size)
            tf.cond(learns, agent.learn_step, lambda: None)
            return next_obs, tf.logical_or(terminated, truncated), steps + 1

        obs, done, _ = tf.while_loop(
            lambda obs, done, steps: tf.logical_and(tf.logical_not(done), steps < max_steps),
            step,
            [obs, tf.constant(False), tf.constant(0, tf.int64)],
        )
        return obs, done
