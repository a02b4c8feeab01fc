"""Builders for the Q-network and the BC classifier's body: a torso, then ReLU dense layers.

    mlp      vectors (standardised by the demonstrations' statistics), or frames flattened
    minatar  MinAtar's network (Young & Tian 2019): one 3×3 convolution of 16 filters, stride 1
    nature   the Nature-DQN network (Mnih et al. 2015): 8×8/4 of 32, 4×4/2 of 64, 3×3/1 of 64

Frames enter as uint8 and are scaled to [0, 1] inside the network (`Frames.scale`), so a replay
of frames never holds a float copy. `torso="auto"` (`resolve_torso`) picks mlp for vectors,
minatar for grids smaller than 36×36 (Nature's strides need at least that) and nature for larger
frames. Every layer is a built-in Keras layer: a saved `q_network.keras` loads anywhere with
`keras.saving.load_model`, in safe mode.
"""

from __future__ import annotations

from collections.abc import Sequence

import keras
import numpy as np
import numpy.typing as npt

from dqfd_bc_keras.envs.network_input import CONV_TORSOS, NATURE_MIN_SIZE, NetworkInput, as_input, resolve_torso

__all__ = [
    "CONV_TORSOS",
    "NATURE_MIN_SIZE",
    "NetworkInput",
    "as_input",
    "build_q_network",
    "dense_stack",
    "normalization",
    "resolve_torso",
    "torso_layers",
]


def torso_layers(
    net_input: NetworkInput, obs_scale: tuple[npt.ArrayLike, npt.ArrayLike] | None = None
) -> list[keras.layers.Layer]:
    """The layers from an observation to the dense layers' input: standardisation (vectors), or
    the [0, 1] scaling, a channel axis for 2-D frames, the convolutions and a flatten (frames)."""
    if net_input.frames is None:
        return [] if obs_scale is None else [normalization(*obs_scale)]
    layers: list[keras.layers.Layer] = [keras.layers.Rescaling(net_input.frames.scale, name="to_unit")]
    if len(net_input.frames.shape) == 2:
        layers.append(keras.layers.Reshape((*net_input.frames.shape, 1), name="channel"))
    for i, (filters, kernel, stride) in enumerate(CONV_TORSOS.get(net_input.torso, ())):
        layers.append(keras.layers.Conv2D(filters, kernel, strides=stride, activation="relu", name=f"conv_{i}"))
    layers.append(keras.layers.Flatten(name="flatten"))
    return layers


def build_q_network(
    net_input: int | NetworkInput,
    n_actions: int,
    hidden: Sequence[int] = (64, 64),
    obs_scale: tuple[np.ndarray, np.ndarray] | None = None,
    name: str = "q_network",
) -> keras.Model:
    """Q(s, ·; θ): a state (vector (d,) or frames) → one value per action (A,): the torso, ReLU
    hidden layers, a linear output.

    `obs_scale` = (mean, std) of the demonstrations' states standardises a vector input with a
    fixed `Normalization` layer: CartPole's angle lives on a ±0.2 scale and its velocities on
    ±2, and the network learns the expert's rule far faster from standardised inputs.
    """
    net_input = as_input(net_input)
    obs = keras.Input(shape=net_input.shape, dtype=net_input.dtype, name="obs")
    q = obs
    for layer in torso_layers(net_input, obs_scale) + dense_stack(hidden, n_actions, out_name="q_values"):
        q = layer(q)
    return keras.Model(obs, q, name=name)


def normalization(mean: npt.ArrayLike, std: npt.ArrayLike) -> keras.layers.Normalization:
    """A fixed (non-trainable) standardisation (s − mean)/std; std is floored at 1e-3, and a
    feature the demonstrations never vary (std 0) is centred, not scaled (std 1), as scikit-learn's
    `StandardScaler` does. Why: floored at 1e-3, such a feature multiplied any change off the
    demonstrations by 1,000 (MiniGrid: 135 of 151 features are constant along a rule's path, and a
    state off it reached the network as inputs of ±10,000, which drove the greedy policy away from
    the rule; docs/TASKS.md)."""
    std = np.asarray(std, np.float32)
    std = np.where(std > 0, np.maximum(std, 1e-3), 1.0)
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
