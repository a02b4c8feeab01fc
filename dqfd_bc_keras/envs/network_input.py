"""What the networks take, decided without TensorFlow: vectors or frames, and the torso that
reads them (`Config.torso`; the layers themselves are in networks.py)."""

from __future__ import annotations

from dataclasses import dataclass

from dqfd_bc_keras.choices import TORSOS
from dqfd_bc_keras.envs.observations import Frames
from dqfd_bc_keras.errors import ConfigError

CONV_TORSOS: dict[str, tuple[tuple[int, int, int], ...]] = {
    "minatar": ((16, 3, 1),),
    "nature": ((32, 8, 4), (64, 4, 2), (64, 3, 1)),
}
"""(filters, kernel, stride) of each ReLU convolution, 'valid' padding."""
NATURE_MIN_SIZE = 36
"""The smallest side the Nature torso takes (8/4, then 4/2, then 3/1, valid padding)."""


@dataclass(frozen=True)
class NetworkInput:
    """What the networks take: flat float32 vectors of `dim` features, or uint8 `frames`, and the
    torso (resolved, never "auto") that reads them."""

    dim: int
    """Features of a vector; values of a frame observation."""
    frames: Frames | None = None
    torso: str = "mlp"

    @property
    def image(self) -> bool:
        return self.frames is not None

    @property
    def shape(self) -> tuple[int, ...]:
        """One observation's shape: (d,) or the frames'."""
        return (self.dim,) if self.frames is None else self.frames.shape

    @property
    def dtype(self) -> str:
        return "float32" if self.frames is None else "uint8"


def as_input(x: int | NetworkInput) -> NetworkInput:
    """A vector of `x` features, or `x` itself."""
    return x if isinstance(x, NetworkInput) else NetworkInput(int(x))


def resolve_torso(torso: str, frames: Frames | None) -> str:
    """The torso `torso` names for these observations (`auto`: by their shape); a `ConfigError`
    for a convolutional torso on vectors or on frames too small for it."""
    if torso not in TORSOS:
        raise ConfigError(f"torso={torso!r} is not one of {TORSOS}")
    if frames is None:
        if torso in CONV_TORSOS:
            raise ConfigError(
                f"torso={torso!r} needs frames (a 2-D or 3-D uint8 or bool Box), "
                "but the observations are vectors: use torso=mlp"
            )
        return "mlp"
    side = min(frames.shape[:2])
    if torso == "auto":
        return "nature" if side >= NATURE_MIN_SIZE else "minatar"
    if torso == "nature" and side < NATURE_MIN_SIZE:
        raise ConfigError(
            f"torso=nature needs frames of at least {NATURE_MIN_SIZE}×{NATURE_MIN_SIZE}, "
            f"got {frames.shape}: use torso=minatar"
        )
    return torso
