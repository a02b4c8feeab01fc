"""J_E of each built-in method (methods.py), as the agent calls it: term(agent, q, batch) → scalar,
and the per-row imitation weights runs log (`Method.weight`).

Each is a `methods.Term`: it reads its settings from `agent.config` and weights its per-sample losses
(losses.py) by the batch's importance weights. A method of your own gives a function of the same
shape; each built-in's reference formula, which the tests check it against, is in reference.py.
"""

from __future__ import annotations

from collections.abc import Sequence
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


def likelihood_weight(agent: TermAgent, q: tf.Tensor, batch: TermBatch) -> tf.Tensor:
    """1/(2σ²(s)): the weight of the Bayesian likelihood on each row (bayes, bayes_local)."""
    return 0.5 / batch.sigma_sq


# --- Past the teacher (ALGORITHM.md §8): J_E that lets the agent leave π_bc where it knows better.


def qfilter_weight(agent: TermAgent, q: tf.Tensor, batch: TermBatch) -> tf.Tensor:
    """The Q-filter (Nair et al. 2018), with a margin: 1 where the agent does not prefer another
    action to the teacher's a_bc = argmax π̄_bc(·|s) by more than l, Q(s, a_bc) + l ≥ max_a Q(s, a),
    else 0; Q is read, not trained, through it. With l = 0 it is Nair's filter read for a DQN, whose
    actor is argmax Q: it keeps only the rows where a_bc is greedy already, so it can sharpen
    agreement but never create it (pre-training from random Q-values reached 0.58 agreement with
    CartPole's expert, against ≥ 0.90 for the other losses); l = `margin` (0.8) lets imitation act
    until the agent's own values say otherwise by DQfD's margin."""
    q = tf.stop_gradient(q)
    a_bc = tf.argmax(batch.pi_bc, axis=1, output_type=tf.int32)
    return tf.cast(losses.action_value(q, a_bc) + agent.config.margin >= tf.reduce_max(q, axis=1), tf.float32)


def qfilter(agent: TermAgent, q: tf.Tensor, batch: TermBatch) -> tf.Tensor:
    """ce on the rows the Q-filter keeps: imitation only where the agent's own Q-values do not
    prefer another action to the teacher's by more than the margin, so TD alone decides where they do."""
    per_sample = qfilter_weight(agent, q, batch) * losses.cross_entropy_loss(q, batch.pi_bc, agent.config.temperature)
    return losses.weighted_mean(per_sample, batch.weights)


def decay_weight(agent: TermAgent, q: tf.Tensor, batch: TermBatch) -> tf.Tensor:
    """w_E on every row (`next_expert_scale`)."""
    return tf.fill(tf.shape(q)[:1], tf.cast(agent.expert_scale, tf.float32))


def ce_decay(agent: TermAgent, q: tf.Tensor, batch: TermBatch) -> tf.Tensor:
    """w_E·H(π_bc, softmax(Q/T)): ce, weighted by how far the agent's own returns are from the teacher's."""
    return tf.cast(agent.expert_scale, tf.float32) * ce(agent, q, batch)


def next_expert_scale(scale: float, returns: Sequence[float], teacher: float, window: int, decay: float) -> float:
    """w_E after an episode: ×ρ when the mean of the last W returns is at least the teacher's mean
    return, ÷ρ (at most 1) when it is below; unchanged before W episodes. Multiplicative, so the
    rule needs no scale of the task's returns: at ρ = 0.9, ten episodes at the teacher's level
    leave 0.35 of the imitation, twenty-two leave under 0.1, and falling back restores it."""
    if len(returns) < window:
        return scale
    if sum(returns[-window:]) / window >= teacher:
        return scale * decay
    return min(1.0, scale / decay)
