"""MinAtar's Seaquest: the preset `minatar-seaquest` and its scripted experts.

Channels sub front 0 and sub back 1 (the player's submarine: two cells, so its facing shows),
friendly bullet 2, trail 3 (the cell behind an enemy or a diver: it gives the direction), enemy
bullet 4, enemy fish 5, enemy sub 6, oxygen gauge 7 and diver gauge 8 (bars on row 9: one cell per
20 frames of oxygen, out of 10; one per diver carried, out of 6), diver 9. The minimal action set is
(noop, left, up, right, down, fire): the player moves on rows 0 (the surface) to 8, or fires from its
front along its row (firing does nothing during a 5-frame cool-down the frame does not show).

Fish and enemy subs enter rows 1–8 from either edge on a spawn timer and cross, moving a cell every
5 frames at first, on timers the frame does not show; an enemy sub fires every 10 frames, its bullet
moving a cell every frame. Touching any of them ends the game; a bullet on one kills it (+1). Divers
cross the same way and are picked up by touching them. Oxygen runs out after 200 frames under
water; surfacing refills it and costs a diver, or, with 6, pays 1 per 20 frames of oxygen left
(and then leaves the count at −1, shown as 0: a quirk of minatar's). Surfacing with no diver ends
the game. Each surfacing makes enemies enter and move faster.

Since the timers do not show, the rules take the worst case: every enemy and bullet may move on every
step, both ways where its direction is ambiguous (two trails, or a bullet in a row without an enemy
sub). As in Asterix, sticky actions (the previous action repeated with probability 0.1) are then
most deaths: the rules also weigh a repeat of their move.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dqfd_bc_keras.tasks.minatar import DEFAULTS, cell
from dqfd_bc_keras.tasks.registry import TaskSpec, register_task

NOOP, LEFT, UP, RIGHT, DOWN, FIRE = 0, 1, 2, 3, 4, 5
MOVES = {NOOP: (0, 0), LEFT: (0, -1), UP: (-1, 0), RIGHT: (0, 1), DOWN: (1, 0), FIRE: (0, 0)}
"""Action → (row, column) step."""
COOL_DOWN = 5
"""Frames between two shots of the player."""
LOW_OXYGEN = 4
"""Gauge cells (20 frames each) at or below which the strong rule surfaces, if it carries a diver:
80 frames for a climb of 8 rows and the dodging on the way (3, 5 and 6 scored a little less over 30 episodes)."""
MAX_DIVERS = 6


def _directions(obs: np.ndarray, y: int, x: int) -> set[int]:
    """Where an entity at (y, x) may move: away from its trail (two trails: either); without one it
    has just entered, from the edge it is on."""
    directions = set()
    if x > 0 and obs[y, x - 1, 3]:
        directions.add(1)
    if x < 9 and obs[y, x + 1, 3]:
        directions.add(-1)
    return directions or {1 if x == 0 else -1}


@dataclass(frozen=True)
class Scene:
    """What the rules read from a frame."""

    y: int
    x: int
    facing: int
    """+1: the sub faces right."""
    oxygen: int
    """Gauge cells, 0–10."""
    divers: int
    """Divers carried, 0–6."""
    enemies: list[tuple[int, int, int]]
    """(row, column, direction) of each fish and enemy sub, twice if it may go either way."""
    divers_around: list[tuple[int, int]]
    bullets: list[tuple[int, int, int]]
    """(row, column, direction) of each enemy bullet: that of the enemy subs in its row, else both."""


def read(obs: np.ndarray) -> Scene:
    y, x = cell(obs[:, :, 0])
    back = int(np.flatnonzero(obs[y, :, 1])[0])
    enemies = [
        (int(ey), int(ex), direction)
        for channel in (5, 6)
        for ey, ex in zip(*np.nonzero(obs[:9, :, channel]), strict=True)
        for direction in _directions(obs, ey, ex)
    ]
    bullets = []
    for by, bx in zip(*np.nonzero(obs[:9, :, 4]), strict=True):
        subs = np.flatnonzero(obs[by, :, 6])
        directions = {d for s in subs for d in _directions(obs, by, int(s))} or {-1, 1}
        bullets += [(int(by), int(bx), d) for d in directions]
    return Scene(
        y,
        x,
        1 if x > back else -1,
        int(obs[9, :, 7].sum()),
        int(obs[9, :, 8].sum()),
        enemies,
        [(int(dy), int(dx)) for dy, dx in zip(*np.nonzero(obs[:9, :, 9]), strict=True)],
        bullets,
    )


def danger(scene: Scene, step: int) -> np.ndarray:
    """(10, 10) bool: the cells an enemy or an enemy bullet may be on during `step` (1: this one), all
    moving on every step."""
    cells = np.zeros((10, 10), bool)
    for y, x, direction in scene.enemies + scene.bullets:
        reach = x + direction * np.arange(step + 1)
        cells[y, reach[(reach >= 0) & (reach <= 9)]] = True
    return cells


def _move(y: int, x: int, action: int) -> tuple[int, int]:
    dy, dx = MOVES[action]
    return min(max(y + dy, 0), 8), min(max(x + dx, 0), 9)


def _play(obs: np.ndarray, low_oxygen: int) -> int:
    """The strong rule, surfacing (with a diver) at `low_oxygen` gauge cells or with 6 divers."""
    scene = read(obs)
    y, x, divers = scene.y, scene.x, scene.divers
    now, next_step = danger(scene, 1), danger(scene, 2)
    ready = not any(abs(bx - x) < COOL_DOWN for _, bx in zip(*np.nonzero(obs[:9, :, 2]), strict=True))
    surface = divers >= 1 and (scene.oxygen <= low_oxygen or divers == MAX_DIVERS)

    def fatal_surface(row: int, from_row: int) -> bool:
        return row == 0 and from_row > 0 and divers == 0

    def wish(ny: int, nx: int, facing: int, fired: bool) -> float:
        """How far (rows and columns) the new cell is from what the rule wants."""
        if surface:
            return float(ny)
        cost = 2.0 if ny == 0 else 0.0  # dive
        if divers < MAX_DIVERS and scene.divers_around:
            cost += 0.5 * min(abs(ny - dy) + abs(nx - dx) for dy, dx in scene.divers_around)
        if scene.enemies:  # into the nearest enemy's row, facing it
            ey, ex, _ = min(scene.enemies, key=lambda e: abs(e[0] - ny) + 0.3 * abs(e[1] - nx))
            cost += abs(ey - ny) + (0.5 if ey == ny and (ex - nx) * facing < 0 else 0.0)
        return cost - (3.0 if fired else 0.0)

    def cost(action: int) -> float:
        ny, nx = _move(y, x, action)
        if fatal_surface(ny, y):
            return 100.0
        facing = -1 if action == LEFT else 1 if action == RIGHT else scene.facing
        ahead = [next_step[_move(ny, nx, b)] or fatal_surface(_move(ny, nx, b)[0], ny) for b in MOVES]
        risk = 10.0 * now[ny, nx] + 0.1 * ahead[action] + 1.0 * all(ahead)  # ahead[action]: a sticky repeat
        risk += 0.05 * (1 <= ny <= 8 and nx in (0, 9))  # where enemies enter
        risk += 0.1 * (ny == 1 and divers == 0)  # a sticky "up" would surface
        fired = action == FIRE and ready and any(ey == y and (ex - x) * scene.facing > 0 for ey, ex, _ in scene.enemies)
        return risk + 0.05 * wish(ny, nx, facing, fired)

    return min(MOVES, key=cost)


def seaquest_strong(obs: np.ndarray) -> int:
    """Hunt: get into the nearest enemy's row facing it and fire, picking up divers on the way; surface
    with 6 divers or, carrying one, when the oxygen is down to 4 gauge cells; never surface without a
    diver. Every move weighed by the worst case: whether an enemy or a bullet can be on the new cell,
    whether every next move is then unsafe, whether a sticky repeat of the move is."""
    return _play(obs, LOW_OXYGEN)


def seaquest_imperfect(obs: np.ndarray) -> int:
    """The strong rule that does not watch its oxygen: it surfaces only with 6 divers, which it rarely
    gathers, so most dives end when the oxygen runs out, after 200 frames."""
    return _play(obs, -1)


# MinAtar has no step limit; a good player's dives last 200 frames or less, and each surfacing makes
# the enemies faster. 1000 steps is five dives, and 10 demonstrated episodes fill a tenth of the
# 100k-step budget.
register_task(
    TaskSpec(
        "minatar-seaquest",
        "MinAtar/Seaquest-v1",
        "minatar-seaquest",
        1000,
        defaults=DEFAULTS,
        experts={"strong": seaquest_strong, "imperfect": seaquest_imperfect},
        keys={"": 0, "left": 1, "up": 2, "right": 3, "down": 4, "space": 5},
        fps=4,  # the pace measured for a person reacting in 0.25 s (benchmarks/play_pace.py)
        doc="MinAtar Seaquest (minimal actions: noop, left, up, right, down, fire), +1 per enemy, 1000-step limit",
    )
)
