"""The BC model's epistemic variance σ²(s) − σ0² (ALGORITHM.md §3): three estimators
(choices.UNCERTAINTIES).

    mc_dropout  the paper's: the variance of K dropout passes of one MAP network.
    ensemble    K MAP networks from different initialisations, each fitted on its own bootstrap
                resample of D_demo (Lakshminarayanan et al. 2017, K = 5); the variance of their
                policies. Trained at once: each layer holds the K members' kernels, (K, in, out).
    distance    grows with the distance d(s) from s to the nearest demonstrated state, in the
                demonstrations' standardised space (`NearestDemoVariance`).
    local       the distance estimator's kernel k(s) = exp(−d(s)²/ℓ²), read as how much of σ0²'s
                confidence is left at s: σ²(s) = σ0²/k(s) (the `bayes_local` method). Ours.

All of them estimate the same quantity, v(s) = mean_a Var[π_bc(a|s)], so their σ² are on one scale.
Its largest value is v_max = (1 − 1/A)/A (members certain of actions spread evenly): 1/4 with two
actions. The first three add it to the floor, σ²(s) = σ0² + v(s) (the paper's form): the weight
1/(2σ²) of the likelihood then never falls below 1/(2(σ0² + v_max)), 0.73 of its full value with
σ0² = 0.5 and four actions, which is why `bayes` imitates the teacher about as hard on the agent's
own states as on the demonstrations (docs/MINATAR.md). `local` divides instead, σ²(s) =
σ0²/(1 − v(s)/v_max): full weight on the demonstrations, none where the BC model has seen nothing.
A BC model is given its estimator as a `VarianceEstimator` (`VarianceEstimator.from_config`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import keras
import numpy as np
import tensorflow as tf

from dqfd_bc_keras.choices import UNCERTAINTIES
from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.envs.frames import Frames


@dataclass(frozen=True)
class VarianceEstimator:
    """σ²(s) = σ0² + the epistemic variance of the estimator `uncertainty`: what a BC model needs to
    know of it. The field names are the keys a saved BC model keeps them under."""

    uncertainty: str = "mc_dropout"
    """The estimator, one of `choices.UNCERTAINTIES`."""
    sigma0_sq: float = 0.5
    """σ0², the floor of σ²: its value where the estimator has no doubt."""
    mc_passes: int = 10
    """K of MC dropout: the dropout passes averaged."""
    mc_dropout: bool = True
    """False: one deterministic pass even with dropout, σ² fixed at σ0² (the ablation)."""
    members: int = 1
    """K of the ensemble: its members; 1 for the other estimators (one network)."""

    def __post_init__(self) -> None:
        if self.uncertainty not in UNCERTAINTIES:
            raise ValueError(f"uncertainty={self.uncertainty!r} is not one of {UNCERTAINTIES}")
        if self.members != 1 and not self.ensemble:
            raise ValueError(f"members={self.members} is for uncertainty='ensemble' only, not {self.uncertainty!r}")

    @property
    def ensemble(self) -> bool:
        return self.uncertainty == "ensemble"

    @property
    def nearest_demo(self) -> bool:
        """The estimator reads the distance to the nearest demonstrated state (`NearestDemoVariance`)."""
        return self.uncertainty in ("distance", "local")

    def sigma_sq(self, variance: tf.Tensor, n_actions: int) -> tf.Tensor:
        """σ²(s) from the estimator's v(s): σ0² + v(s), or for `local` σ0²/(1 − v(s)/v_max), the
        fraction kept at least `LOCAL_FLOOR` so that σ² stays finite (a weight of 1e-6 is none)."""
        if self.uncertainty != "local":
            return self.sigma0_sq + variance
        kept = tf.maximum(1.0 - variance / max_policy_variance(n_actions), LOCAL_FLOOR)
        return self.sigma0_sq / kept

    @classmethod
    def from_saved(cls, saved: dict) -> VarianceEstimator:
        """The estimator of a saved BC model's config, its keys taken out of `saved`; a model saved
        before `uncertainty`, `mc_dropout` or `members` existed gets their defaults."""
        return cls(
            uncertainty=str(saved.pop("uncertainty", "mc_dropout")),
            sigma0_sq=float(saved.pop("sigma0_sq")),
            mc_passes=int(saved.pop("mc_passes")),
            mc_dropout=bool(saved.pop("mc_dropout", True)),
            members=int(saved.pop("members", 1)),
        )

    @classmethod
    def from_config(cls, config: Config) -> VarianceEstimator:
        """The estimator `config` asks for: the one its method fixes (`bayes_local`'s `local`), or
        `config.uncertainty` for the bayes loss; MC dropout for the others, whose MLE model has no
        dropout, so that its passes agree and σ² is σ0²."""
        uncertainty = (config.method.uncertainty or config.uncertainty) if config.bayesian_bc else "mc_dropout"
        return cls(
            uncertainty=uncertainty,
            sigma0_sq=float(config.sigma0_sq),
            mc_passes=int(config.mc_passes),
            mc_dropout=bool(config.mc_dropout),
            members=int(config.ensemble_members) if uncertainty == "ensemble" else 1,
        )


MC_DROPOUT = VarianceEstimator()
"""The paper's estimator: 10 MC-dropout passes, σ0² = 0.5."""
LOCAL_FLOOR = 1e-6
"""The least fraction of σ0²'s confidence `local` keeps: σ² ≤ 10⁶·σ0²."""


def max_policy_variance(n_actions: int) -> float:
    """The largest mean_a Var_k[π^k(a|s)] any set of policies has: (1 − 1/A)/A.

    Var_k[p(a)] ≤ m_a(1 − m_a) for p(a) ∈ [0, 1] with mean m_a (equality: one-hot members),
    and Σ_a m_a(1 − m_a) is largest, 1 − 1/A, at m = uniform."""
    return (1.0 - 1.0 / n_actions) / n_actions


def policy_variance(probs: tf.Tensor) -> tf.Tensor:
    """mean_a Var_k[π^k(a|s)] of K policies probs (K, B, A) → (B,)."""
    return tf.reduce_mean(tf.math.reduce_variance(probs, axis=0), axis=1)


@keras.saving.register_keras_serializable(package="dqfd_bc_keras")
class EnsembleDense(keras.layers.Layer):
    """K independent dense layers applied at once: (K, B, in) → (K, B, units).

    Each member's kernel is drawn by Glorot-uniform for its own (in, units) shape, as a
    `Dense` layer's would be (Keras's initialiser would count K into the fan-in)."""

    def __init__(self, members: int, units: int, activation: str | None = None, **kwargs) -> None:
        super().__init__(**kwargs)
        self.members, self.units = int(members), int(units)
        self.activation = keras.activations.get(activation)

    def build(self, input_shape) -> None:
        fan_in = int(input_shape[-1])
        glorot = keras.initializers.GlorotUniform()
        self.kernel = self.add_weight(
            shape=(self.members, fan_in, self.units),
            name="kernel",
            initializer=lambda shape, dtype=None: tf.stack(
                [glorot((fan_in, self.units), dtype) for _ in range(shape[0])]
            ),
        )
        self.bias = self.add_weight(shape=(self.members, 1, self.units), initializer="zeros", name="bias")

    def call(self, x: tf.Tensor) -> tf.Tensor:
        return self.activation(tf.matmul(x, self.kernel) + self.bias)

    def compute_output_shape(self, input_shape):
        return (self.members, *tuple(input_shape)[1:-1], self.units)

    def get_config(self) -> dict:
        return {
            **super().get_config(),
            "members": self.members,
            "units": self.units,
            "activation": keras.activations.serialize(self.activation),
        }


def ensemble_stack(members: int, hidden: Sequence[int], n_out: int) -> list[keras.layers.Layer]:
    """K ReLU MLPs side by side, (K, B, d) → (K, B, n_out); no dropout (the members' spread
    is the uncertainty)."""
    layers = [EnsembleDense(members, units, "relu", name=f"hidden_{i}") for i, units in enumerate(hidden)]
    return [*layers, EnsembleDense(members, n_out, name="logits")]


def bootstrap_counts(members: int, n: int, seed: tf.Tensor) -> tf.Tensor:
    """(K, N) how often each of N pairs is drawn in each member's resample of size N.

    Weighting a pair's loss by its count is training on the resample: the same loss, the same
    gradient, without materialising K datasets."""
    draws = tf.random.stateless_uniform(
        [members, n], seed=tf.stack([seed, tf.constant(7, tf.int64)]), maxval=n, dtype=tf.int32
    )
    flat = draws + n * tf.range(members)[:, None]
    counts = tf.math.unsorted_segment_sum(tf.ones([members * n]), tf.reshape(flat, [-1]), members * n)
    return tf.reshape(counts, [members, n])


def reference_rows(n: int, capacity: int, seed: int) -> np.ndarray:
    """Which of n demonstrated states the distance estimator keeps: all, or a uniform subsample
    of `capacity` of them (in order)."""
    if n <= capacity:
        return np.arange(n)
    return np.sort(np.random.default_rng(seed).choice(n, capacity, replace=False))


DISTANCE_SIDE = 21
"""Frames are average-pooled to about this side before the distance estimator reads them (84 → 21)."""


def pooled_frames(obs: tf.Tensor, frames: Frames) -> tf.Tensor:
    """Frames (B, *shape) as the distance estimator reads them: in [0, 1], average-pooled to about
    `DISTANCE_SIDE` a side and flattened. Frames, not a torso's features: those change at every
    refit and are trained to tell actions apart, not to say how far a state is from the
    demonstrations; a MinAtar distance is then √(cells that differ)."""
    x = tf.cast(obs, tf.float32) * frames.scale
    x = x[..., None] if len(frames.shape) == 2 else x
    pool = max(1, min(frames.shape[:2]) // DISTANCE_SIDE)
    if pool > 1:
        x = tf.nn.avg_pool2d(x, pool, pool, "VALID")
    return tf.reshape(x, [tf.shape(x)[0], -1])


@keras.saving.register_keras_serializable(package="dqfd_bc_keras")
class NearestDemoVariance(keras.layers.Layer):
    """σ²(s) − σ0² = v·(1 − exp(−d(s)²/ℓ²)), d(s) the distance from standardised s to the
    nearest of (up to `capacity`) demonstrated states.

    Why this form: it is the posterior variance of a Gaussian process with an RBF kernel of
    length ℓ (k = exp(−d²/(2ℓ²))) and prior variance v, given the nearest demonstrated state
    alone, v·(1 − k²): 0 on the
    demonstrations, v far from them, and monotone in between. The full GP's variance given
    all of D_demo is never larger (more data only shrinks it), so this is its upper bound at
    the cost of one distance matrix; its cost and its memory are fixed by the `capacity`
    reference states (a uniform subsample once D_demo is larger). ℓ = 1 demonstration standard
    deviation, the unit the states are standardised in; v = `max_policy_variance(A)`, the
    most the other two estimators can express, so σ² is on their scale. Frames have no such
    unit (`length=None`): ℓ is then the median distance from a reference state to its nearest
    other one, so a state as far from D_demo as the demonstrations are from each other gets
    1 − e⁻¹ of v.
    """

    def __init__(
        self, obs_dim: int, n_actions: int, capacity: int = 2048, length: float | None = 1.0, **kwargs
    ) -> None:
        super().__init__(**kwargs)
        self.obs_dim, self.n_actions = int(obs_dim), int(n_actions)
        self.capacity, self.length = int(capacity), None if length is None else float(length)
        self.references = self.add_weight(
            shape=(self.capacity, self.obs_dim), initializer="zeros", trainable=False, name="references"
        )
        self.count = self.add_weight(shape=(), initializer="zeros", trainable=False, name="count")
        self.length_sq = self.add_weight(shape=(), initializer="ones", trainable=False, name="length_sq")
        """ℓ², fixed, or set from the references (`length=None`)."""
        if self.length is not None:
            self.length_sq.assign(self.length**2)

    def set_references(self, z: np.ndarray) -> None:
        """Remember demonstrated states `z` (n ≤ capacity, d) in the space distances are measured in
        (`uncertainty.reference_rows` picks them)."""
        padded = np.zeros((self.capacity, self.obs_dim), np.float32)
        padded[: len(z)] = z
        self.references.assign(padded)
        self.count.assign(float(len(z)))
        if self.length is None:
            self.length_sq.assign(self._median_nearest_sq(z))

    @staticmethod
    def _median_nearest_sq(z: np.ndarray) -> float:
        """The median over z of the squared distance to the nearest other row (1 with fewer than 2,
        or when every row is a duplicate)."""
        if len(z) < 2:
            return 1.0
        squared = (z**2).sum(1)[:, None] - 2.0 * z @ z.T + (z**2).sum(1)[None, :]
        np.fill_diagonal(squared, np.inf)
        median = float(np.median(np.maximum(squared.min(axis=1), 0.0)))
        return median if median > 0 else 1.0

    def nearest_distance(self, z: tf.Tensor) -> tf.Tensor:
        """d(s) for standardised states z (B, d) → (B,)."""
        r = self.references
        squared = (
            tf.reduce_sum(tf.square(z), axis=1, keepdims=True)
            - 2.0 * tf.matmul(z, r, transpose_b=True)
            + tf.reduce_sum(tf.square(r), axis=1)[None, :]
        )
        in_use = tf.range(self.capacity, dtype=tf.float32) < self.count
        squared = tf.where(in_use[None, :], squared, tf.constant(np.inf, tf.float32))
        return tf.sqrt(tf.maximum(tf.reduce_min(squared, axis=1), 0.0))

    def call(self, z: tf.Tensor) -> tf.Tensor:
        d = self.nearest_distance(z)
        return max_policy_variance(self.n_actions) * (1.0 - tf.exp(-tf.square(d) / self.length_sq))

    def get_config(self) -> dict:
        return {
            **super().get_config(),
            "obs_dim": self.obs_dim,
            "n_actions": self.n_actions,
            "capacity": self.capacity,
            "length": self.length,
        }
