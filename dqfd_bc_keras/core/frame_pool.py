"""The replay's frames (`networks.NetworkInput.image`), never stored as floats, nor once per stack.

A uint8 pool holds single frames, two slots per table row (its s_t's newest frame, written only
when s_t does not continue the previous row's s_{t+1}, and its s_{t+1}'s newest frame), and a
row's s and s' columns hold the k pool indices of their stacked frames (k = 1 for MinAtar, 4 for
Atari). Within an episode s_t's frames are the previous row's s_{t+1}'s, and s_{t+1}'s are s_t's
shifted by one and a new frame; a fresh stack (a reset) is k copies of one frame. The
self-generated rows' slots run k rows beyond the table's capacity, so the oldest rows' earlier
frames outlive them.
"""

from __future__ import annotations

import numpy as np
import tensorflow as tf

from dqfd_bc_keras.envs.frames import Frames
from dqfd_bc_keras.errors import ConfigError


class FramePool(tf.Module):
    """The frames of D_demo's `demo_capacity` rows and D_replay's `capacity` rows, by pool index."""

    def __init__(self, frames: Frames, demo_capacity: int, capacity: int) -> None:
        super().__init__()
        self.frames, self.demo_capacity, self.capacity = frames, int(demo_capacity), int(capacity)
        k = frames.stack
        self.slot_rows = self.demo_capacity + self.capacity + k
        """Rows of pool slots: D_demo's, then D_replay's capacity and k more (module docstring)."""
        self.pool = tf.Variable(
            tf.zeros([2 * self.slot_rows, *frames.frame_shape], tf.uint8), trainable=False, name="frame_pool"
        )
        self.serial = tf.Variable(tf.constant(0, tf.int64), trainable=False, name="serial")
        """Self-generated transitions stored so far: their slot row is D_demo's + serial mod (capacity + k)."""
        self.last_next = tf.Variable(tf.zeros(frames.shape, tf.uint8), trainable=False, name="last_next_obs")
        self.last_next_index = tf.Variable(tf.zeros([k]), trainable=False, name="last_next_index")
        self.has_last = tf.Variable(False, trainable=False, name="has_last")

    @property
    def bytes(self) -> int:
        return int(np.prod(self.pool.shape))

    def _newest(self, obs: tf.Tensor) -> tf.Tensor:
        """The newest frame of observations (..., *shape): the last of a stack, or all of it."""
        return obs[..., -1] if self.frames.stack > 1 else obs

    def store(self, obs: tf.Tensor, next_obs: tf.Tensor) -> tuple[tf.Tensor, tf.Tensor]:
        """Write the new frames of one self-generated transition to the pool; returns the pool
        indices (k,) of s and of s', as float32 table columns (exact below 2^24)."""
        k = self.frames.stack
        slot = 2 * (self.demo_capacity + tf.cast(self.serial % (self.capacity + k), tf.int32))
        obs, next_obs = tf.cast(obs, tf.uint8), tf.cast(next_obs, tf.uint8)
        checks = []
        if k > 1:  # the invariants that let a stack be stored as one new frame
            checks.append(
                tf.debugging.Assert(
                    tf.reduce_all(next_obs[..., :-1] == obs[..., 1:]),
                    ["s' is not s's frame stack shifted by one frame"],
                )
            )
        continues = tf.logical_and(self.has_last, tf.reduce_all(obs == self.last_next))

        def fresh() -> tf.Tensor:
            ok = (
                []
                if k == 1
                else [
                    tf.debugging.Assert(
                        tf.reduce_all(obs == obs[..., -1:]), ["a fresh frame stack must be copies of one frame"]
                    )
                ]
            )
            with tf.control_dependencies(ok):
                self.pool.scatter_nd_update([[slot]], self._newest(obs)[None])
            return tf.fill([k], tf.cast(slot, tf.float32))

        with tf.control_dependencies(checks):
            obs_index = tf.cond(continues, self.last_next_index.read_value, fresh)
        self.pool.scatter_nd_update([[slot + 1]], self._newest(next_obs)[None])
        next_index = tf.concat([obs_index[1:], tf.cast(slot + 1, tf.float32)[None]], axis=0)
        self.last_next.assign(next_obs)
        self.last_next_index.assign(next_index)
        self.has_last.assign(True)
        self.serial.assign_add(1)
        return obs_index, next_index

    def store_demos(self, obs: np.ndarray, next_obs: np.ndarray, ends: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Write D_demo's frames (complete episodes in time order; `ends` marks each episode's last
        transition) to its slots; returns the pool indices (n, k) of every s and s'."""
        k, n = self.frames.stack, len(obs)
        newest = (lambda x: x[..., -1]) if k > 1 else (lambda x: x)
        starts = np.flatnonzero(np.concatenate([[True], ends[:-1]]))
        if k > 1 and not (
            np.array_equal(next_obs[..., :-1], obs[..., 1:]) and (obs[starts] == obs[starts][..., -1:]).all()
        ):
            raise ConfigError(
                "demonstrated frame stacks must shift by one frame per step and start as copies "
                "of one frame (as the Atari preprocessing makes them)"
            )
        frames = np.empty((2 * n, *self.frames.frame_shape), np.uint8)
        frames[1::2] = newest(next_obs)
        obs_index, next_index = np.empty((n, k), np.float32), np.empty((n, k), np.float32)
        for i in range(n):
            if i > 0 and not ends[i - 1]:  # inside an episode: s_t is s_{t-1}'s s'
                obs_index[i] = next_index[i - 1]
            else:
                frames[2 * i] = newest(obs[i])
                obs_index[i] = 2 * i
            next_index[i] = np.append(obs_index[i][1:], 2 * i + 1)
        self.pool.scatter_nd_update(tf.range(2 * n)[:, None], frames)
        return obs_index, next_index

    def observations(self, columns: tf.Tensor) -> tf.Tensor:
        """The frames (B, *shape), uint8, that table columns (B, k) of pool indices name."""
        frames = tf.gather(self.pool, tf.cast(columns, tf.int32))  # (B, k, *frame_shape)
        if self.frames.stack > 1:
            return tf.transpose(frames, [0, *range(2, frames.shape.rank), 1])
        return frames[:, 0]
