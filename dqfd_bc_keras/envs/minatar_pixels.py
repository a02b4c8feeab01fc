"""MinAtar as a person sees it: each cell in its channel's colour, scaled up to a visible size.

MinAtar draws a state one way in its GUI (`minatar.Environment.display_state`, `minatar.gui.GUI`)
and in `minatar.gym`'s `rgb_array`: black where no channel is on, else the colour of the last
channel on, from seaborn's `color_palette("cubehelix", n_channels)`, which samples matplotlib's
`cubehelix` colormap (Green 2011; `matplotlib._cm.cubehelix`, a 256-entry lookup table) at n
evenly spaced points inside (0, 1) (`seaborn.palettes.mpl_palette`). Its `rgb_array` gives those
colours as floats in [0, 1] on 10×10 pixels, which a window or a video casting to uint8 shows
black, and it needs seaborn. `palette` computes the same colours from the formula, without
seaborn; `MinAtarPixels` renders uint8 frames of `CELL` pixels a cell for every MinAtar env made
(`envs.make`), so the play window, `demos show` and every video show MinAtar's own picture.
"""

from __future__ import annotations

import functools
import math
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.core import RenderFrame

CELL = 48
"""Pixels per side of a cell: MinAtar's 10×10 grid is 480×480 on screen and in videos."""
LUT = 256
"""Entries of matplotlib's lookup table for a colormap given by functions (rcParams["image.lut"])."""
START, ROTATIONS, HUE, GAMMA = 0.5, -1.5, 1.0, 1.0
"""matplotlib's `cubehelix` colormap's parameters (its defaults: from purple, −1.5 turns, hue 1)."""
DIRECTIONS = np.array([[-0.14861, 1.78277], [-0.29227, -0.90649], [1.97294, 0.0]])
"""Cubehelix's red, green and blue as (cos φ, sin φ) coefficients (Green 2011, eq. 2)."""


@functools.cache
def palette(n_channels: int) -> np.ndarray:
    """MinAtar's colours for a state of `n_channels` channels: (n_channels + 1, 3) uint8, black
    first (no channel on), then channel i's colour at row i + 1."""
    samples = np.linspace(0, 1, n_channels + 2)[1:-1]  # seaborn: evenly spaced, the ends left out
    x = np.minimum(np.floor(samples * LUT), LUT - 1) / (LUT - 1)  # matplotlib's nearest table entry
    x = x**GAMMA
    amplitude = HUE * x * (1 - x) / 2
    phi = 2 * math.pi * (START / 3 + ROTATIONS * x)
    rgb = x[:, None] + amplitude[:, None] * (np.stack([np.cos(phi), np.sin(phi)], axis=1) @ DIRECTIONS.T)
    colours = np.round(np.clip(rgb, 0, 1) * 255).astype(np.uint8)
    return np.vstack([np.zeros((1, 3), np.uint8), colours])


def pixels(state: np.ndarray, cell: int = CELL) -> np.ndarray:
    """A MinAtar state (H, W, C) of 0/1 as RGB uint8 pixels (H·cell, W·cell, 3): each cell in the
    colour of its last channel on, black where none is, scaled by nearest neighbour."""
    n = state.shape[-1]
    index = np.amax(np.asarray(state, np.int64) * np.arange(1, n + 1), axis=-1)  # MinAtar's `numerical_state`
    return np.repeat(np.repeat(palette(n)[index], cell, axis=0), cell, axis=1)


class MinAtarPixels(gym.Wrapper):
    """A MinAtar env whose `rgb_array` frames are `pixels` of its state; `fps` (the pace a person
    plays the game at) is its `render_fps`, the rate of its videos."""

    def __init__(self, env: gym.Env, fps: float | None = None) -> None:
        super().__init__(env)
        if fps is not None:
            self.metadata = {**env.metadata, "render_fps": fps}

    def render(self) -> RenderFrame | list[RenderFrame] | None:
        if self.render_mode != "rgb_array":
            return self.env.render()
        return pixels(minatar_game(self.env).state())


def minatar_game(env: gym.Env) -> Any:
    """The `minatar.Environment` that MinAtar's gym env `env` steps (MinAtar ships no types)."""
    unwrapped: Any = env.unwrapped
    return unwrapped.game
