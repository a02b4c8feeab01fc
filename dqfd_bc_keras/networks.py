"""MLP builders for the Q-network and the BC classifier's body.

The Q-network is a plain functional Keras model (no custom objects), so a saved
`q_network.keras` loads anywhere with `keras.saving.load_model`.
"""

from __future__ import annotations

from collections.abc import Sequence

import keras
import numpy as np


def build_q_network(
    obs_dim: int,
    n_actions: int,
    hidden: Sequence[int] = (64, 64),
    obs_scale: tuple[np.ndarray, np.ndarray] | None = None,
    name: str = "q_network",
) -> keras.Model:
    """Q(s, ·; θ): state (d,) → one value per action (A,), ReLU hidden layers, linear output.

    `obs_scale` = (mean, std) of the demonstrations' states standardises the input with a
    fixed `Normalization` layer: CartPole's angle lives on a ±0.2 scale and its velocities on
    ±2, and the network learns the expert's rule far faster from standardised inputs.
    """
    obs = keras.Input(shape=(obs_dim,), name="obs")
    q = obs if obs_scale is None else normalization(*obs_scale)(obs)
    for layer in dense_stack(hidden, n_actions, out_name="q_values"):
        q = layer(q)
    return keras.Model(obs, q, name=name)


def normalization(mean: np.ndarray, std: np.ndarray) -> keras.layers.Normalization:
    """A fixed (non-trainable) standardisation (s − mean)/std; std is floored at 1e-3."""
    std = np.maximum(np.asarray(std, np.float32), 1e-3)
    return keras.layers.Normalization(mean=np.asarray(mean, np.float32), variance=std**2, name="standardize")


def dense_stack(
    hidden: Sequence[int], n_out: int, dropout: float = 0.0, out_name: str = "logits"
) -> list[keras.layers.Layer]:
    """ReLU layers, each followed by dropout when `dropout` > 0, then a linear layer of `n_out` units."""
    layers: list[keras.layers.Layer] = []
    for i, units in enumerate(hidden):
        layers.append(keras.layers.Dense(units, activation="relu", name=f"hidden_{i}"))
        if dropout > 0:
            layers.append(keras.layers.Dropout(dropout, name=f"dropout_{i}"))
    layers.append(keras.layers.Dense(n_out, name=out_name))
    return layers
