"""Prioritized replay over D_demo ∪ D_replay, held in TensorFlow variables (ALGORITHM.md §1).

Storage is preallocated: table rows [0, demo_capacity) hold the demonstrations (never evicted;
replaced as a whole when dynamic demonstrations change D_demo), rows [demo_capacity,
demo_capacity + capacity) are a circular buffer of self-generated transitions. One sum tree
over all rows gives proportional prioritization,

    P(i) = p_i^α / Σ_k p_k^α,   p_i = |δ_i| + ε_d (demo) or ε_a (self-generated),
    w_i = (N·P(i))^(−β) / max_j w_j   (max over the batch),

and new transitions enter at the largest priority seen. Everything here runs inside a
TensorFlow graph, so storing, sampling and the priority write-back add no graph calls.

Every sample carries its n-step return, computed on the fly from the stored sequence:
R = Σ_{k<m} γ^k r_{t+k} with m ≤ n stopping at the episode's end (terminated or truncated)
or at the newest stored transition, then bootstrapping from s_{t+m} with γ^m·(1 − terminated).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import tensorflow as tf

from .errors import ConfigError


class Batch(NamedTuple):
    """A prioritized mini-batch; every field is a (B, ...) tensor."""

    indices: tf.Tensor
    """(B,) int32 storage rows, for the priority write-back."""
    obs: tf.Tensor
    """(B, d) s_t."""
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


class SumTree(tf.Module):
    """A 32-ary sum tree in `tf.Variable`s: sampling and updating touch 32 values per level.

    `levels[0]` is the root, `levels[-1]` the leaves. A flat cumulative sum costs ~1 ms per
    sample at 150k rows on this CPU; four levels of 32 cost a few µs.
    """

    BRANCH = 32

    def __init__(self, size: int) -> None:
        super().__init__()
        self.depth = max(1, math.ceil(math.log(size, self.BRANCH) - 1e-9))
        self.levels = [tf.Variable(tf.zeros([self.BRANCH**d]), trainable=False, name=f"level_{d}")
                       for d in range(self.depth + 1)]
        # (x @ upper)[:, j] = Σ_{i ≤ j} x[:, i]: TensorFlow's CPU cumsum is several times slower.
        self._upper = tf.constant(np.triu(np.ones((self.BRANCH, self.BRANCH), np.float32)))

    @property
    def total(self) -> tf.Tensor:
        return self.levels[0][0]

    def leaves(self, indices: tf.Tensor) -> tf.Tensor:
        return tf.gather(self.levels[-1], indices)

    def _children(self, nodes: tf.Tensor) -> tf.Tensor:
        return nodes[:, None] * self.BRANCH + tf.range(self.BRANCH)

    def set(self, indices: tf.Tensor, values: tf.Tensor) -> None:
        """Set leaves `indices` (n,) to `values` (n,) and recompute their ancestors."""
        nodes = tf.cast(indices, tf.int32)
        self.levels[-1].scatter_nd_update(nodes[:, None], tf.cast(values, tf.float32))
        for d in range(self.depth - 1, -1, -1):
            nodes = nodes // self.BRANCH
            sums = tf.reduce_sum(tf.gather(self.levels[d + 1], self._children(nodes)), axis=1)
            self.levels[d].scatter_nd_update(nodes[:, None], sums)

    def find(self, mass: tf.Tensor) -> tf.Tensor:
        """The leaf whose cumulative-sum interval holds each of `mass` (n,) in [0, total)."""
        nodes = tf.zeros_like(mass, dtype=tf.int32)
        for d in range(1, self.depth + 1):
            children = tf.gather(self.levels[d], self._children(nodes))  # (n, BRANCH)
            cumulative = tf.matmul(children, self._upper)  # a cumsum along the row, as one matmul
            mass = tf.minimum(mass, cumulative[:, -1] * (1.0 - 1e-6))  # float rounding at the edge
            passed = tf.cast(cumulative <= mass[:, None], tf.float32)  # the children wholly below mass
            mass -= tf.reduce_sum(children * passed, axis=1)
            nodes = nodes * self.BRANCH + tf.cast(tf.reduce_sum(passed, axis=1), tf.int32)
        return nodes


class PrioritizedReplay(tf.Module):
    """D_demo and D_replay with proportional prioritization and n-step returns, in the graph.

    Each row of one float32 table packs a transition and the BC model's view of its state:
    [s (d) | s' (d) | a | r | terminated | truncated | π̄_bc (A) | σ²], so a whole n-step
    window of the batch is one gather. π̄_bc and σ² are functions of s alone and the BC model
    is fixed between refits, so they are computed when a row is written (and recomputed for
    every row after a refit) instead of K MC-dropout passes on every sampled batch.
    """

    def __init__(
        self,
        obs_dim: int,
        n_actions: int,
        capacity: int = 100_000,
        demo_capacity: int = 50_000,
        n_step: int = 10,
        gamma: float = 0.99,
        alpha: float = 0.4,
        eps_agent: float = 0.001,
        eps_demo: float = 1.0,
        seed: int = 0,
    ) -> None:
        super().__init__()
        if capacity < n_step:
            raise ConfigError(f"replay capacity must be ≥ n_step={n_step}, got {capacity}")
        self.obs_dim, self.n_actions = int(obs_dim), int(n_actions)
        self.capacity, self.demo_capacity = int(capacity), int(demo_capacity)
        self.n_step, self.gamma, self.alpha = int(n_step), float(gamma), float(alpha)
        self.eps_agent, self.eps_demo = float(eps_agent), float(eps_demo)
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
        self.tree = SumTree(rows)
        self._strictly_upper = tf.constant(np.triu(np.ones((n_step, n_step), np.float32), k=1))
        self.rng = tf.random.Generator.from_seed(seed)

    @property
    def size(self) -> tf.Tensor:
        return self.demo_size + self.agent_size

    def rows(self, obs, actions, rewards, next_obs, terminated, truncated, pi_bc, sigma_sq) -> tf.Tensor:
        """Pack (n, ...) transition arrays into (n, width) table rows."""
        column = lambda x: tf.cast(tf.reshape(x, [-1, 1]), tf.float32)  # noqa: E731
        return tf.concat([tf.cast(obs, tf.float32), tf.cast(next_obs, tf.float32), column(actions),
                          column(rewards), column(terminated), column(truncated),
                          tf.cast(pi_bc, tf.float32), column(sigma_sq)], axis=1)

    def set_demos(self, rows: tf.Tensor) -> None:
        """Replace D_demo by these packed rows (time order, complete episodes), at max priority."""
        n, old = int(rows.shape[0]), int(self.demo_size.numpy())
        if n == 0 or n > self.demo_capacity:
            raise ConfigError(f"D_demo must hold 1 to demo_capacity={self.demo_capacity} transitions, got {n}")
        if rows.shape[1] != self.table.shape[1]:
            raise ConfigError(f"demonstration rows have width {rows.shape[1]}, the table {self.table.shape[1]}")
        self.table.scatter_nd_update(tf.range(n)[:, None], rows)
        self.demo_size.assign(n)
        priorities = tf.concat([tf.fill([n], self.max_priority), tf.zeros([max(old - n, 0)])], axis=0)
        self.tree.set(tf.range(len(priorities)), priorities)

    def store(self, row: tf.Tensor) -> None:
        """Append one packed self-generated transition (width,) at the circular head, at max priority."""
        index = self.demo_capacity + self.head
        self.table.scatter_nd_update([[index]], row[None])
        self.tree.set(index[None], self.max_priority[None])
        self.head.assign((self.head + 1) % self.capacity)
        self.agent_size.assign(tf.minimum(self.agent_size + 1, self.capacity))

    def stored_indices(self) -> tf.Tensor:
        """The table rows in use: D_demo, then D_replay."""
        return tf.concat([tf.range(self.demo_size), self.demo_capacity + tf.range(self.agent_size)], axis=0)

    def sample(self, batch_size: int, beta: tf.Tensor) -> Batch:
        """Draw `batch_size` rows with P(i) ∝ p_i^α, with IS weights and n-step returns."""
        total = self.tree.total
        indices = self.tree.find(self.rng.uniform([batch_size]) * total)
        weights = tf.pow(tf.cast(self.size, tf.float32) * self.tree.leaves(indices) / total, -beta)
        weights /= tf.reduce_max(weights)
        window = tf.gather(self.table, self._window(indices))  # (B, n, width); step 0 is the row itself
        row = window[:, 0]
        n_returns, n_next_obs, n_discount = self._n_step(indices, window)
        return Batch(
            indices=indices, obs=row[:, self.OBS], actions=tf.cast(row[:, self.ACTION], tf.int32),
            rewards=row[:, self.REWARD], next_obs=row[:, self.NEXT_OBS],
            discount=self.gamma * (1.0 - row[:, self.TERMINATED]),
            n_returns=n_returns, n_next_obs=n_next_obs, n_discount=n_discount,
            pi_bc=row[:, self.PI_BC], sigma_sq=row[:, self.SIGMA_SQ],
            is_demo=tf.cast(indices < self.demo_capacity, tf.float32), weights=weights,
        )

    def _window(self, indices: tf.Tensor) -> tf.Tensor:
        """(B, n) rows t, t+1, …, t+n−1 of each sample's region (D_replay wraps around)."""
        k = tf.range(self.n_step)
        agent_position = (indices - self.demo_capacity + k[:, None]) % self.capacity
        return tf.transpose(tf.where(indices < self.demo_capacity, indices + k[:, None],
                                     self.demo_capacity + agent_position))

    def _n_step(self, indices: tf.Tensor, window: tf.Tensor) -> tuple[tf.Tensor, tf.Tensor, tf.Tensor]:
        """(R, s_{t+m}, γ^m·(1 − terminated)) for each row, m ≤ n within its episode."""
        k = tf.range(self.n_step)
        is_demo = indices < self.demo_capacity
        # How many transitions were stored after this one (so far) in its region.
        ahead = tf.where(is_demo, self.demo_size - 1 - indices,
                         (self.head - 1 - (indices - self.demo_capacity)) % self.capacity)
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
