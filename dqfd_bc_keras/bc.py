"""The behavioural-cloning classifier π_bc(a|s), fitted on D_demo (ALGORITHM.md §3).

Two ways to fit it, one `train_step`:
- MLE (for `ce` and `bc_margin`, as in DQfD-BC): plain cross entropy, no dropout;
- MAP (for `bayes`): cross entropy + a Gaussian weight prior ‖w‖²/(2·s²·N), with dropout kept
  active at prediction time (MC dropout), so `predictive` returns the mean policy π̄_bc and a
  variance σ²(s) = σ0² + mean_a Var_k[π_bc^k(a|s)] over K stochastic passes.
"""

from __future__ import annotations

from collections.abc import Sequence

import keras
import numpy as np
import tensorflow as tf

from .config import Config
from .networks import dense_stack, normalization
from .optimizers import FusedAdam


@keras.saving.register_keras_serializable(package="dqfd_bc_keras")
class BCModel(keras.Model):
    """MLP classifier: state (d,) → action logits (A,); `call` returns logits."""

    def __init__(
        self,
        obs_dim: int,
        n_actions: int,
        hidden: Sequence[int] = (64, 64),
        dropout: float = 0.0,
        prior_scale: float | None = None,
        mc_passes: int = 10,
        sigma0_sq: float = 0.5,
        mc_dropout: bool = True,
        obs_mean: Sequence[float] | None = None,
        obs_std: Sequence[float] | None = None,
        **kwargs,
    ) -> None:
        """`prior_scale=None` fits by MLE; a number s fits by MAP with the prior N(0, s²I).

        `obs_mean`/`obs_std` standardise the input (the demonstrations' statistics).
        `mc_dropout=False` predicts with one deterministic pass even when trained with dropout
        (the ablation "σ² fixed at σ0²").
        """
        super().__init__(**kwargs)
        self.obs_dim, self.n_actions = int(obs_dim), int(n_actions)
        self.hidden, self.dropout = tuple(int(h) for h in hidden), float(dropout)
        self.prior_scale = None if prior_scale is None else float(prior_scale)
        self.mc_passes, self.sigma0_sq, self.mc_dropout = int(mc_passes), float(sigma0_sq), bool(mc_dropout)
        self.obs_mean = None if obs_mean is None else [float(x) for x in obs_mean]
        self.obs_std = None if obs_std is None else [float(x) for x in obs_std]
        self.stack = dense_stack(self.hidden, self.n_actions, self.dropout)
        if obs_mean is not None:
            self.stack.insert(0, normalization(self.obs_mean, self.obs_std))
        # N of the prior's 1/N scaling: the size of the dataset being fitted (set by `fit_demos`).
        self.n_data = self.add_weight(shape=(), initializer="ones", trainable=False, name="n_data")
        self.loss_tracker = keras.metrics.Mean(name="loss")
        self.ce_tracker = keras.metrics.Mean(name="cross_entropy")
        self.accuracy = keras.metrics.SparseCategoricalAccuracy(name="accuracy")
        self.build((None, self.obs_dim))

    def build(self, input_shape) -> None:
        shape = tuple(input_shape)
        for layer in self.stack:
            layer.build(shape)
            shape = layer.compute_output_shape(shape)
        super().build(input_shape)

    def call(self, obs: tf.Tensor, training: bool = False) -> tf.Tensor:
        x = obs
        for layer in self.stack:
            x = layer(x, training=training)
        return x

    @property
    def map_fit(self) -> bool:
        return self.prior_scale is not None

    @property
    def metrics(self) -> list[keras.metrics.Metric]:
        return [self.loss_tracker, self.ce_tracker, self.accuracy]

    def prior_loss(self) -> tf.Tensor:
        """‖w‖²/(2·s²·N) over every weight (MAP), or 0 (MLE)."""
        if not self.map_fit:
            return tf.constant(0.0)
        squared = tf.add_n([tf.reduce_sum(tf.square(w)) for w in self.trainable_weights])
        return squared / (2.0 * self.prior_scale**2 * self.n_data)

    def train_step(self, data):
        obs, actions = data
        with tf.GradientTape() as tape:
            logits = self(obs, training=True)
            ce = self.cross_entropy(actions, logits)
            loss = ce + self.prior_loss()
        grads = tape.gradient(loss, self.trainable_weights)
        self.optimizer.apply(grads, self.trainable_weights)
        return self._record(actions, logits, ce, loss)

    def test_step(self, data):
        obs, actions = data
        logits = self(obs, training=False)
        ce = self.cross_entropy(actions, logits)
        return self._record(actions, logits, ce, ce + self.prior_loss())

    @staticmethod
    def cross_entropy(actions: tf.Tensor, logits: tf.Tensor) -> tf.Tensor:
        """mean −log π_bc(a_E|s) over the batch."""
        return tf.reduce_mean(tf.nn.sparse_softmax_cross_entropy_with_logits(tf.cast(actions, tf.int32), logits))

    def _record(self, actions, logits, ce, loss) -> dict[str, tf.Tensor]:
        self.loss_tracker.update_state(loss)
        self.ce_tracker.update_state(ce)
        self.accuracy.update_state(actions, logits)
        return {m.name: m.result() for m in self.metrics}

    def predictive(self, obs: tf.Tensor) -> tuple[tf.Tensor, tf.Tensor]:
        """(π̄_bc (B, A), σ² (B,)): the mean and variance of K MC-dropout passes, in one graph.

        Without dropout (the MLE model) every pass is the same: π̄_bc = π_bc and σ² = σ0²; so it
        is with `mc_dropout=False`.
        """
        if self.dropout == 0.0 or not self.mc_dropout:
            probs = tf.nn.softmax(self(obs, training=False))
            return probs, tf.fill(tf.shape(probs)[:1], tf.constant(self.sigma0_sq, probs.dtype))
        batch = tf.shape(obs)[0]
        logits = self(tf.tile(obs, [self.mc_passes, 1]), training=True)
        probs = tf.reshape(tf.nn.softmax(logits), [self.mc_passes, batch, self.n_actions])
        pi_bar = tf.reduce_mean(probs, axis=0)
        epistemic = tf.reduce_mean(tf.math.reduce_variance(probs, axis=0), axis=1)
        return pi_bar, self.sigma0_sq + epistemic

    def fit_demos(
        self, obs: np.ndarray, actions: np.ndarray, epochs: int, batch_size: int = 64, seed: int = 0
    ) -> dict[str, float]:
        """Fit (or, called again, warm-start) on demonstration pairs (s, a_E); N = len(obs).

        Each epoch visits every pair once in a fresh random order (from `seed` and the epoch),
        in batches of `batch_size` (the last one smaller), through `train_step`; all epochs run
        in one graph call. Keras's `fit` spent ~1.5 s per call here on its data pipeline and
        callbacks, for a few hundred half-millisecond steps. Returns the last epoch's metrics.
        """
        self.n_data.assign(float(len(obs)))
        if epochs > 0:
            self._fit(tf.constant(obs, tf.float32), tf.constant(actions, tf.int32), tf.constant(epochs),
                      tf.constant(min(batch_size, len(obs))), tf.constant(seed, tf.int64))
        return {metric.name: float(metric.result()) for metric in self.metrics}

    @tf.function(autograph=False, input_signature=[
        tf.TensorSpec([None, None], tf.float32), tf.TensorSpec([None], tf.int32), tf.TensorSpec([], tf.int32),
        tf.TensorSpec([], tf.int32), tf.TensorSpec([], tf.int64)])
    def _fit(self, obs, actions, epochs, batch_size, seed) -> None:
        n = tf.shape(obs)[0]
        batches = (n + batch_size - 1) // batch_size

        def epoch(e):
            for metric in self.metrics:
                metric.reset_state()
            order = tf.argsort(tf.random.stateless_uniform([n], seed=tf.stack([seed, tf.cast(e, tf.int64)])))

            def batch(b):
                rows = order[b * batch_size: tf.minimum((b + 1) * batch_size, n)]
                with tf.control_dependencies([self.train_step((tf.gather(obs, rows), tf.gather(actions, rows)))["loss"]]):
                    return b + 1

            with tf.control_dependencies([tf.while_loop(lambda b: b < batches, batch, [tf.constant(0)])]):
                return e + 1

        tf.while_loop(lambda e: e < epochs, epoch, [tf.constant(0)])

    def get_config(self) -> dict:
        return {
            **super().get_config(),
            "obs_dim": self.obs_dim, "n_actions": self.n_actions, "hidden": list(self.hidden),
            "dropout": self.dropout, "prior_scale": self.prior_scale, "mc_passes": self.mc_passes,
            "sigma0_sq": self.sigma0_sq, "mc_dropout": self.mc_dropout, "obs_mean": self.obs_mean, "obs_std": self.obs_std,
        }


def build_bc_model(
    config: Config, obs_dim: int, n_actions: int, obs_scale: tuple[np.ndarray, np.ndarray] | None = None
) -> BCModel:
    """The BC model `config.expert_loss` calls for: MAP with dropout for bayes, MLE otherwise."""
    bayesian = config.bayesian_bc
    mean, std = (None, None) if obs_scale is None else obs_scale
    model = BCModel(
        obs_dim, n_actions, hidden=config.bc_hidden, dropout=config.bc_dropout if bayesian else 0.0,
        prior_scale=config.bc_prior_scale if bayesian else None, mc_passes=config.mc_passes,
        sigma0_sq=config.sigma0_sq, mc_dropout=config.mc_dropout, obs_mean=mean, obs_std=std, name="bc_model",
    )
    model.compile(optimizer=FusedAdam(config.bc_learning_rate))
    return model
