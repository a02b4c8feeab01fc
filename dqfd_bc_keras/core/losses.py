"""The terms of the total loss (paper Eq. 4, ALGORITHM.md §2–§3) as pure functions of tensors.

    J(Q) = J_DQ(Q) + λ1·J_n(Q) + λ2·J_E(Q) + λ3·J_L2(Q)

Shapes: B is the batch size, A the number of actions. Per-sample terms return (B,) tensors;
the agent multiplies them by the importance weights and averages (`weighted_mean`). Targets
are wrapped in `stop_gradient`: the gradient only flows through Q(s, ·; θ).
"""

from __future__ import annotations

from collections.abc import Sequence

import tensorflow as tf


def bootstrap_value(q_next_target: tf.Tensor, q_next_online: tf.Tensor | None, target: str = "dqn") -> tf.Tensor:
    """The value of s' the target bootstraps from, (B,).

    dqn:    max_a' Q(s', a'; θ')                        (the paper's target, default)
    double: Q(s', argmax_a' Q(s', a'; θ); θ')           (DQfD's double-DQN target)

    q_next_target: (B, A) Q(s', ·; θ');  q_next_online: (B, A) Q(s', ·; θ), read only for `double`.
    """
    if target == "dqn":
        return tf.reduce_max(q_next_target, axis=1)
    if target == "double":
        a_star = tf.argmax(q_next_online, axis=1, output_type=tf.int32)
        return tf.gather(q_next_target, a_star, axis=1, batch_dims=1)
    raise ValueError(f"unknown target {target!r}; expected 'dqn' or 'double'")


def td_target(returns: tf.Tensor, discount: tf.Tensor, next_value: tf.Tensor) -> tf.Tensor:
    """y = R + discount · V(s_next), without gradient, (B,).

    For the 1-step loss R = r_t and discount = γ·(1 − terminated_t); for the n-step loss
    R = Σ_{k<m} γ^k r_{t+k} and discount = γ^m·(1 − terminated_{t+m−1}), m ≤ n stopping at the
    episode's end. A truncated transition keeps its discount: it bootstraps. All (B,).
    """
    return tf.stop_gradient(returns + discount * next_value)


def td_error(q: tf.Tensor, actions: tf.Tensor, y: tf.Tensor) -> tf.Tensor:
    """δ = y − Q(s, a), (B,). q: (B, A); actions: (B,) int; y: (B,)."""
    q_sa = action_value(q, actions)
    _assert_same_shape(q_sa, y, "the target y must have shape (B,)")
    return y - q_sa


def action_value(q: tf.Tensor, actions: tf.Tensor) -> tf.Tensor:
    """Q(s, a) for each row's action, (B,), as Σ_a' Q(s, a')·1[a' = a]: the same numbers as a
    gather, and a gradient of two ops where a batched gather's takes ~50."""
    return tf.reduce_sum(q * tf.one_hot(tf.cast(actions, tf.int32), tf.shape(q)[1], dtype=q.dtype), axis=1)


def td_loss(delta: tf.Tensor, kind: str = "squared") -> tf.Tensor:
    """Per-sample TD loss, (B,): δ² (the paper's squared error) or Huber(δ) (option)."""
    if kind == "squared":
        return tf.square(delta)
    if kind == "huber":
        abs_delta = tf.abs(delta)
        return tf.where(abs_delta <= 1.0, 0.5 * tf.square(delta), abs_delta - 0.5)
    raise ValueError(f"unknown TD loss {kind!r}; expected 'squared' or 'huber'")


def margin_loss(q: tf.Tensor, expert_actions: tf.Tensor, margin: float = 0.8) -> tf.Tensor:
    """Large-margin loss (DQfD Eq. 5; DQfD-BC Eq. 8 with a_E = argmax π_bc), (B,).

        J_E = max_a [Q(s, a) + l(a_E, a)] − Q(s, a_E),   l(a_E, a) = margin if a ≠ a_E else 0

    q: (B, A); expert_actions: (B,) int, the demonstrated (or BC-predicted) action a_E.
    """
    a_e = tf.cast(expert_actions, tf.int32)
    l = margin * (1.0 - tf.one_hot(a_e, tf.shape(q)[1], dtype=q.dtype))  # noqa: E741 (the paper's l(a_E, a))
    return tf.reduce_max(q + l, axis=1) - action_value(q, a_e)


def q_policy(q: tf.Tensor, temperature: float = 1.0) -> tf.Tensor:
    """p_Q(a|s) = softmax(Q(s, ·)/T), (B, A)."""
    return tf.nn.softmax(q / temperature, axis=1)


def cross_entropy_loss(q: tf.Tensor, pi_bc: tf.Tensor, temperature: float = 1.0) -> tf.Tensor:
    """DQfD-BC's expert loss (Eqs. 6–7), (B,):  H(π_bc, p_Q) = −Σ_a π_bc(a|s) log p_Q(a|s).

    q: (B, A); pi_bc: (B, A) the BC model's action probabilities, a constant target.
    """
    log_p_q = tf.nn.log_softmax(q / temperature, axis=1)
    return -tf.reduce_sum(tf.stop_gradient(pi_bc) * log_p_q, axis=1)


def bayes_likelihood_loss(q: tf.Tensor, pi_bar: tf.Tensor, sigma_sq: tf.Tensor, temperature: float = 1.0) -> tf.Tensor:
    """The Gaussian log-likelihood part of the Bayesian expert loss (paper Eqs. 17–20), (B,):

        Σ_a (p_Q(a|s; θ) − π̄_bc(a|s))² / (2·σ²(s))

    A confident BC model (σ² → σ0², small) imitates at full weight; an uncertain one
    (σ² large) lets the TD losses and the prior lead. q, pi_bar: (B, A); sigma_sq: (B,).
    """
    squared = tf.reduce_sum(tf.square(q_policy(q, temperature) - tf.stop_gradient(pi_bar)), axis=1)
    return squared / (2.0 * tf.stop_gradient(sigma_sq))


def bayes_prior_loss(
    weights: Sequence[tf.Variable | tf.Tensor],
    prior_weights: Sequence[tf.Variable | tf.Tensor],
    prior_scale: float,
    n_data: int | tf.Tensor | tf.Variable,
) -> tf.Tensor:
    """The Gaussian prior part, a scalar:  ‖θ − θ_prior‖² / (2·s_p²·N).

    weights: the Q-network's trainable variables θ; prior_weights: θ_prior, same shapes;
    prior_scale: s_p; n_data: N, the number of demonstration transitions (MAP scaling).
    """
    # tf.nn.l2_loss(x) = ‖x‖²/2 in one op (and one for its gradient); θ_prior is not trained.
    half_squared = tf.add_n(
        [tf.nn.l2_loss(w - tf.stop_gradient(p)) for w, p in zip(weights, prior_weights, strict=True)]
    )
    return half_squared / (prior_scale**2 * tf.cast(n_data, half_squared.dtype))


def l2_loss(kernels: list[tf.Variable]) -> tf.Tensor:
    """J_L2 = Σ ‖W‖² over the Q-network's kernel matrices (biases excluded), a scalar."""
    return 2.0 * tf.add_n([tf.nn.l2_loss(k) for k in kernels])  # l2_loss(k) = ‖k‖²/2


def weighted_mean(per_sample: tf.Tensor, weights: tf.Tensor) -> tf.Tensor:
    """mean_i w_i·ℓ_i over the batch: importance weights (and masks) applied, (B,) → scalar."""
    _assert_same_shape(per_sample, weights, "per-sample losses and weights must both be (B,)")
    return tf.reduce_mean(weights * per_sample)


def _assert_same_shape(a: tf.Tensor, b: tf.Tensor, message: str) -> None:
    """Refuse silent broadcasting ((B,) against (B, 1)); checked when the graph is traced."""
    if not a.shape.is_compatible_with(b.shape):
        raise ValueError(f"{message}, got {a.shape} and {b.shape}")
