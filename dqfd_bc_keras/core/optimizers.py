"""Adam with TensorFlow's fused kernel: the same state and update as `keras.optimizers.Adam`, to
float32 rounding (the kernel forms 1 − β2 in float32, 1.3e-5 of itself from Keras's; see
tests/test_optimizers.py). Its variables must be Keras variables, as a model's are.

An update of our small networks costs in TensorFlow ops, not in arithmetic (each op a few µs,
see README "Performance"). Keras's Adam spends ~15 ops per variable; `ResourceApplyAdam` does
the same step in one:

    m ← m + (g − m)(1 − β1),  v ← v + (g² − v)(1 − β2),
    θ ← θ − lr·√(1 − β2^t)/(1 − β1^t) · m/(√v + ε)
"""

from __future__ import annotations

import keras
import tensorflow as tf


@keras.saving.register_keras_serializable(package="dqfd_bc_keras")
class FusedAdam(keras.optimizers.Adam):
    """`keras.optimizers.Adam` (without amsgrad) whose per-variable step is one fused op."""

    def _backend_update_step(self, grads, trainable_variables, learning_rate):
        if self.amsgrad:
            return super()._backend_update_step(grads, trainable_variables, learning_rate)
        # The scalars all variables share, computed once per step rather than once per variable.
        dtype = trainable_variables[0].dtype
        step = tf.cast(self.iterations + 1, dtype)
        beta_1, beta_2 = tf.constant(self.beta_1, dtype), tf.constant(self.beta_2, dtype)
        beta1_power, beta2_power = tf.pow(beta_1, step), tf.pow(beta_2, step)
        lr, epsilon = tf.cast(learning_rate, dtype), tf.constant(self.epsilon, dtype)
        for gradient, variable in zip(grads, trainable_variables, strict=True):
            index = self._get_variable_index(variable)
            tf.raw_ops.ResourceApplyAdam(
                var=variable.value.handle,
                m=self._momentums[index].value.handle,
                v=self._velocities[index].value.handle,
                beta1_power=beta1_power,
                beta2_power=beta2_power,
                lr=lr,
                beta1=beta_1,
                beta2=beta_2,
                epsilon=epsilon,
                grad=tf.cast(gradient, dtype),
            )
