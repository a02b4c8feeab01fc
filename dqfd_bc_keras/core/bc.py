"""The behavioural-cloning classifier π_bc(a|s), fitted on D_demo (ALGORITHM.md §3).

Two ways to fit it, one `train_step`:
- MLE (for `ce` and `bc_margin`, as in DQfD-BC): plain cross entropy, no dropout;
- MAP (for `bayes`): cross entropy + a Gaussian weight prior ‖w‖²/(2·s²·N), and `predictive`
  returns the mean policy π̄_bc and a variance σ²(s) = σ0² + the epistemic part from one of
  `choices.UNCERTAINTIES`: MC dropout (the paper's: dropout kept active for K passes), an
  ensemble of K members on bootstrap resamples, or the distance to the demonstrations.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import keras
import numpy as np
import numpy.typing as npt
import tensorflow as tf

from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.core.networks import dense_stack, torso_layers
from dqfd_bc_keras.core.optimizers import FusedAdam
from dqfd_bc_keras.core.uncertainty import (
    MC_DROPOUT,
    NearestDemoVariance,
    VarianceEstimator,
    bootstrap_counts,
    ensemble_stack,
    policy_variance,
    pooled_frames,
    reference_rows,
)
from dqfd_bc_keras.envs.frames import Frames
from dqfd_bc_keras.envs.network_input import NetworkInput, as_input


@dataclass(frozen=True)
class BCNetwork:
    """The classifier's dense layers and how they are fitted: by MLE (`prior_scale` None) or by MAP
    with the prior N(0, s²I), s = `prior_scale`; `dropout` acts in the dense layers. The default:
    two ReLU layers of 64, no dropout, MLE."""

    hidden: tuple[int, ...] = (64, 64)
    dropout: float = 0.0
    prior_scale: float | None = None

    @property
    def map_fit(self) -> bool:
        return self.prior_scale is not None


@keras.saving.register_keras_serializable(package="dqfd_bc_keras")
class BCModel(keras.Model):
    """Classifier: state (a vector (d,), or frames through a convolutional torso) → action logits
    (A,); `call` returns logits."""

    def __init__(
        self,
        net_input: int | NetworkInput,
        n_actions: int,
        network: BCNetwork = BCNetwork(),
        estimator: VarianceEstimator = MC_DROPOUT,
        obs_scale: tuple[npt.ArrayLike, npt.ArrayLike] | None = None,
        **kwargs,
    ) -> None:
        """`net_input` is what it reads (vectors of that width, or frames and their torso);
        `obs_scale` (mean, std) standardises vectors (the demonstrations' statistics). `estimator`
        is σ²'s: an ensemble's members, and dropout, are in the dense layers after the
        torso, which is where they act on frames too (an ensemble's members then share the torso,
        as Bootstrapped DQN's heads do: Osband et al. 2016). `build_bc_model` makes it from a Config.
        """
        super().__init__(**kwargs)
        self.net_input, self.n_actions = as_input(net_input), int(n_actions)
        self.network, self.estimator = network, estimator
        scale = None if obs_scale is None else [[float(x) for x in np.ravel(part)] for part in obs_scale]
        self.obs_scale = None if scale is None else (scale[0], scale[1])
        """(mean, std) as lists of floats, as saved; frames read none of it (they are scaled to [0, 1])."""
        self.body = torso_layers(self.net_input, None if self.net_input.image else self.obs_scale)
        """Standardisation (vectors) or the convolutional torso (frames): what the dense layers read."""
        self.stack = (
            ensemble_stack(estimator.members, network.hidden, self.n_actions)
            if estimator.ensemble
            else dense_stack(network.hidden, self.n_actions, network.dropout)
        )
        self.distance = (
            NearestDemoVariance(
                self._distance_width(),
                self.n_actions,
                name="nearest_demo_variance",
                length=None if self.net_input.image else 1.0,
            )
            if estimator.nearest_demo
            else None
        )
        # N of the prior's 1/N scaling: the size of the dataset being fitted (set by `fit_demos`).
        self.n_data = self.add_weight(shape=(), initializer="ones", trainable=False, name="n_data")
        self.loss_tracker = keras.metrics.Mean(name="loss")
        self.ce_tracker = keras.metrics.Mean(name="cross_entropy")
        self.accuracy = keras.metrics.SparseCategoricalAccuracy(name="accuracy")
        self._fit = tf.function(
            self._fit_graph,
            autograph=False,
            input_signature=[
                tf.TensorSpec([None, *self.net_input.shape], self.net_input.dtype),
                tf.TensorSpec([None], tf.int32),
                tf.TensorSpec([], tf.int32),
                tf.TensorSpec([], tf.int32),
                tf.TensorSpec([], tf.int64),
            ],
        )
        self.build((None, *self.net_input.shape))

    def build(self, input_shape) -> None:
        shape = tuple(input_shape)
        for layer in self.body:
            layer.build(shape)
            shape = layer.compute_output_shape(shape)
        shape = (self.estimator.members, *shape) if self.ensemble else shape
        for layer in self.stack:
            layer.build(shape)
            shape = layer.compute_output_shape(shape)
        super().build(input_shape)

    def call(self, obs: tf.Tensor, training: bool = False) -> tf.Tensor:
        """Logits of π̄_bc: the network's, or for an ensemble log of the members' mean policy."""
        logits = self.member_logits(obs, training)
        return self._mean_policy_logits(logits) if self.ensemble else logits

    @staticmethod
    def _mean_policy_logits(member_logits: tf.Tensor) -> tf.Tensor:
        """log mean_k softmax(logits_k): (K, B, A) → (B, A), the ensemble's π̄_bc as logits."""
        return tf.math.log(tf.reduce_mean(tf.nn.softmax(member_logits), axis=0) + 1e-12)

    def member_logits(self, obs: tf.Tensor, training: bool = False) -> tf.Tensor:
        """(K, B, A) logits of each ensemble member, or (B, A) of the one network."""
        return self.head_logits(self.features(obs), training)

    def head_logits(self, x: tf.Tensor, training: bool = False) -> tf.Tensor:
        """The dense layers (dropout, or the ensemble's members) on features `x` (B, f)."""
        if self.ensemble:
            x = tf.broadcast_to(x[None], [self.estimator.members, tf.shape(x)[0], x.shape[-1]])
        for layer in self.stack:
            x = layer(x, training=training)
        return x

    def features(self, obs: tf.Tensor) -> tf.Tensor:
        """What the dense layers read: vectors in the demonstrations' standard units (as given
        without statistics), or the torso's features of frames."""
        x = obs if self.net_input.image else tf.cast(obs, tf.float32)
        for layer in self.body:
            x = layer(x)
        return x

    def distance_view(self, obs: tf.Tensor) -> tf.Tensor:
        """The space the distance estimator measures in: standardised vectors, or the frames pooled
        (`uncertainty.pooled_frames`)."""
        frames = self.net_input.frames
        return self.features(obs) if frames is None else pooled_frames(obs, frames)

    def _distance_width(self) -> int:
        """Features of `distance_view`: the observation's width, or what pooling leaves of the frames."""
        if not self.net_input.image:
            return self.net_input.dim
        return int(self.distance_view(tf.zeros([1, *self.net_input.shape], tf.uint8)).shape[1])

    @property
    def ensemble(self) -> bool:
        return self.estimator.ensemble

    @property
    def metrics(self) -> list[keras.metrics.Metric]:
        return [self.loss_tracker, self.ce_tracker, self.accuracy]

    def prior_loss(self) -> tf.Tensor:
        """‖w‖²/(2·s²·N) over every weight (MAP), or 0 (MLE); an ensemble's members each have
        their own prior, so this is their sum."""
        scale = self.network.prior_scale
        if scale is None:
            return tf.constant(0.0)
        squared = tf.add_n([tf.reduce_sum(tf.square(w)) for w in self.trainable_weights])
        return squared / (2.0 * scale**2 * self.n_data)

    def train_step(self, data):
        """One step on mean cross entropy + prior; an ensemble's data carries (K, B) bootstrap
        counts, and its loss is the sum of the members' losses (each member its own gradient)."""
        obs, actions, counts = data if len(data) == 3 else (*data, None)
        with tf.GradientTape() as tape:
            logits = self.member_logits(obs, training=True)
            if self.ensemble:
                per_pair = tf.nn.sparse_softmax_cross_entropy_with_logits(
                    tf.broadcast_to(tf.cast(actions, tf.int32)[None], tf.shape(logits)[:2]), logits
                )
                ce = tf.reduce_mean(per_pair)
                loss = tf.reduce_sum(tf.reduce_mean(counts * per_pair, axis=1)) + self.prior_loss()
            else:
                ce = self.cross_entropy(actions, logits)
                loss = ce + self.prior_loss()
        grads = tape.gradient(loss, self.trainable_weights)
        self.optimizer.apply(grads, self.trainable_weights)
        return self._record(actions, self._mean_policy_logits(logits) if self.ensemble else logits, ce, loss)

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
        """(π̄_bc (B, A), σ² (B,)), σ² from σ0² and the estimator's epistemic variance v
        (`VarianceEstimator.sigma_sq`: σ0² + v but for `local`), in one graph:

        mc_dropout  the mean and variance of K dropout passes;
        ensemble    the mean and variance of the K members;
        distance    one deterministic pass, and the nearest-demonstration variance;
        local       the same pass and variance, σ² = σ0²/(1 − v/v_max).
        Without dropout (the MLE model) every MC pass is the same: π̄_bc = π_bc and σ² = σ0²; so
        it is with `mc_dropout=False`.
        """
        sigma0_sq, passes = self.estimator.sigma0_sq, self.estimator.mc_passes
        if self.ensemble:
            probs = tf.nn.softmax(self.member_logits(obs))
            return tf.reduce_mean(probs, axis=0), self.estimator.sigma_sq(policy_variance(probs), self.n_actions)
        if self.distance is not None:
            variance = self.distance(self.distance_view(obs))
            return tf.nn.softmax(self(obs)), self.estimator.sigma_sq(variance, self.n_actions)
        if self.network.dropout == 0.0 or not self.estimator.mc_dropout:
            probs = tf.nn.softmax(self(obs, training=False))
            return probs, tf.fill(tf.shape(probs)[:1], tf.constant(sigma0_sq, probs.dtype))
        batch = tf.shape(obs)[0]
        # The body has no dropout: its features are computed once and the K passes share them.
        logits = self.head_logits(tf.tile(self.features(obs), [passes, 1]), training=True)
        probs = tf.reshape(tf.nn.softmax(logits), [passes, batch, self.n_actions])
        return tf.reduce_mean(probs, axis=0), self.estimator.sigma_sq(policy_variance(probs), self.n_actions)

    def fit_demos(
        self, obs: np.ndarray, actions: np.ndarray, epochs: int, batch_size: int = 64, seed: int = 0
    ) -> dict[str, float]:
        """Fit (or, called again, warm-start) on demonstration pairs (s, a_E); N = len(obs).

        Each epoch visits every pair once in a fresh random order (from `seed` and the epoch),
        in batches of `batch_size` (the last one smaller), through `train_step`; all epochs run
        in one graph call: Keras's `fit` spent more on its data pipeline and callbacks than on
        the steps themselves (docs/PERFORMANCE.md). Each fit draws an ensemble's
        bootstrap resamples afresh and a distance estimator's reference states. Returns the
        last epoch's metrics.
        """
        self.n_data.assign(float(len(obs)))
        if self.distance is not None:
            rows = reference_rows(len(obs), self.distance.capacity, seed)
            self.distance.set_references(self.distance_view(tf.constant(obs[rows])).numpy())
        if epochs > 0:
            self._fit(
                tf.constant(obs, self.net_input.dtype),
                tf.constant(actions, tf.int32),
                tf.constant(epochs),
                tf.constant(min(batch_size, len(obs))),
                tf.constant(seed, tf.int64),
            )
        return {metric.name: float(metric.result()) for metric in self.metrics}

    def _fit_graph(self, obs, actions, epochs, batch_size, seed) -> None:
        n = tf.shape(obs)[0]
        batches = (n + batch_size - 1) // batch_size
        counts = bootstrap_counts(self.estimator.members, n, seed) if self.ensemble else None

        def epoch(e):
            for metric in self.metrics:
                metric.reset_state()
            order = tf.argsort(tf.random.stateless_uniform([n], seed=tf.stack([seed, tf.cast(e, tf.int64)])))

            def batch(b):
                rows = order[b * batch_size : tf.minimum((b + 1) * batch_size, n)]
                data = (tf.gather(obs, rows), tf.gather(actions, rows))
                data += (tf.gather(counts, rows, axis=1),) if self.ensemble else ()
                with tf.control_dependencies([self.train_step(data)["loss"]]):
                    return b + 1

            with tf.control_dependencies([tf.while_loop(lambda b: b < batches, batch, [tf.constant(0)])]):
                return e + 1

        tf.while_loop(lambda e: e < epochs, epoch, [tf.constant(0)])

    def get_config(self) -> dict:
        """The settings flat, under the keys every saved BC model has (`from_config` groups them)."""
        frames, (mean, std) = self.net_input.frames, self.obs_scale or (None, None)
        return {
            **super().get_config(),
            "obs_dim": self.net_input.dim,
            "n_actions": self.n_actions,
            "hidden": list(self.network.hidden),
            "dropout": self.network.dropout,
            "prior_scale": self.network.prior_scale,
            **dataclasses.asdict(self.estimator),
            "obs_mean": mean,
            "obs_std": std,
            "frames": None
            if frames is None
            else {"shape": list(frames.shape), "scale": frames.scale, "stack": frames.stack},
            "torso": self.net_input.torso,
        }

    @classmethod
    def from_config(cls, config: dict) -> BCModel:
        """The model of `get_config`'s settings; a model saved before a setting existed (no
        `frames`, `torso`, nor the estimator's newer fields) gets its default."""
        config = dict(config)
        frames = config.pop("frames", None)
        frames = (
            None
            if frames is None
            else Frames(tuple(int(n) for n in frames["shape"]), float(frames["scale"]), int(frames.get("stack", 1)))
        )
        torso = config.pop("torso", "mlp")
        net_input = NetworkInput(int(config.pop("obs_dim")), frames, torso if frames is not None else "mlp")
        prior_scale = config.pop("prior_scale")
        network = BCNetwork(
            tuple(int(h) for h in config.pop("hidden")),
            float(config.pop("dropout")),
            None if prior_scale is None else float(prior_scale),
        )
        estimator = VarianceEstimator.from_saved(config)
        mean, std = config.pop("obs_mean", None), config.pop("obs_std", None)
        scale = None if mean is None else (mean, std)
        return cls(net_input, config.pop("n_actions"), network, estimator, scale, **config)


def build_bc_model(
    config: Config,
    net_input: int | NetworkInput,
    n_actions: int,
    obs_scale: tuple[np.ndarray, np.ndarray] | None = None,
) -> BCModel:
    """The BC model `config.expert_loss` calls for: MLE for ce and bc_margin; MAP for bayes,
    with `config.uncertainty`'s estimator (dropout for mc_dropout and distance, whose π̄_bc is
    then the paper's MAP network's; none in an ensemble's members)."""
    estimator = VarianceEstimator.from_config(config)
    bayesian = config.bayesian_bc
    network = BCNetwork(
        hidden=tuple(int(h) for h in config.bc_hidden),
        dropout=float(config.bc_dropout) if bayesian and not estimator.ensemble else 0.0,
        prior_scale=float(config.bc_prior_scale) if bayesian else None,
    )
    model = BCModel(net_input, n_actions, network, estimator, obs_scale, name="bc_model")
    model.compile(optimizer=FusedAdam(config.bc_learning_rate))
    return model
