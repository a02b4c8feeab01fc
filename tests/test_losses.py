"""Tests for the pure loss functions in dqfd_bc_keras.core.losses (ALGORITHM.md §2–§3).

Every expected value is worked out by hand (the arithmetic is in the comments / literals);
none is computed by calling the function under test.
"""

import ast
import math
from pathlib import Path

import numpy as np
import pytest
import tensorflow as tf

from dqfd_bc_keras.choices import TARGETS, TD_LOSSES
from dqfd_bc_keras.core import losses
from dqfd_bc_keras.core.losses import (
    bayes_likelihood_loss,
    bayes_prior_loss,
    bootstrap_value,
    cross_entropy_loss,
    l2_loss,
    margin_loss,
    q_policy,
    td_error,
    td_loss,
    td_target,
    weighted_mean,
)

RTOL, ATOL = 1e-6, 1e-6
LN2, LN3 = math.log(2.0), math.log(3.0)


def f32(x) -> tf.Tensor:
    return tf.constant(x, dtype=tf.float32)


def close(actual, expected) -> None:
    np.testing.assert_allclose(np.asarray(actual), np.asarray(expected, dtype=np.float64), rtol=RTOL, atol=ATOL)


# Q-values whose softmax is easy by hand: exp([0, ln2, ln3]) = [1, 2, 3] -> p = [1/6, 2/6, 3/6];
# and uniform Q-values [1, 1, 1] -> p = [1/3, 1/3, 1/3].
Q_EASY = [[0.0, LN2, LN3], [1.0, 1.0, 1.0]]


# ---------------------------------------------------------------- 1. bootstrap_value

# s'_0: target Q = [1, 3, 2], online Q = [4, 0, 1];  s'_1: target Q = [0.5, -1, 0.2], online Q = [0, 2, 1]
Q_NEXT_TARGET = [[1.0, 3.0, 2.0], [0.5, -1.0, 0.2]]
Q_NEXT_ONLINE = [[4.0, 0.0, 1.0], [0.0, 2.0, 1.0]]


@pytest.mark.parametrize(
    "target, expected",
    [
        ("dqn", [3.0, 0.5]),  # max of target rows: max(1,3,2)=3, max(0.5,-1,0.2)=0.5
        ("double", [1.0, -1.0]),  # online argmax = [0, 1] -> target[0,0]=1, target[1,1]=-1
    ],
)
def test_bootstrap_value_dqn_takes_max_and_double_takes_target_at_online_argmax(target, expected) -> None:
    close(bootstrap_value(f32(Q_NEXT_TARGET), f32(Q_NEXT_ONLINE), target), expected)


def test_bootstrap_value_unknown_target_raises_naming_it() -> None:
    with pytest.raises(ValueError, match="sarsa"):
        bootstrap_value(f32(Q_NEXT_TARGET), f32(Q_NEXT_ONLINE), "sarsa")


def test_the_modes_config_accepts_are_the_modes_the_losses_take() -> None:
    """choices.py spells them for config and the CLIs; losses.py takes the strings it is given."""
    for target in TARGETS:
        bootstrap_value(f32(Q_NEXT_TARGET), f32(Q_NEXT_ONLINE), target)
    for kind in TD_LOSSES:
        td_loss(f32(DELTA), kind)


def test_the_loss_module_imports_tensorflow_alone() -> None:
    """Pure math: no config, envs or Gymnasium come in with it (the standard library's abstract
    collections name the types of its arguments)."""
    tree = ast.parse(Path(losses.__file__).read_text())
    imported = {alias.name for node in ast.walk(tree) if isinstance(node, ast.Import) for alias in node.names}
    imported |= {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)}
    assert imported == {"__future__", "collections.abc", "tensorflow"}


# ---------------------------------------------------------------- 2. td_target / td_error


def test_one_step_target_terminated_does_not_bootstrap_truncated_does() -> None:
    gamma = 0.9
    rewards = [1.0, 1.0, 1.0]
    # sample 0: ordinary; sample 1: terminated; sample 2: truncated (not terminated)
    terminated = [0.0, 1.0, 0.0]
    next_value = [2.0, 5.0, 4.0]
    discount = [gamma * (1.0 - d) for d in terminated]  # [0.9, 0, 0.9]
    y = td_target(f32(rewards), f32(discount), f32(next_value))
    # 1 + 0.9*2 = 2.8;  1 + 0*5 = 1;  1 + 0.9*4 = 4.6
    close(y, [2.8, 1.0, 4.6])


def test_n_step_target_with_window_cut_at_episode_end() -> None:
    # n = 10 but the episode ended after m = 3 steps: rewards r0=1, r1=2, r2=3, gamma = 0.9.
    # R = 1 + 0.9*2 + 0.81*3 = 1 + 1.8 + 2.43 = 5.23;  gamma^m = 0.9^3 = 0.729.
    # sample 0 was truncated (bootstraps): discount 0.729; sample 1 terminated: discount 0.
    returns = [5.23, 5.23]
    discount = [0.729, 0.0]
    next_value = [10.0, 10.0]
    y = td_target(f32(returns), f32(discount), f32(next_value))
    # 5.23 + 0.729*10 = 12.52;  5.23 + 0 = 5.23
    close(y, [12.52, 5.23])


def test_td_target_carries_no_gradient() -> None:
    v = tf.Variable([2.0, 3.0])
    with tf.GradientTape() as tape:
        next_value = 2.0 * v
        y = td_target(f32([1.0, 1.0]), f32([0.9, 0.9]), next_value)
        total = tf.reduce_sum(y)
    assert tape.gradient(total, v) is None


def test_td_error_is_target_minus_q_at_taken_action_with_gradient_minus_one_there() -> None:
    q = f32([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])
    actions = tf.constant([2, 0])
    y = f32([2.5, 3.0])
    with tf.GradientTape() as tape:
        tape.watch(q)
        delta = td_error(q, actions, y)
        total = tf.reduce_sum(delta)
    # 2.5 - q[0,2]=3 -> -0.5;  3 - q[1,0]=4 -> -1
    close(delta, [-0.5, -1.0])
    # d(y - q[i, a_i])/dq = -1 at (i, a_i), 0 elsewhere
    close(tape.gradient(total, q), [[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0]])


def test_td_error_rejects_target_of_shape_b_by_1() -> None:
    q = f32([[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]])
    with pytest.raises((tf.errors.InvalidArgumentError, ValueError)):
        td_error(q, tf.constant([0, 1, 0]), f32([[1.0], [2.0], [3.0]]))


def test_td_error_rejects_target_of_shape_1_by_1_for_a_single_sample() -> None:
    # B = 1: y of shape (1, 1) must be rejected too, not broadcast to a (1, 1) error.
    with pytest.raises((tf.errors.InvalidArgumentError, ValueError)):
        td_error(f32([[1.0, 2.0]]), tf.constant([0]), f32([[1.0]]))


# ---------------------------------------------------------------- 3. td_loss

DELTA = [-2.0, -0.5, 0.0, 0.5, 3.0]


@pytest.mark.parametrize(
    "kind, expected",
    [
        ("squared", [4.0, 0.25, 0.0, 0.25, 9.0]),  # delta^2
        # |d|<=1: 0.5 d^2 -> 0.125, 0, 0.125;  |d|>1: |d|-0.5 -> 2-0.5=1.5, 3-0.5=2.5
        ("huber", [1.5, 0.125, 0.0, 0.125, 2.5]),
    ],
)
def test_td_loss_squared_and_huber(kind, expected) -> None:
    close(td_loss(f32(DELTA), kind), expected)


def test_td_loss_unknown_kind_raises() -> None:
    with pytest.raises(ValueError, match="absolute"):
        td_loss(f32(DELTA), "absolute")


# ---------------------------------------------------------------- 4. margin_loss


def test_margin_loss_zero_when_expert_leads_by_more_than_margin_positive_otherwise() -> None:
    q = f32(
        [
            [2.0, 1.0, 0.5],  # a_E=0 leads by 1.0 > 0.8: q+l = [2, 1.8, 1.3], max 2 - q_aE 2 = 0
            [1.0, 1.5, 0.2],  # a_E=1 leads by 0.5 < 0.8: q+l = [1.8, 1.5, 1.0], max 1.8 - 1.5 = 0.3
            [3.0, 1.0, 0.0],  # a_E=2 trails:              q+l = [3.8, 1.8, 0.0], max 3.8 - 0 = 3.8
        ]
    )
    close(margin_loss(q, tf.constant([0, 1, 2]), margin=0.8), [0.0, 0.3, 3.8])


# ---------------------------------------------------------------- 5. q_policy

S2, S3 = math.sqrt(2.0), math.sqrt(3.0)


@pytest.mark.parametrize(
    "temperature, expected",
    [
        # exp([0, ln2, ln3]) = [1, 2, 3], sum 6
        (1.0, [[1 / 6, 2 / 6, 3 / 6], [1 / 3, 1 / 3, 1 / 3]]),
        # exp([0, ln2, ln3]/2) = [1, sqrt2, sqrt3], sum 1+sqrt2+sqrt3
        (2.0, [[1 / (1 + S2 + S3), S2 / (1 + S2 + S3), S3 / (1 + S2 + S3)], [1 / 3, 1 / 3, 1 / 3]]),
    ],
)
def test_q_policy_is_softmax_of_q_over_temperature(temperature, expected) -> None:
    close(q_policy(f32(Q_EASY), temperature), expected)


# ---------------------------------------------------------------- 6. cross_entropy_loss

PI_BC = [[0.5, 0.25, 0.25], [0.0, 0.0, 1.0]]
# sample 0: p_Q = [1/6, 1/3, 1/2] -> -(0.5 ln(1/6) + 0.25 ln(1/3) + 0.25 ln(1/2)) = 0.5 ln6 + 0.25 ln3 + 0.25 ln2
# sample 1: p_Q = [1/3]*3, one-hot target -> -ln(1/3) = ln3
CE_EXPECTED = [0.5 * math.log(6.0) + 0.25 * LN3 + 0.25 * LN2, LN3]


def test_cross_entropy_loss_by_hand() -> None:
    close(cross_entropy_loss(f32(Q_EASY), f32(PI_BC)), CE_EXPECTED)


def test_cross_entropy_loss_divides_q_by_temperature() -> None:
    # Q = 2 * Q_EASY with T = 2 gives the same p_Q, hence the same values
    q = [[0.0, 2 * LN2, 2 * LN3], [2.0, 2.0, 2.0]]
    close(cross_entropy_loss(f32(q), f32(PI_BC), temperature=2.0), CE_EXPECTED)


def test_cross_entropy_loss_has_no_gradient_into_pi_bc() -> None:
    pi_bc = tf.Variable(PI_BC)
    q = tf.Variable(Q_EASY)
    with tf.GradientTape() as tape:
        total = tf.reduce_sum(cross_entropy_loss(q, pi_bc))
    grad_q, grad_pi = tape.gradient(total, [q, pi_bc])
    assert grad_pi is None
    # dH/dq = p_Q - pi_bc: [1/6-1/2, 1/3-1/4, 1/2-1/4], [1/3, 1/3, 1/3-1]
    close(grad_q, [[-1 / 3, 1 / 12, 1 / 4], [1 / 3, 1 / 3, -2 / 3]])


# ---------------------------------------------------------------- 7. bayes_likelihood_loss

PI_BAR = [[0.5, 0.25, 0.25], [1.0, 0.0, 0.0]]
# sample 0: p_Q - pi_bar = [1/6-1/2, 1/3-1/4, 1/2-1/4] = [-1/3, 1/12, 1/4]
#           squares: 1/9 + 1/144 + 1/16 = (16 + 1 + 9)/144 = 26/144 = 13/72
# sample 1: p_Q - pi_bar = [1/3-1, 1/3, 1/3] = [-2/3, 1/3, 1/3]
#           squares: 4/9 + 1/9 + 1/9 = 6/9 = 2/3
SQ = [13 / 72, 2 / 3]


def test_bayes_likelihood_loss_by_hand() -> None:
    sigma_sq = [0.5, 0.25]
    # 13/72 / (2*0.5) = 13/72;  (2/3) / (2*0.25) = 4/3
    close(bayes_likelihood_loss(f32(Q_EASY), f32(PI_BAR), f32(sigma_sq)), [13 / 72, 4 / 3])


def _likelihood_and_grad(sigma_sq: float):
    q = tf.Variable(Q_EASY)
    with tf.GradientTape() as tape:
        value = bayes_likelihood_loss(q, f32(PI_BAR), f32([sigma_sq, sigma_sq]))
        total = tf.reduce_sum(value)
    return value.numpy(), tape.gradient(total, q).numpy()


def test_bayes_likelihood_vanishes_for_large_variance() -> None:
    value, grad = _likelihood_and_grad(1e6)
    # 13/72 / 2e6 ≈ 9.0e-8;  (2/3) / 2e6 ≈ 3.3e-7
    close(value, [13 / 72 / 2e6, 2 / 3 / 2e6])
    assert np.all(np.abs(value) < 1e-6)
    assert np.all(np.abs(grad) < 1e-6)


def test_bayes_likelihood_at_small_floor_is_fifty_times_the_default() -> None:
    value_small, grad_small = _likelihood_and_grad(0.01)
    value_default, grad_default = _likelihood_and_grad(0.5)
    # 1/(2*0.01) = 50 vs 1/(2*0.5) = 1: ratio 0.5/0.01 = 50
    close(value_small, [13 / 72 * 50, 2 / 3 * 50])
    close(value_default, SQ)
    np.testing.assert_allclose(value_small, 50.0 * value_default, rtol=RTOL)
    np.testing.assert_allclose(grad_small, 50.0 * grad_default, rtol=RTOL, atol=1e-5)
    assert np.abs(grad_default).max() > 1e-2  # the comparison is not between zeros


def test_bayes_likelihood_has_no_gradient_into_pi_bar_or_sigma() -> None:
    q = tf.Variable(Q_EASY)
    pi_bar = tf.Variable(PI_BAR)
    sigma_sq = tf.Variable([0.5, 0.25])
    with tf.GradientTape() as tape:
        total = tf.reduce_sum(bayes_likelihood_loss(q, pi_bar, sigma_sq))
    grad_q, grad_pi, grad_sigma = tape.gradient(total, [q, pi_bar, sigma_sq])
    assert grad_q is not None and grad_pi is None and grad_sigma is None


# ---------------------------------------------------------------- 8. bayes_prior_loss

THETA = [[[1.0, 2.0], [3.0, 4.0]], [0.5, -1.0]]
# ||theta||^2 = 1 + 4 + 9 + 16 + 0.25 + 1 = 31.25


@pytest.mark.parametrize(
    "prior_scale, n_data, expected",
    [
        (1.0, 10, 31.25 / 20.0),  # 2 * 1^2 * 10 = 20 -> 1.5625
        (2.0, 5, 31.25 / 40.0),  # 2 * 2^2 * 5 = 40 -> 0.78125
    ],
)
def test_bayes_prior_loss_with_zero_center_is_plain_shrinkage(prior_scale, n_data, expected) -> None:
    weights = [tf.Variable(t) for t in THETA]
    zeros = [tf.Variable(tf.zeros_like(w)) for w in weights]
    close(bayes_prior_loss(weights, zeros, prior_scale, tf.constant(n_data)), expected)


def test_bayes_prior_loss_with_nonzero_center_and_its_gradient() -> None:
    weights = [tf.Variable(t) for t in THETA]
    prior = [tf.Variable([[1.0, 1.0], [1.0, 1.0]]), tf.Variable([0.5, 1.0])]
    # theta - prior = [[0, 1], [2, 3]] and [0, -2]: squares 0+1+4+9+0+4 = 18
    # s_p = 1, N = 10: 18 / (2*1*10) = 0.9
    with tf.GradientTape() as tape:
        value = bayes_prior_loss(weights, prior, 1.0, tf.constant(10))
    close(value, 0.9)
    grads = tape.gradient(value, weights + prior)
    # d/dtheta = (theta - prior) / (s_p^2 N) = diffs / 10
    close(grads[0], [[0.0, 0.1], [0.2, 0.3]])
    close(grads[1], [0.0, -0.2])
    assert grads[2] is None and grads[3] is None  # the prior center is a constant


# ---------------------------------------------------------------- 9. l2_loss


def test_l2_loss_is_sum_of_squares_of_kernels() -> None:
    kernels = [tf.Variable([[1.0, -2.0], [0.0, 3.0]]), tf.Variable([[0.5], [-0.5]])]
    # 1 + 4 + 0 + 9 + 0.25 + 0.25 = 14.5
    close(l2_loss(kernels), 14.5)


# ---------------------------------------------------------------- 10. weighted_mean


def test_weighted_mean_by_hand() -> None:
    # (1*1 + 0.5*2 + 0*3) / 3 = 2/3
    close(weighted_mean(f32([1.0, 2.0, 3.0]), f32([1.0, 0.5, 0.0])), 2 / 3)


@pytest.mark.parametrize(
    "per_sample, weights",
    [
        ([1.0, 2.0, 3.0], [[1.0], [0.5], [0.0]]),  # (B,) vs (B,1)
        ([[1.0], [2.0], [3.0]], [1.0, 0.5, 0.0]),  # (B,1) vs (B,)
    ],
)
def test_weighted_mean_rejects_shape_mismatch_instead_of_broadcasting(per_sample, weights) -> None:
    with pytest.raises((tf.errors.InvalidArgumentError, ValueError)):
        weighted_mean(f32(per_sample), f32(weights))
