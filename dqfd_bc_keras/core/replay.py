"""Prioritized replay over D_demo ∪ D_replay, held in TensorFlow variables (ALGORITHM.md §1).

Storage is preallocated: table rows [0, demo_capacity) hold the demonstrations (never evicted;
replaced as a whole when dynamic demonstrations change D_demo), rows [demo_capacity,
demo_capacity + capacity) are a circular buffer of self-generated transitions. One sum tree
over all rows gives proportional prioritization,

    P(i) = p_i^α / Σ_k p_k^α,   p_i = |δ_i| + ε_d (demo) or ε_a (self-generated),
    w_i = (N·P(i))^(−β) / max_j w_j   (max over the batch),

and new transitions enter at the largest priority seen. Everything here runs inside a
TensorFlow graph, so storing, sampling and the priority write-back add no graph calls.

Every sample carries its n-step return from the stored sequence: R = Σ_{k<m} γ^k r_{t+k}
with m ≤ n stopping at the episode's end (terminated or truncated) or at the newest stored
transition, then bootstrapping from s_{t+m} with γ^m·(1 − terminated). A row's return only
changes when a row of its window is written, so it is computed then (for all of D_demo when it
is set) and kept beside the table: sampling reads it with one gather instead of re-deriving it
for every batch.

Self-generated rows are stored one at a time but settled in batches (`settle`): their n-step
returns (and those of the n − 1 rows before them, whose windows reach them) and, where the
agent gives an `expert_view`, π̄_bc and σ² of their states. Every op in a graph has a fixed cost
here (docs/PERFORMANCE.md), so one settle of the rows stored between two samples costs about
what settling one row did. `sample` settles first, so a batch never sees the difference: what it
reads is what storing and settling each row at once would have written. Settles come only there
and every `SETTLE_ROWS` rows, never where a graph call ends, so the MC-dropout draws of a run do
not depend on where its graph calls stop (its evaluation grid); the count waiting is checkpointed.

Frames are stored once each, as uint8, in a pool the table indexes (frame_pool.py).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import tensorflow as tf

from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.core.frame_pool import FramePool
from dqfd_bc_keras.core.networks import NetworkInput, as_input
from dqfd_bc_keras.core.sum_tree import SumTree
from dqfd_bc_keras.errors import ConfigError


class Batch(NamedTuple):
    """A prioritized mini-batch; every field is a (B, ...) tensor."""

    indices: tf.Tensor
    """(B,) int32 storage rows, for the priority write-back."""
    obs: tf.Tensor
    """(B, d) s_t, or (B, *shape) uint8 frames."""
    actions: tf.Tensor
    """(B,) int32 a_t."""
    rewards: tf.Tensor
    """(B,) r_t."""
    next_obs: tf.Tensor
    """(B, d) s_{t+1}."""
    discount: tf.Tensor
    """(B,) γ·(1 − terminated_t): zero only for a true termination."""
    n_returns: tf.Tensor
    """(B,) Σ_{k<m} γ^k r_{t+k}."""
    n_next_obs: tf.Tensor
    """(B, d) s_{t+m}."""
    n_discount: tf.Tensor
    """(B,) γ^m·(1 − terminated_{t+m−1})."""
    pi_bc: tf.Tensor
    """(B, A) π̄_bc(·|s_t), the BC model's (mean) policy, stored with the row."""
    sigma_sq: tf.Tensor
    """(B,) σ²(s_t), the BC model's predictive variance, stored with the row."""
    is_demo: tf.Tensor
    """(B,) 1.0 for demonstration rows, 0.0 for self-generated ones."""
    weights: tf.Tensor
    """(B,) importance-sampling weights, max 1."""


@dataclass(frozen=True)
class ReplaySettings:
    """The replay's sizes, n-step return and prioritization (`from_config`: a run's); each default
    is the Config's."""

    capacity: int = Config.replay_capacity
    """Rows of D_replay, the circular buffer of self-generated transitions."""
    demo_capacity: int = Config.demo_capacity
    """Rows kept for D_demo."""
    n_step: int = Config.n_step
    gamma: float = Config.gamma
    alpha: float = Config.priority_alpha
    """The priority exponent: P(i) ∝ p_i^α."""
    eps_agent: float = Config.priority_eps_agent
    eps_demo: float = Config.priority_eps_demo
    seed: int = Config.seed
    """Seeds the sampling's generator."""

    @classmethod
    def from_config(cls, config: Config) -> ReplaySettings:
        c = config
        return cls(
            capacity=c.replay_capacity,
            demo_capacity=c.demo_capacity,
            n_step=c.n_step,
            gamma=c.gamma,
            alpha=c.priority_alpha,
            eps_agent=c.priority_eps_agent,
            eps_demo=c.priority_eps_demo,
            seed=c.seed,
        )


class PrioritizedReplay(tf.Module):
    """D_demo and D_replay with proportional prioritization and n-step returns, in the graph.

    Each row of one float32 table packs a transition and the BC model's view of its state:
    [s (d) | s' (d) | a | r | terminated | truncated | π̄_bc (A) | σ²], so a whole n-step
    window of the batch is one gather. π̄_bc and σ² are functions of s alone and the BC model
    is fixed between refits, so they are computed when a row is written or settled (and recomputed
    for every row after a refit) instead of K MC-dropout passes on every sampled batch.
    """

    SETTLE_ROWS = 64
    """At most this many rows wait to be settled: a batch that shares the per-op cost, and bounds
    what a settle holds in memory while no sample comes (before learning starts)."""

    def __init__(
        self, net_input: int | NetworkInput, n_actions: int, settings: ReplaySettings = ReplaySettings()
    ) -> None:
        super().__init__()
        s = settings
        if s.capacity < s.n_step:
            raise ConfigError(f"replay capacity must be ≥ n_step={s.n_step}, got {s.capacity}")
        net_input = as_input(net_input)
        frames = net_input.frames
        self.obs_dim = net_input.dim if frames is None else frames.stack
        """Columns of s (and of s') in the table: features, or the pool indices of the stacked frames."""
        self.n_actions = int(n_actions)
        self.capacity, self.demo_capacity = int(s.capacity), int(s.demo_capacity)
        self.n_step, self.gamma, self.alpha = int(s.n_step), float(s.gamma), float(s.alpha)
        self.eps_agent, self.eps_demo = float(s.eps_agent), float(s.eps_demo)
        d, A = self.obs_dim, self.n_actions
        self.OBS, self.NEXT_OBS = slice(0, d), slice(d, 2 * d)
        self.ACTION, self.REWARD, self.TERMINATED, self.TRUNCATED = 2 * d, 2 * d + 1, 2 * d + 2, 2 * d + 3
        self.PI_BC, self.SIGMA_SQ = slice(2 * d + 4, 2 * d + 4 + A), 2 * d + 4 + A
        rows = self.demo_capacity + self.capacity
        self.table = tf.Variable(tf.zeros([rows, 2 * d + 5 + A]), trainable=False, name="table")
        self.demo_size = tf.Variable(0, trainable=False, name="demo_size")
        self.agent_size = tf.Variable(0, trainable=False, name="agent_size")
        self.head = tf.Variable(0, trainable=False, name="head")
        self.max_priority = tf.Variable(1.0, trainable=False, name="max_priority")
        """The largest p^α written so far: new transitions enter with it."""
        self.n_step_view = tf.Variable(tf.zeros([rows, d + 2]), trainable=False, name="n_step_view")
        """[R | s_{t+m} (d) | γ^m·(1 − terminated)] of each row, kept current by `_refresh_n_step`."""
        self.tree = SumTree(rows)
        self.expert_view: Callable[[tf.Tensor], tuple[tf.Tensor, tf.Tensor]] | None = None
        """States → (π̄_bc, σ²), written into self-generated rows when they are settled (the agent sets it
        when it has a BC model); None: rows keep the π̄_bc and σ² they were stored with."""
        self.unsettled = tf.Variable(0, trainable=False, name="unsettled")
        """How many of the newest self-generated rows wait for `settle`."""
        self.settle_rows = min(self.SETTLE_ROWS, self.capacity)
        self._strictly_upper = tf.constant(np.triu(np.ones((self.n_step, self.n_step), np.float32), k=1))
        self.rng = tf.random.Generator.from_seed(s.seed)
        self.frame_pool = None if frames is None else FramePool(frames, self.demo_capacity, self.capacity)
        """Where frames are stored when observations are frames (then s and s' columns hold pool indices)."""

    @property
    def size(self) -> tf.Tensor:
        return self.demo_size + self.agent_size

    @property
    def pool_bytes(self) -> int:
        """Bytes of the frame pool (0 for vector observations)."""
        return 0 if self.frame_pool is None else self.frame_pool.bytes

    def observations(self, columns: tf.Tensor) -> tf.Tensor:
        """States from table columns (B, obs_dim): the vectors themselves, or the frames (B, *shape)
        their pool indices name, uint8."""
        return columns if self.frame_pool is None else self.frame_pool.observations(columns)

    def states(self, indices: tf.Tensor) -> tf.Tensor:
        """s_t of stored rows `indices`."""
        return self.observations(tf.gather(self.table, indices)[:, self.OBS])

    def rows(self, obs, actions, rewards, next_obs, terminated, truncated, pi_bc, sigma_sq) -> tf.Tensor:
        """Pack (n, ...) transition arrays into (n, width) table rows."""
        column = lambda x: tf.cast(tf.reshape(x, [-1, 1]), tf.float32)
        return tf.concat(
            [
                tf.cast(obs, tf.float32),
                tf.cast(next_obs, tf.float32),
                column(actions),
                column(rewards),
                column(terminated),
                column(truncated),
                tf.cast(pi_bc, tf.float32),
                column(sigma_sq),
            ],
            axis=1,
        )

    def set_demos(self, rows: tf.Tensor) -> None:
        """Replace D_demo by these packed rows (time order, complete episodes), at max priority."""
        n, old = int(rows.shape[0]), int(self.demo_size.numpy())
        if n == 0 or n > self.demo_capacity:
            raise ConfigError(f"D_demo must hold 1 to demo_capacity={self.demo_capacity} transitions, got {n}")
        if rows.shape[1] != self.table.shape[1]:
            raise ConfigError(f"demonstration rows have width {rows.shape[1]}, the table {self.table.shape[1]}")
        self.table.scatter_nd_update(tf.range(n)[:, None], rows)
        self.demo_size.assign(n)
        self._refresh_n_step(tf.range(n))
        priorities = tf.concat([tf.fill([n], self.max_priority), tf.zeros([max(old - n, 0)])], axis=0)
        self.tree.set(tf.range(len(priorities)), priorities)

    def store(self, row: tf.Tensor) -> None:
        """Append one packed self-generated transition (width,) at the circular head, at max priority;
        its n-step return (and π̄_bc, σ² with an `expert_view`) are written when it is settled."""
        position = self.head.read_value()
        index = self.demo_capacity + position
        self.table.scatter_nd_update([[index]], row[None])
        self.tree.set(index[None], self.max_priority[None])
        self.head.assign((position + 1) % self.capacity)
        self.agent_size.assign(tf.minimum(self.agent_size + 1, self.capacity))
        self.unsettled.assign_add(1)
        tf.cond(self.unsettled >= self.settle_rows, self.settle, lambda: None)

    def settle(self) -> None:
        """Write the views of the rows stored since the last settle, in one batch: the n-step returns
        of those rows and of the n − 1 before them (whose windows reach them), and with an
        `expert_view` π̄_bc and σ² of their states."""

        def write() -> None:
            newest = lambda m: self.demo_capacity + (self.head - 1 - tf.range(m)) % self.capacity
            self._refresh_n_step(newest(tf.minimum(self.unsettled + self.n_step - 1, self.capacity)))
            if self.expert_view is not None:
                rows = newest(self.unsettled)
                self.set_expert_targets(rows, *self.expert_view(self.states(rows)))
            self.unsettled.assign(0)

        tf.cond(self.unsettled > 0, write, lambda: None)

    def stored_indices(self) -> tf.Tensor:
        """The table rows in use: D_demo, then D_replay."""
        return tf.concat([tf.range(self.demo_size), self.demo_capacity + tf.range(self.agent_size)], axis=0)

    def sample(self, batch_size: int, beta: tf.Tensor) -> Batch:
        """Draw `batch_size` rows with P(i) ∝ p_i^α, with IS weights and n-step returns."""
        self.settle()
        total = self.tree.total
        indices = self.tree.find(self.rng.uniform([batch_size]) * total)
        weights = tf.pow(tf.cast(self.size, tf.float32) * self.tree.leaves(indices) / total, -beta)
        return self._batch(indices, weights / tf.reduce_max(weights))

    def sample_balanced(self, batch_size: int) -> Batch:
        """SQIL's batch: the first half uniformly from D_demo, the second from D_replay (all from
        D_demo while D_replay is empty), weights 1."""
        self.settle()
        u = self.rng.uniform([batch_size])
        from_agent = tf.logical_and(tf.range(batch_size) >= batch_size // 2, self.agent_size > 0)
        indices = tf.where(
            from_agent,
            self.demo_capacity + tf.cast(u * tf.cast(self.agent_size, tf.float32), tf.int32),
            tf.cast(u * tf.cast(self.demo_size, tf.float32), tf.int32),
        )
        return self._batch(indices, tf.ones([batch_size]))

    def rows_as_batch(self, indices: tf.Tensor) -> Batch:
        """Stored rows `indices` as a batch of weights 1, to read them as the loss does (no sampling)."""
        return self._batch(indices, tf.ones(tf.shape(indices)))

    def _batch(self, indices: tf.Tensor, weights: tf.Tensor) -> Batch:
        """The stored rows `indices` as a batch with these importance weights."""
        row = tf.gather(self.table, indices)
        n_returns, n_next_obs, n_discount = tf.split(tf.gather(self.n_step_view, indices), [1, self.obs_dim, 1], axis=1)
        return Batch(
            indices=indices,
            obs=self.observations(row[:, self.OBS]),
            actions=tf.cast(row[:, self.ACTION], tf.int32),
            rewards=row[:, self.REWARD],
            next_obs=self.observations(row[:, self.NEXT_OBS]),
            discount=self.gamma * (1.0 - row[:, self.TERMINATED]),
            n_returns=n_returns[:, 0],
            n_next_obs=self.observations(n_next_obs),
            n_discount=n_discount[:, 0],
            pi_bc=row[:, self.PI_BC],
            sigma_sq=row[:, self.SIGMA_SQ],
            is_demo=tf.cast(indices < self.demo_capacity, tf.float32),
            weights=weights,
        )

    def _refresh_n_step(self, indices: tf.Tensor) -> None:
        """Recompute the n-step return, s_{t+m} and discount of rows `indices` (distinct)."""
        window = tf.gather(self.table, self._window(indices))  # (n, n_step, width); step 0 is the row
        n_returns, n_next_obs, n_discount = self._n_step(indices, window)
        self.n_step_view.scatter_nd_update(
            indices[:, None], tf.concat([n_returns[:, None], n_next_obs, n_discount[:, None]], axis=1)
        )

    def _window(self, indices: tf.Tensor) -> tf.Tensor:
        """(B, n) rows t, t+1, …, t+n−1 of each sample's region (D_replay wraps around)."""
        k = tf.range(self.n_step)
        agent_position = (indices - self.demo_capacity + k[:, None]) % self.capacity
        return tf.transpose(
            tf.where(indices < self.demo_capacity, indices + k[:, None], self.demo_capacity + agent_position)
        )

    def _n_step(self, indices: tf.Tensor, window: tf.Tensor) -> tuple[tf.Tensor, tf.Tensor, tf.Tensor]:
        """(R, s_{t+m}, γ^m·(1 − terminated)) for each row, m ≤ n within its episode."""
        k = tf.range(self.n_step)
        is_demo = indices < self.demo_capacity
        # How many transitions were stored after this one (so far) in its region.
        ahead = tf.where(
            is_demo, self.demo_size - 1 - indices, (self.head - 1 - (indices - self.demo_capacity)) % self.capacity
        )
        done = window[:, :, self.TERMINATED] + window[:, :, self.TRUNCATED] > 0
        # Step k is in the window iff no earlier step ended the episode and it has been stored.
        ended_before = tf.matmul(tf.cast(done, tf.float32), self._strictly_upper) > 0  # Σ_{i<k} done_i > 0
        inside = tf.cast(tf.logical_and(tf.logical_not(ended_before), k[None, :] <= ahead[:, None]), tf.float32)
        discounts = tf.pow(self.gamma, tf.cast(k, tf.float32))
        n_returns = tf.reduce_sum(inside * discounts * window[:, :, self.REWARD], axis=1)
        m = tf.cast(tf.reduce_sum(inside, axis=1), tf.int32)  # ≥ 1: step 0 is always inside
        last = tf.gather(window, m - 1, axis=1, batch_dims=1)  # (B, width), the row t+m−1
        n_discount = tf.pow(self.gamma, tf.cast(m, tf.float32)) * (1.0 - last[:, self.TERMINATED])
        return n_returns, last[:, self.NEXT_OBS], n_discount

    def set_expert_targets(self, indices: tf.Tensor, pi_bc: tf.Tensor, sigma_sq: tf.Tensor) -> None:
        """Overwrite π̄_bc and σ² of rows `indices` (after the BC model was refitted)."""
        rows = tf.gather(self.table, indices)
        rows = tf.concat([rows[:, : self.PI_BC.start], pi_bc, sigma_sq[:, None]], axis=1)
        self.table.scatter_nd_update(indices[:, None], rows)

    def update_priorities(self, indices: tf.Tensor, td_abs: tf.Tensor) -> None:
        """p_i ← (|δ_i| + ε)^α after a gradient step, ε = ε_d for demonstrations, ε_a otherwise."""
        eps = tf.where(indices < self.demo_capacity, self.eps_demo, self.eps_agent)
        priorities = tf.pow(td_abs + eps, self.alpha)
        self.tree.set(indices, priorities)
        self.max_priority.assign(tf.maximum(self.max_priority, tf.reduce_max(priorities)))
