"""Adam with TensorFlow's fused kernel: the same state and arithmetic as `keras.optimizers.Adam`.

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

    def update_step(self, gradient, variable, learning_rate):
        if self.amsgrad:
            return super().update_step(gradient, variable, learning_rate)
        dtype = variable.dtype
        step = tf.cast(self.iterations + 1, dtype)
        beta_1, beta_2 = tf.cast(self.beta_1, dtype), tf.cast(self.beta_2, dtype)
        index = self._get_variable_index(variable)
        tf.raw_ops.ResourceApplyAdam(
            var=variable.handle, m=self._momentums[index].handle,
            v=self._velocities[index].handle, beta1_power=tf.pow(beta_1, step),
            beta2_power=tf.pow(beta_2, step), lr=tf.cast(learning_rate, dtype), beta1=beta_1,
            beta2=beta_2, epsilon=tf.cast(self.epsilon, dtype), grad=tf.cast(gradient, dtype),
        )
