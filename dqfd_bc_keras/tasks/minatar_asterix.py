"""MinAtar's Asterix: the preset `minatar-asterix` and its scripted experts.

Channels player 0, enemy 1, trail 2 (the cell behind an enemy or a treasure: it gives the
direction), gold 3 (a treasure). The minimal action set is (noop, left, up, right, down); the player
stays on rows 1–8. Each of rows 1–8 holds at most one entity, which enters from the left or the
right edge (a third of them gold) into an empty row on a spawn timer, crosses and leaves; an entity
just entered has no trail, and its edge gives its direction. Each step the player moves first and
meets what is on its new cell (gold: +1, an enemy: the end), then the entities may move one cell,
on a timer the frame does not show, and meet it again. Every 100 frames or so the timers shorten:
from a move every 5 frames and an entry every 10 to both every frame after about 920 frames.

Since the timers do not show, the rules take the worst case: an entity may move on every step, and
an entity may enter any empty row. Most deaths are then the env's sticky actions (the previous
action is repeated with probability 0.1), which carry the player into a cell it meant to leave, and
walls, where an enemy coming along the row leaves only up or down.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from dqfd_bc_keras.tasks.minatar import DEFAULTS, cell
from dqfd_bc_keras.tasks.registry import TaskSpec, register_task

NOOP, LEFT, UP, RIGHT, DOWN = 0, 1, 2, 3, 4
MOVES = {NOOP: (0, 0), LEFT: (0, -1), UP: (-1, 0), RIGHT: (0, 1), DOWN: (1, 0)}
"""Action → (row, column) step."""
LOOKAHEAD = 3
"""Steps the strong rule looks ahead (further, the worst case closes every row)."""


def _entities(obs: np.ndarray) -> list[tuple[int, int, int, bool]]:
    """(row, column, direction, gold) of each entity: its trail is behind it; without one it has just
    entered, from the edge it is on."""
    entities = []
    for channel, gold in ((1, False), (3, True)):
        for y, x in zip(*np.nonzero(obs[:, :, channel]), strict=True):
            if x > 0 and obs[y, x - 1, 2]:
                direction = 1
            elif x < 9 and obs[y, x + 1, 2]:
                direction = -1
            else:
                direction = 1 if x == 0 else -1
            entities.append((int(y), int(x), direction, gold))
    return entities


def danger(obs: np.ndarray, step: int) -> np.ndarray:
    """(10, 10) bool: the cells an enemy may be on during `step` (1: this one) in the worst case:
    each enemy moving on every step, and one entering every empty row from either edge at once."""
    cells = np.zeros((10, 10), bool)
    rows = set()
    for y, x, direction, gold in _entities(obs):
        rows.add(y)
        if not gold:
            reach = x + direction * np.arange(step + 1)
            cells[y, reach[(reach >= 0) & (reach <= 9)]] = True
    for y in set(range(1, 9)) - rows:
        cells[y, : step + 1] = cells[y, 9 - step :] = True
    return cells


def _move(y: int, x: int, action: int) -> tuple[int, int]:
    dy, dx = MOVES[action]
    return min(max(y + dy, 1), 8), min(max(x + dx, 0), 9)


def _gold_distance(obs: np.ndarray) -> Callable[[int, int], float]:
    """Cell → distance (rows + columns) to the nearest treasure; with none, to the centre."""
    golds = [(y, x) for y, x, _, gold in _entities(obs) if gold]
    if not golds:
        return lambda y, x: abs(y - 4.5) + abs(x - 4.5)
    return lambda y, x: min(abs(y - gy) + abs(x - gx) for gy, gx in golds)


def asterix_strong(obs: np.ndarray) -> int:
    """Take a move that is safe this step and leaves the longest worst-case escape (3 steps ahead);
    among those, weigh (heaviest first) a sticky repeat of the move next step being fatal, the
    distance to the nearest treasure and to the centre column (walls are traps)."""
    py, px = cell(obs[:, :, 0])
    dangers = [danger(obs, step) for step in range(1, LOOKAHEAD + 1)]
    to_gold = _gold_distance(obs)

    def survives(y: int, x: int, step: int) -> int:
        """Steps survived from (y, x) after `step` steps, up to the lookahead, in the worst case."""
        if step >= LOOKAHEAD:
            return 0
        best = 0
        for action in MOVES:
            ny, nx = _move(y, x, action)
            if not dangers[step][ny, nx]:
                best = max(best, 1 + survives(ny, nx, step + 1))
                if best == LOOKAHEAD - step:
                    break
        return best

    def cost(action: int) -> float:
        y, x = _move(py, px, action)
        wish = 0.01 * to_gold(y, x) + 0.02 * abs(x - 4.5)
        if dangers[0][y, x]:
            return 10 + wish
        sticky = 0.1 * dangers[1][_move(y, x, action)]  # the env repeats this action next step
        return sticky + (LOOKAHEAD - 1 - survives(y, x, 1)) + wish

    return min(MOVES, key=cost)


def asterix_imperfect(obs: np.ndarray) -> int:
    """Go for the nearest treasure by any move no enemy can meet this step: no lookahead, so it walks
    into rows it cannot leave, and pins itself against the walls."""
    py, px = cell(obs[:, :, 0])
    now, to_gold = danger(obs, 1), _gold_distance(obs)
    return min(MOVES, key=lambda action: (bool(now[_move(py, px, action)]), to_gold(*_move(py, px, action))))


# MinAtar has no step limit; Asterix's timers shorten until entities move and enter on every frame
# (about 920 frames), after which the game is the same to the end. 1000 steps covers that ramp, and 10
# demonstrated episodes fill a tenth of the 100k-step budget.
register_task(
    TaskSpec(
        "minatar-asterix",
        "MinAtar/Asterix-v1",
        "minatar-asterix",
        1000,
        defaults=DEFAULTS,
        experts={"strong": asterix_strong, "imperfect": asterix_imperfect},
        keys={"": 0, "left": 1, "up": 2, "right": 3, "down": 4},
        fps=4,  # the pace measured for a person reacting in 0.25 s (benchmarks/play_pace.py)
        doc="MinAtar Asterix (minimal actions: noop, left, up, right, down), +1 per treasure, 1000-step limit",
    )
)
