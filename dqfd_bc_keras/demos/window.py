"""The window a person plays and watches demonstrations in: the env's frame scaled up, lines of
text beneath, and the keyboard read between frames (pygame, imported only here and in keys.py)."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dqfd_bc_keras.demos.keys import CONTROLS, pygame
from dqfd_bc_keras.errors import ConfigError

HEADLESS = {"offscreen", "dummy"}
"""SDL's video drivers without a screen: used when asked for (SDL_VIDEODRIVER, the tests), else no display was found."""
WIDTH = 600
"""The frame's larger side on screen, about: small frames (MinAtar's 10x10) are scaled by a whole factor."""
LINE = 22
"""Pixels per line of text."""
TEXT = (235, 235, 235)
BACKGROUND = (24, 24, 28)


@dataclass
class Input:
    """What the keyboard did since the last poll."""

    down: set[str] = field(default_factory=set)
    """Action keys held now or pressed since (a tap between two frames counts)."""
    pressed: set[str] = field(default_factory=set)
    """Action keys pressed since the last poll (held from before, they are not)."""
    controls: set[str] = field(default_factory=set)
    """What the control keys asked for (`keys.CONTROLS`' values)."""
    closed: bool = False
    """The window was closed."""


def _no_display(why: str) -> str:
    """What a person without a screen is told, and what to do."""
    return (
        f"cannot open a window (no display: {why}): run it on a desktop (DISPLAY or WAYLAND_DISPLAY set), "
        "or headless under a virtual display (xvfb-run python -m dqfd_bc_keras.demos …)"
    )


class Window:
    """A pygame window: `draw` a frame and text, `poll` the keyboard, `tick` at a frame rate."""

    def __init__(self, title: str) -> None:
        self.pg = pygame()
        asked = os.environ.get("SDL_VIDEODRIVER")
        try:
            self.pg.display.init()
        except self.pg.error as error:  # the driver asked for has no display to open (x11 without DISPLAY)
            self.pg.display.quit()
            said = f"SDL_VIDEODRIVER={asked} says" if asked else "SDL says"
            raise ConfigError(_no_display(f"{said} {str(error)!r}")) from None
        driver = self.pg.display.get_driver()
        if driver in HEADLESS and asked != driver:  # SDL's fallback, not a choice
            self.pg.display.quit()
            raise ConfigError(_no_display(f"SDL found only {driver!r}"))
        self.pg.display.set_caption(title)
        self.pg.font.init()
        self.font = self.pg.font.Font(None, LINE + 2)  # pygame's own font: nothing to find on the system
        self.clock = self.pg.time.Clock()
        self.screen: Any = None  # pygame's display Surface (pygame is imported untyped), made by the first draw
        self.held: set[str] = set()

    def wrap(self, line: str, width: int) -> list[str]:
        """`line` broken at " · " (else at spaces) into lines that fit `width` pixels."""
        sep = " · " if " · " in line else " "
        rows = [""]
        for part in line.split(sep):
            joined = f"{rows[-1]}{sep}{part}" if rows[-1] else part
            if rows[-1] and self.font.size(joined)[0] > width:
                rows.append(part)
            else:
                rows[-1] = joined
        return rows

    def draw(self, frame: object, lines: list[str]) -> None:
        """Show `frame` (an RGB array, H x W x 3: an `rgb_array` render) scaled up, `lines` beneath it
        (wrapped to its width)."""
        pg = self.pg
        image = None if frame is None else np.asarray(frame, np.uint8)
        h, w = image.shape[:2] if image is not None else (0, WIDTH)
        scale = max(1, round(WIDTH / max(h, w)))
        width = max(w * scale, WIDTH)
        lines = [row for line in lines for row in self.wrap(line, width - 20)]
        size = (width, h * scale + LINE * len(lines) + 16)
        if self.screen is None or self.screen.get_size() != size:
            self.screen = pg.display.set_mode(size)
        self.screen.fill(BACKGROUND)
        if image is not None:
            surface = pg.surfarray.make_surface(np.ascontiguousarray(image[..., :3].swapaxes(0, 1)))
            self.screen.blit(pg.transform.scale(surface, (w * scale, h * scale)), ((size[0] - w * scale) // 2, 0))
        for i, line in enumerate(lines):
            self.screen.blit(self.font.render(line, True, TEXT), (10, h * scale + 8 + i * LINE))
        pg.display.flip()

    def poll(self) -> Input:
        """The keys down and the controls pressed since the last poll; closing the window is `closed`."""
        pg, got = self.pg, Input()
        for event in pg.event.get():
            if event.type == pg.QUIT:
                got.closed = True
            elif event.type in (pg.KEYDOWN, pg.KEYUP):
                name = pg.key.name(event.key)
                if name in CONTROLS:
                    if event.type == pg.KEYDOWN:
                        got.controls.add(CONTROLS[name])
                elif event.type == pg.KEYDOWN:
                    self.held.add(name)
                    got.pressed.add(name)
                else:
                    self.held.discard(name)
        got.down = got.pressed | self.held
        return got

    def tick(self, fps: float) -> None:
        """Wait until 1/fps seconds have passed since the last tick."""
        self.clock.tick(fps)

    def close(self) -> None:
        self.pg.display.quit()
