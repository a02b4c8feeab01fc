"""J_E of each built-in method (methods.py), as the agent calls it: term(agent, q, batch) → scalar.

Each is a `methods.Term`: it reads its settings from `agent.config` and weights its per-sample losses
(losses.py) by the batch's importance weights. A method of your own gives a function of the same
shape; each built-in's reference formula, which the tests check it against, is in reference.py.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import tensorflow as tf

from dqfd_bc_keras.core import losses

if TYPE_CHECKING:
    from dqfd_bc_keras.core.methods import TermAgent, TermBatch


def margin(agent: TermAgent, q: tf.Tensor, batch: TermBatch) -> tf.Tensor:
    """DQfD: the large margin on the demonstrated action a_E, on demonstration rows only."""
    per_sample = losses.margin_loss(q, batch.actions, agent.config.margin)
    return losses.weighted_mean(per_sample, batch.weights * batch.is_demo)


def bc_margin(agent: TermAgent, q: tf.Tensor, batch: TermBatch) -> tf.Tensor:
    """DQfD-BC: the large margin around a_E = argmax π_bc(·|s), on every row."""
    a_e = tf.argmax(batch.pi_bc, axis=1, output_type=tf.int32)
    return losses.weighted_mean(losses.margin_loss(q, a_e, agent.config.margin), batch.weights)


def ce(agent: TermAgent, q: tf.Tensor, batch: TermBatch) -> tf.Tensor:
    """DQfD-BC: H(π_bc, softmax(Q/T)) on every row."""
    return losses.weighted_mean(losses.cross_entropy_loss(q, batch.pi_bc, agent.config.temperature), batch.weights)


def bayes(agent: TermAgent, q: tf.Tensor, batch: TermBatch) -> tf.Tensor:
    """The paper's loss: the Gaussian likelihood around π̄_bc with variance σ²(s), plus the prior
    ‖θ − θ_prior‖²/(2 s_p² N) (unless ablated with `bayes_prior=False`)."""
    c = agent.config
    likelihood = losses.weighted_mean(
        losses.bayes_likelihood_loss(q, batch.pi_bc, batch.sigma_sq, c.temperature), batch.weights
    )
    if not c.bayes_prior:
        return likelihood
    return likelihood + losses.bayes_prior_loss(agent.theta, agent.prior_weights, c.prior_scale, agent.demo_size)
