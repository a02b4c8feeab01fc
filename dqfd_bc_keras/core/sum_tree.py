"""The sum tree of prioritized replay (ALGORITHM.md §1): P(i) ∝ p_i^α, sampled in two levels.

Every op in a graph has a fixed cost on this machine (docs/PERFORMANCE.md), so the tree is as
shallow as it can be: blocks of `SumTree.WIDTH` leaves and one sum per block.
"""

from __future__ import annotations

import math

import tensorflow as tf


class SumTree(tf.Module):
    """Proportional sampling over `size` leaves in two levels: blocks of `WIDTH` leaves and
    each block's sum, both `tf.Variable`s.

    Sampling is a cumulative sum and a binary search (`tf.searchsorted`) per level; an update
    rewrites the leaves and re-sums their blocks: a dozen TensorFlow ops in all, where a
    32-ary tree of 150k leaves takes five levels of a dozen each: every op has a fixed cost
    here, and a cumulative sum along wide rows costs far more than one along a long vector
    (docs/PERFORMANCE.md), hence narrow blocks. The total is re-summed from the block sums on
    each read, so rounding never accumulates.
    """

    WIDTH = 64

    def __init__(self, size: int) -> None:
        super().__init__()
        self.size = int(size)
        self.width = self.WIDTH
        self.blocks = max(1, math.ceil(self.size / self.width))
        self.leaf = tf.Variable(tf.zeros([self.blocks, self.width]), trainable=False, name="leaves")
        self.block_sums = tf.Variable(tf.zeros([self.blocks]), trainable=False, name="block_sums")

    @property
    def total(self) -> tf.Tensor:
        return tf.reduce_sum(self.block_sums)

    def _cell(self, indices: tf.Tensor) -> tf.Tensor:
        """(n, 2) [block, position] of each leaf index."""
        indices = tf.cast(indices, tf.int32)
        return tf.stack([indices // self.width, indices % self.width], axis=1)

    def leaves(self, indices: tf.Tensor) -> tf.Tensor:
        return tf.gather_nd(self.leaf, self._cell(indices))

    def set(self, indices: tf.Tensor, values: tf.Tensor) -> None:
        """Set leaves `indices` (n,) to `values` (n,) and re-sum their blocks."""
        cells = self._cell(indices)
        self.leaf.scatter_nd_update(cells, tf.cast(values, tf.float32))
        blocks = cells[:, :1]
        self.block_sums.scatter_nd_update(blocks, tf.reduce_sum(tf.gather_nd(self.leaf, blocks), axis=1))

    def find(self, mass: tf.Tensor) -> tf.Tensor:
        """The leaf whose cumulative-sum interval holds each of `mass` (n,) in [0, total)."""
        cumulative = tf.cumsum(self.block_sums)
        # Float rounding can put a mass at or past the last boundary: keep it inside.
        mass = tf.minimum(mass, cumulative[-1] * (1.0 - 1e-6))
        # The first block whose cumulative sum exceeds the mass: never an empty one.
        # The clamps never bind for finite priorities; NaN ones (a diverged update) would index past
        # the end, and the divergence must reach `training.check_finite`, not crash a gather.
        block = tf.minimum(tf.searchsorted(cumulative, mass, side="right"), self.blocks - 1)
        mass -= tf.gather(tf.concat([[0.0], cumulative], axis=0), block)
        within = tf.cumsum(tf.gather(self.leaf, block), axis=1)  # (n, width)
        mass = tf.minimum(mass, within[:, -1] * (1.0 - 1e-6))
        position = tf.searchsorted(within, mass[:, None], side="right")[:, 0]
        return tf.minimum(block * self.width + position, self.size - 1)
