"""The Q-agent: a Keras model whose custom `train_step` is the only place J(Q) is assembled.

    J(Q) = J_DQ(Q) + λ1·J_n(Q) + λ2·J_E(Q) + λ3·J_L2(Q)          (paper Eq. 4, ALGORITHM.md §2)

`train_step(batch)` takes a prioritized batch, calls the pure loss functions, takes one Adam
step on θ, refreshes θ' every τ steps and returns δ for the priority write-back. `learn(K)`
runs K × (sample → train_step → write priorities) in one graph call: pre-training (demos only)
and online training go through it, and the graph-call boundary, not the math, is what costs.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING

import keras
import numpy as np
import tensorflow as tf

from dqfd_bc_keras.choices import LOSS_TERMS
from dqfd_bc_keras.core import losses
from dqfd_bc_keras.core.bc import BCModel
from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.core.networks import NetworkInput, as_input, build_q_network
from dqfd_bc_keras.core.optimizers import FusedAdam
from dqfd_bc_keras.core.replay import Batch, PrioritizedReplay, ReplaySettings
from dqfd_bc_keras.errors import ConfigError

if TYPE_CHECKING:
    from dqfd_bc_keras.demos.dataset import DemoDataset

WEIGHED_ROWS = 1024
"""The most rows of D_demo, and of D_replay, whose imitation weights are averaged after each episode."""


class MeanVector(keras.metrics.Metric):
    """Running means of named scalars in two variables: one update is two ops, where a
    `keras.metrics.Mean` per scalar adds several ops each to every learning step. Values come and
    go by name, so a term added or reordered cannot land in another's column."""

    def __init__(self, names: tuple[str, ...], name: str = "mean_vector") -> None:
        super().__init__(name=name)
        self.names = names
        self.total = self.add_variable(shape=(len(names),), initializer="zeros", name="total")
        self.count = self.add_variable(shape=(), initializer="zeros", name="count")

    def update_state(self, values: Mapping[str, tf.Tensor]) -> None:
        """Add one value of each name; a name missing or unknown raises when the graph is traced."""
        if set(values) != set(self.names):
            raise ValueError(f"{self.name} takes the values {self.names}, got {tuple(values)}")
        self.total.assign_add(tf.stack([values[name] for name in self.names]))
        self.count.assign_add(1.0)

    def result(self) -> dict[str, tf.Tensor]:
        return dict(zip(self.names, tf.unstack(tf.math.divide_no_nan(self.total, self.count)), strict=True))


class DQfDAgent(keras.Model):
    """Q(s, ·; θ), the target network θ', θ_prior, and the learning step over a replay.

    `net_input` is what the Q-network takes: a `NetworkInput`, or the width of a vector state."""

    def __init__(
        self,
        config: Config,
        net_input: int | NetworkInput,
        n_actions: int,
        replay: PrioritizedReplay,
        bc_model: BCModel | None = None,
        obs_scale: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> None:
        super().__init__(name="dqfd_agent")
        if config.uses_bc and bc_model is None:
            raise ConfigError(f"expert_loss={config.expert_loss!r} needs a fitted BC model")
        self.config = config
        self.method = config.method
        self.expert_term = self.method.expert_term()
        self.imitation_weight = self.method.weight_term()
        self.net_input = as_input(net_input)
        self.obs_dim, self.n_actions = self.net_input.dim, int(n_actions)
        self.q_network = build_q_network(self.net_input, n_actions, config.hidden, obs_scale)
        self.target_network = build_q_network(
            self.net_input, n_actions, config.hidden, obs_scale, name="target_network"
        )
        self.target_network.trainable = False
        self.replay = replay
        self.bc_model = bc_model
        if bc_model is not None:  # the BC model's view of self-generated states, in the replay's batches
            replay.expert_view = self.expert_targets
        # θ_prior of the Bayesian loss: zero during pre-training, then (by default) the
        # pre-trained weights (`capture_prior`).
        self.prior_weights = [
            tf.Variable(tf.zeros_like(w), trainable=False, name="prior") for w in self.q_network.trainable_weights
        ]
        self.train_steps = tf.Variable(0, dtype=tf.int64, trainable=False, name="train_steps")
        self.expert_scale = tf.Variable(1.0, trainable=False, name="expert_scale")
        """w_E of a method with a `decay` (methods.py), set after each episode from the run's
        returns (`expert_terms.next_expert_scale`; TrainingState keeps it); 1 for the others."""
        self.loss_means = MeanVector(LOSS_TERMS, name="losses")
        self.expert_view = tf.function(
            self.expert_targets,
            autograph=False,
            input_signature=[tf.TensorSpec([None, *self.net_input.shape], self.net_input.dtype)],
        )
        """`expert_targets` of many states outside a graph (D_demo, refits): traced once."""
        self.compile(optimizer=FusedAdam(config.learning_rate))
        self.optimizer.build(self.q_network.trainable_variables)
        self.refresh_target()

    def call(self, obs: tf.Tensor) -> tf.Tensor:
        return self.q_network(obs)

    @property
    def metrics(self) -> list[keras.metrics.Metric]:
        return [self.loss_means]

    def losses_so_far(self) -> dict[str, tf.Tensor]:
        """The mean of each term of J(Q) over the learning steps since `reset_metrics`."""
        return self.loss_means.result()

    @tf.function(input_signature=[], autograph=False)
    def take_losses(self) -> dict[str, tf.Tensor]:
        """`losses_so_far`, then `reset_metrics`, in one graph call (one an episode, and MinAtar's
        first episodes last a dozen steps)."""
        losses = {name: tf.identity(value) for name, value in self.losses_so_far().items()}
        with tf.control_dependencies(list(losses.values())):
            self.reset_metrics()
        return losses

    @property
    def theta(self) -> list[keras.Variable]:
        """θ, the Q-network's trainable weights (methods.TermAgent: what a method's term may read)."""
        return self.q_network.trainable_weights

    @property
    def demo_size(self) -> tf.Variable:
        """N = |D_demo| (methods.TermAgent)."""
        return self.replay.demo_size

    def refresh_target(self) -> None:
        """θ' ← θ."""
        for target, online in zip(self.target_network.weights, self.q_network.weights, strict=True):
            target.assign(online)

    def capture_prior(self) -> None:
        """θ_prior ← θ at the end of pre-training (`prior_center="pretrained"`), else keep 0."""
        if self.config.prior_center == "pretrained":
            for prior, weight in zip(self.prior_weights, self.q_network.trainable_weights, strict=True):
                prior.assign(weight)

    def beta(self) -> tf.Tensor:
        """β of the importance weights, linear from β0 to 1 over `beta_anneal_steps` steps."""
        c = self.config
        progress = tf.minimum(1.0, tf.cast(self.train_steps, tf.float32) / max(c.beta_anneal_steps, 1))
        return c.priority_beta0 + (1.0 - c.priority_beta0) * progress

    def expert_targets(self, obs: tf.Tensor) -> tuple[tf.Tensor, tf.Tensor]:
        """(π̄_bc (n, A), σ² (n,)) of the BC model for states `obs`; uniform and σ0² without one."""
        if self.bc_model is None:
            n = tf.shape(obs)[0]
            return tf.fill([n, self.n_actions], 1.0 / self.n_actions), tf.fill([n], self.config.sigma0_sq)
        return self.bc_model.predictive(obs)

    def imitation_weights(self) -> tuple[float | None, float | None]:
        """The imitation weight J_E puts on a row (`Method.weight`: 1/(2σ²) for the Bayesian
        likelihood, the Q-filter's 0 or 1, w_E) averaged over D_demo's rows and over D_replay's, as
        the rows hold them for the loss: how much more the loss imitates on demonstrated states than
        on the agent's own (rows not settled yet, NaN, left out). A region of more than
        `WEIGHED_ROWS` rows is read at that many evenly spaced rows. None for a method without a
        weight, and for an empty replay."""
        if self.imitation_weight is None:
            return None, None
        (on_demos, n_demos), (on_agents, n_agents) = self._mean_imitation_weights()
        return (float(on_demos) if n_demos else None), (float(on_agents) if n_agents else None)

    @tf.function(input_signature=[], autograph=False)
    def _mean_imitation_weights(self) -> tuple[tuple[tf.Tensor, tf.Tensor], tuple[tf.Tensor, tf.Tensor]]:
        """(mean weight, rows counted) over D_demo and over D_replay, in one graph call: it comes
        after every episode, and MinAtar's first episodes last a dozen steps."""
        r, imitation_weight = self.replay, self.imitation_weight
        assert imitation_weight is not None, "imitation_weights() asks only a method with a weight"

        def mean_weight(start: tf.Tensor, size: tf.Tensor) -> tuple[tf.Tensor, tf.Tensor]:
            count, size = tf.cast(tf.minimum(size, WEIGHED_ROWS), tf.int64), tf.cast(size, tf.int64)
            spaced = tf.range(count) * size // tf.maximum(count, 1)
            batch = r.rows_as_batch(start + tf.cast(spaced, tf.int32))
            settled = tf.logical_not(tf.math.is_nan(batch.sigma_sq))
            weight = imitation_weight(self, self.q_network(batch.obs), batch)
            weight = tf.boolean_mask(weight, settled)
            return tf.reduce_mean(weight), tf.size(weight)

        return mean_weight(tf.constant(0), r.demo_size), mean_weight(tf.constant(r.demo_capacity), r.agent_size)

    @property
    def sqil(self) -> bool:
        """SQIL learns from rewards 1 on demonstrations and 0 on its own data, in balanced batches."""
        return self.method.sqil_rewards

    def set_demos(self, obs, actions, rewards, next_obs, terminated, truncated) -> None:
        """Fill D_demo with these transitions (with the BC model's view of each state)."""
        rewards = np.ones_like(rewards) if self.sqil else rewards
        pi_bc, sigma_sq = self.expert_view(tf.constant(obs, self.net_input.dtype))
        if self.replay.frame_pool is not None:  # frames: the table holds their pool indices
            obs, next_obs = self.replay.frame_pool.store_demos(obs, next_obs, np.logical_or(terminated, truncated))
        self.replay.set_demos(self.replay.rows(obs, actions, rewards, next_obs, terminated, truncated, pi_bc, sigma_sq))

    def store(self, obs, action, reward, next_obs, terminated, truncated) -> None:
        """Append one self-generated transition to D_replay (graph-compatible). With a BC model its
        view of s (π̄_bc, σ²) is written when the replay settles the row, with the rows stored
        around it, before the next sample: NaN until then, so an early read could not pass unseen."""
        if self.bc_model is None:
            pi_bc, sigma_sq = self.expert_targets(tf.cast(obs, self.net_input.dtype)[None])
        else:
            pi_bc, sigma_sq = tf.fill([1, self.n_actions], np.nan), tf.fill([1], np.nan)
        reward = 0.0 * tf.cast(reward, tf.float32) if self.sqil else reward
        if self.replay.frame_pool is not None:  # frames: the table holds their pool indices
            obs, next_obs = self.replay.frame_pool.store(obs, next_obs)
        self.replay.store(
            self.replay.rows(obs[None], action, reward, next_obs[None], terminated, truncated, pi_bc, sigma_sq)[0]
        )

    def refresh_expert_targets(self, chunk: int = 8192) -> None:
        """Recompute π̄_bc and σ² of every stored row, after the BC model was refitted."""
        indices = self.replay.stored_indices()
        for start in range(0, int(indices.shape[0]), chunk):
            rows = indices[start : start + chunk]
            self.replay.set_expert_targets(rows, *self.expert_view(self.replay.states(rows)))

    def expert_loss(self, q: tf.Tensor, batch: Batch) -> tf.Tensor:
        """J_E of the config's method (methods.py; the built-in terms are in expert_terms.py)."""
        return tf.constant(0.0) if self.expert_term is None else self.expert_term(self, q, batch)

    def train_step(self, batch: Batch) -> tf.Tensor:
        """One gradient step on J(Q) for `batch`; returns the 1-step TD errors δ, (B,)."""
        c = self.config
        B = tf.shape(batch.actions)[0]
        theta = self.q_network.trainable_weights
        q_next_target, q_n_next_target = tf.split(
            self.target_network(tf.concat([batch.next_obs, batch.n_next_obs], 0)), [B, B]
        )
        # The online network's view of s' is only read by the double-DQN target.
        q_next = q_n_next = None
        if c.target == "double":
            q_next, q_n_next = tf.split(self.q_network(tf.concat([batch.next_obs, batch.n_next_obs], 0)), [B, B])
        with tf.GradientTape() as tape:
            q = self.q_network(batch.obs)
            # J_DQ: y = r + γ(1 − terminated)·V'(s_{t+1})
            y = losses.td_target(batch.rewards, batch.discount, losses.bootstrap_value(q_next_target, q_next, c.target))
            delta = losses.td_error(q, batch.actions, y)
            j_dq = losses.weighted_mean(losses.td_loss(delta, c.td_loss), batch.weights)
            # J_n: y_n = Σ_{k<m} γ^k r_{t+k} + γ^m(1 − terminated)·V'(s_{t+m})
            y_n = losses.td_target(
                batch.n_returns, batch.n_discount, losses.bootstrap_value(q_n_next_target, q_n_next, c.target)
            )
            j_n = losses.weighted_mean(losses.td_loss(losses.td_error(q, batch.actions, y_n), c.td_loss), batch.weights)
            j_e = self.expert_loss(q, batch)
            j_l2 = losses.l2_loss([layer.kernel for layer in self.q_network.layers if hasattr(layer, "kernel")])
            loss = j_dq + c.lambda_n * j_n + c.lambda_expert * j_e + c.lambda_l2 * j_l2
        self.optimizer.apply(tape.gradient(loss, theta), theta)
        self.train_steps.assign_add(1)
        tf.cond(self.train_steps % c.target_update_period == 0, self.refresh_target, lambda: None)
        self.loss_means.update_state({"loss": loss, "td": j_dq, "n_step": j_n, "expert": j_e, "l2": j_l2})
        return delta

    def learn_step(self) -> None:
        """Sample a prioritized batch → train_step → write back |δ| as the new priorities
        (SQIL: a balanced uniform batch, and no priorities)."""
        if self.sqil:
            self.train_step(self.replay.sample_balanced(self.config.batch_size))
            return
        batch = self.replay.sample(self.config.batch_size, self.beta())
        delta = self.train_step(batch)
        self.replay.update_priorities(batch.indices, tf.abs(delta))

    @tf.function(input_signature=[tf.TensorSpec([], tf.int32)], autograph=False)
    def learn(self, steps: tf.Tensor) -> dict[str, tf.Tensor]:
        """`steps` learning steps in one graph call; returns the running means of the losses.

        Graphs here are written with explicit `tf.while_loop`/`tf.cond` (`autograph=False`):
        AutoGraph would otherwise rewrite every function the loop calls, Keras's included,
        which cost several seconds of tracing per run."""

        def step(i: tf.Tensor) -> tf.Tensor:
            self.learn_step()
            return i + 1

        tf.while_loop(lambda i: i < steps, step, [tf.constant(0)])
        return self.losses_so_far()

    def pretrain(self, steps: int, steps_per_call: int = 100) -> dict[str, float]:
        """k gradient steps on D_demo alone (Algorithm 1, step 2), then capture θ_prior."""
        # Batches are drawn with replacement: one short demonstration (fewer transitions than a
        # batch, as a noisy expert's can be) is still a dataset to learn from.
        if int(self.replay.agent_size.numpy()) != 0:
            raise ConfigError("pre-training samples D_demo alone, but the replay already holds agent data")
        result: dict[str, tf.Tensor] = {}
        for done in range(0, steps, steps_per_call):
            result = self.learn(min(steps_per_call, steps - done))
        self.capture_prior()
        return {name: float(value) for name, value in result.items()}

    def reset_metrics(self) -> None:
        self.loss_means.reset_state()

    def greedy_actions(self, obs: tf.Tensor) -> tf.Tensor:
        """argmax_a Q(s, a; θ), (B,)."""
        return tf.argmax(self.q_network(obs), axis=1, output_type=tf.int32)

    def checkpoint(self) -> tf.train.Checkpoint:
        """Everything needed to resume learning bit for bit: θ, θ', θ_prior, Adam, replay, π_bc.

        Variables are listed one by one: TensorFlow's object tracking does not see inside
        Keras 3's layer lists, nor the dropout layers' random-seed state.
        """
        bc_variables = self.bc_model.variables if self.bc_model is not None else []
        return tf.train.Checkpoint(
            q_network=self.q_network,
            target_network=self.target_network,
            optimizer=self.optimizer,
            train_steps=self.train_steps,
            replay=self.replay,
            **{f"prior_{i}": prior for i, prior in enumerate(self.prior_weights)},
            **{f"bc_{i}": variable.value for i, variable in enumerate(bc_variables)},
        )


def make_agent(
    config: Config,
    demos: DemoDataset | None,
    bc_model: BCModel | None = None,
    obs_scale: tuple[np.ndarray, np.ndarray] | None = None,
    spaces: tuple[int | NetworkInput, int] | None = None,
) -> DQfDAgent:
    """A fresh agent whose D_demo holds `demos`, networks scaled by `obs_scale` (default: the
    demos' states). Without demos (plain DQN) give `spaces` = (obs_dim or `NetworkInput`,
    n_actions) and, for vectors, `obs_scale`. Frames need no `obs_scale`: they are scaled to [0, 1]."""
    if demos is not None:
        spaces = spaces or (demos.meta.obs_dim, demos.meta.n_actions)
    image = spaces is not None and as_input(spaces[0]).image
    if demos is not None and not image:
        obs_scale = obs_scale or demos.obs_scale()
    if spaces is None or (obs_scale is None and not image):
        raise ConfigError("an agent without demonstrations needs obs_scale and spaces")
    replay = PrioritizedReplay(*spaces, ReplaySettings.from_config(config))
    agent = DQfDAgent(config, *spaces, replay, bc_model, obs_scale=obs_scale)
    if demos is not None:
        agent.set_demos(demos.obs, demos.actions, demos.rewards, demos.next_obs, demos.terminated, demos.truncated)
    return agent
