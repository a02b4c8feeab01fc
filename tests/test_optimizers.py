"""FusedAdam (one `ResourceApplyAdam` op per variable) against `keras.optimizers.Adam`: the same
first step computed by hand, the same weights after many steps, on loose variables and a model."""

import keras
import numpy as np
import pytest
import tensorflow as tf

import dqfd_bc_keras  # noqa: F401  (first: TensorFlow's threads and log level)
from dqfd_bc_keras.core.optimizers import FusedAdam

SHAPES = [(4, 64), (64,), (64, 2), ()]


def variables(seed: int) -> list[keras.Variable]:
    """Keras variables, as a model's are (FusedAdam reads their TensorFlow handle)."""
    rng = np.random.default_rng(seed)
    return [keras.Variable(rng.normal(size=shape).astype(np.float32)) for shape in SHAPES]


def test_the_first_step_is_adams_with_bias_correction():
    """t = 1: m = (1 − β1)·g, v = (1 − β2)·g², so θ moves by lr·√(1 − β2)/(1 − β1) · m/(√v + ε)
    = lr·g/(|g| + ε/√(1 − β2)): lr·sign(g) where |g| ≫ ε, 0 where g = 0. The kernel forms
    1 − β2 in float32 (0.999 → 0.00099998713), so v is that, not 0.001·g²."""
    lr, eps = 0.01, 1e-7
    theta = keras.Variable(np.array([1.0, -2.0, 3.0, 0.5], np.float32))
    g = np.array([0.5, -3.0, 0.0, 1e-6], np.float32)
    optimizer = FusedAdam(lr, epsilon=eps)
    optimizer.apply([tf.constant(g)], [theta])
    one_minus_b1, one_minus_b2 = 1 - np.float32(0.9), 1 - np.float32(0.999)
    np.testing.assert_allclose(optimizer._momentums[0].numpy(), one_minus_b1 * g, rtol=1e-6)
    np.testing.assert_allclose(optimizer._velocities[0].numpy(), one_minus_b2 * g**2, rtol=1e-6)
    by_hand = np.array([1.0, -2.0, 3.0, 0.5]) - lr * g / (np.abs(g) + eps / np.sqrt(0.001))
    np.testing.assert_allclose(theta.numpy(), by_hand, rtol=1e-6)
    np.testing.assert_allclose(theta.numpy()[:3], [1.0 - lr, -2.0 + lr, 3.0], rtol=1e-6)


@pytest.mark.slow
@pytest.mark.parametrize("lr", [1e-3, 0.05])
def test_500_steps_of_random_gradients_match_keras_adam(lr):
    fused_theta, keras_theta = variables(0), variables(0)
    fused, stock = FusedAdam(lr), keras.optimizers.Adam(lr)
    rng = np.random.default_rng(1)
    for _ in range(500):
        # Gradients of all sizes, some exactly 0, as a ReLU network's are.
        grads = [
            tf.constant(
                (rng.normal(size=s) * 10.0 ** rng.uniform(-4, 1, size=s) * (rng.random(size=s) > 0.1)).astype(
                    np.float32
                )
            )
            for s in SHAPES
        ]
        fused.apply(grads, fused_theta)
        stock.apply(grads, keras_theta)
    assert int(fused.iterations.numpy()) == int(stock.iterations.numpy()) == 500
    # Each update agrees to ~1e-5 of its size (≤ a few lr) for the float32 1 − β2 below.
    for a, b in zip(fused_theta, keras_theta, strict=True):
        np.testing.assert_allclose(a.numpy(), b.numpy(), rtol=1e-5, atol=500 * lr * 1e-5)
    # Keras forms 1 − β2 in float64 (0.001), the kernel in float32: v differs by 1.3e-5 of itself.
    for a, b in zip(fused.variables, stock.variables, strict=True):
        np.testing.assert_allclose(a.numpy(), b.numpy(), rtol=3e-5, atol=1e-12)


def small_model(optimizer: keras.optimizers.Optimizer) -> keras.Model:
    keras.utils.set_random_seed(0)
    model = keras.Sequential([keras.Input((4,)), keras.layers.Dense(32, activation="tanh"), keras.layers.Dense(2)])
    model.compile(optimizer=optimizer, loss="mse")
    return model


@pytest.mark.slow
def test_training_a_small_model_matches_keras_adam():
    """200 full-batch steps of a regression: the same losses and weights. tanh, not ReLU: where a
    ReLU's input lies within rounding of 0, two roundings send its gradient different ways."""
    rng = np.random.default_rng(2)
    x = rng.normal(size=(256, 4)).astype(np.float32)
    y = np.stack([np.sin(x[:, 0]) + x[:, 1] * x[:, 2], x[:, 3] ** 2], 1).astype(np.float32)
    fused, stock = small_model(FusedAdam(1e-2)), small_model(keras.optimizers.Adam(1e-2))
    losses = {}
    for name, model in (("fused", fused), ("keras", stock)):  # train_on_batch: fit's compiled step, no epoch overhead
        losses[name] = [float(model.train_on_batch(x, y)) for _ in range(200)]
    assert losses["fused"][-1] < 0.5 * losses["fused"][0]  # it learned
    np.testing.assert_allclose(losses["fused"], losses["keras"], rtol=1e-4)
    for a, b in zip(fused.weights, stock.weights, strict=True):
        np.testing.assert_allclose(a.numpy(), b.numpy(), rtol=1e-4, atol=1e-5)


def test_amsgrad_falls_back_to_keras_adam():
    fused_theta, keras_theta = variables(3), variables(3)
    fused, stock = FusedAdam(0.01, amsgrad=True), keras.optimizers.Adam(0.01, amsgrad=True)
    grads = [tf.ones(s) for s in SHAPES]
    for _ in range(3):
        fused.apply(grads, fused_theta)
        stock.apply(grads, keras_theta)
    for a, b in zip(fused_theta, keras_theta, strict=True):
        np.testing.assert_array_equal(a.numpy(), b.numpy())
