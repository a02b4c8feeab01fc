"""MinAtar's Breakout and Freeway (Young & Tian 2019): 10×10 frames of 0/1 channels, sticky actions.

MinAtar is an optional dependency (`pip install minatar`). Its Gymnasium ids exist only after
`minatar.gym.register_envs()`, and importing `minatar.gym` takes seconds (it imports seaborn and
matplotlib for rendering); so this module registers the same ids with the same lazy entry point
itself, and minatar is imported only when one of its envs is made. `require_minatar` is that
import, quiet, with a one-line error when minatar is missing.

Breakout is the classic; Freeway is the second because a rule can play it well from one frame:
every car's speed and direction are in it, so whether a lane stays clear is a computation, while
Asterix, SpaceInvaders and Seaquest spawn enemies at random, and Seaquest adds oxygen and divers.

The experts read the frame as the networks see it: a (10, 10, C) uint8 array of 0/1, row 0 at the
top, channels in minatar's order. Each is a deterministic function of the frame; the env's sticky
actions (the previous action is repeated with probability 0.1) are its only noise.
"""

from __future__ import annotations

import importlib.util
import logging
import math
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.tasks.registry import TASKS, TaskSpec, register_task

GAMES = ("asterix", "breakout", "freeway", "seaquest", "space_invaders")
"""MinAtar's games, as `minatar.gym.register_envs` names them (Breakout-v0: all 6 actions, -v1: the minimal set)."""


def _register_ids() -> None:
    """Register MinAtar's ids as `minatar.gym.register_envs` does (a test checks they are the same),
    without importing minatar."""
    from gymnasium.envs.registration import register, registry

    for game in GAMES:
        name = game.title().replace("_", "")
        for version, minimal in (("v0", False), ("v1", True)):
            if f"MinAtar/{name}-{version}" not in registry:  # minatar's own registration came first
                register(
                    id=f"MinAtar/{name}-{version}",
                    entry_point="minatar.gym:BaseEnv",
                    kwargs={"game": game, "use_minimal_action_set": minimal},
                )


@contextmanager
def _quiet_root_logger() -> Iterator[None]:
    """Swallow what is logged on the root logger meanwhile, without configuring it: minatar warns
    "Cannot import seaborn" through `logging.warning`, which would also call `basicConfig()`."""
    root = logging.getLogger()
    handler, level = logging.NullHandler(), root.level
    root.addHandler(handler)
    root.setLevel(logging.ERROR)
    try:
        yield
    finally:
        root.removeHandler(handler)
        root.setLevel(level)


def require_minatar() -> None:
    """Import `minatar.gym` (quietly: without seaborn it only cannot render); a `ConfigError` if it is not installed."""
    try:
        with _quiet_root_logger():
            import minatar.gym  # noqa: F401  (registers MinAtar's Gymnasium ids)
    except ImportError:
        raise ConfigError("the MinAtar tasks need the minatar package: pip install minatar") from None


if importlib.util.find_spec("minatar") is not None:
    _register_ids()


def pace(game: str) -> float | None:
    """Steps per second a person plays MinAtar's `game` at (any action set): the `fps` of the
    preset that plays it (measured: docs/DEMONSTRATIONS.md); None if no preset plays it."""
    prefix = f"MinAtar/{game.title().replace('_', '')}-"
    return next((spec.fps for spec in TASKS.values() if spec.env_id.startswith(prefix) and spec.fps), None)


# --- Breakout -------------------------------------------------------------------------------------
# Channels paddle 0, ball 1, trail 2 (the ball's previous cell), brick 3. The minimal action set is
# (noop, left, right). Each step the paddle moves first, then the ball one cell along its diagonal:
# reflected by the side walls and the ceiling (it stays put along the reflected axis), by a brick
# (which breaks, unless the ball broke one on the step before; the ball stays in its row), and by
# the paddle when the paddle is under the ball's column or under the cell it would enter on row 9.
# Missing the ball ends the episode; the three brick rows (1–3) refill once all are broken.

NOOP, LEFT, RIGHT = 0, 1, 2
BRICK_ROWS = (1, 3)
"""The first and last rows that can hold bricks."""


def cell(grid: np.ndarray) -> tuple[int, int]:
    """(row, column) of the one cell that is on in `grid`, a channel of a MinAtar frame."""
    (y,), (x,) = np.nonzero(grid)
    return int(y), int(x)


def _ball_state(obs: np.ndarray) -> tuple[int, int, int, int, bool]:
    """(x, y, dx, dy, strike) of the ball from its cell and trail; `strike`: a brick broke on the step
    before (or the ball sits on a brick, passing through), so the next brick does not reflect it."""
    bricks = obs[:, :, 3]
    (y, x), (ty, tx) = cell(obs[:, :, 1]), cell(obs[:, :, 2])
    on_brick = bool(bricks[y, x])
    dx = x - tx if x != tx else (1 if x == 0 else -1)  # no sideways move: reflected by a side wall
    if y != ty:
        dy = y - ty
    elif y == 8 or y == 0:
        dy = -1 if y == 8 else 1  # reflected by the paddle or the ceiling
    elif on_brick:
        dy = 1  # the start: the ball begins on row 3's bricks, falling
    else:
        # Reflected by a brick, now broken: the one above (so now falling), unless that one is still
        # there and the one below is not (it fell onto it: now rising). Row 4 has bricks only above.
        dy = -1 if y < BRICK_ROWS[1] + 1 and bricks[y - 1, x] and not bricks[y + 1, x] else 1
    strike = on_brick or (y == ty and 0 < y < 8)
    return x, y, dx, dy, strike


@dataclass(frozen=True)
class Flight:
    """The ball's path until it comes down to the paddle row, simulated from one frame."""

    steps: int | None
    """Steps before the one on which it enters row 9 (the paddle can move steps + 1 cells by then);
    None: it does not come down within the horizon."""
    columns: tuple[int, int] = (0, 0)
    """Its column on row 8 and the one it enters on row 9: a paddle under the first returns it
    with the same sideways direction, under the second with the opposite one."""
    dx: int = 0
    """Its sideways direction on that step."""
    first_break: float = math.inf
    """Steps before the first brick breaks."""
    bricks: np.ndarray | None = field(default=None, compare=False, repr=False)
    """The bricks then (refilled if none is left, as the env does on that step)."""


def _fly(bricks: np.ndarray, x: int, y: int, dx: int, dy: int, strike: bool, horizon: int = 60) -> Flight:
    """Simulate the ball (bricks breaking on a copy) until it comes down to row 9."""
    bricks = bricks.astype(bool)
    first_break = math.inf
    for step in range(horizon):
        new_x, new_y = x + dx, y + dy
        if not 0 <= new_x <= 9:
            new_x, dx = min(max(new_x, 0), 9), -dx
        hit = False
        if new_y < 0:
            new_y, dy = 0, -dy
        elif bricks[new_y, new_x]:
            hit = True
            if not strike:
                bricks[new_y, new_x] = False
                new_y, dy = y, -dy
                first_break = min(first_break, step)
        elif new_y == 9:
            if not bricks.any():
                bricks[BRICK_ROWS[0] : BRICK_ROWS[1] + 1] = True
            return Flight(step, (x, new_x), dx, first_break, bricks)
        strike = hit
        x, y = new_x, new_y
    return Flight(None, first_break=first_break)


def _move_towards(paddle: int, column: int) -> int:
    return LEFT if column < paddle else RIGHT if column > paddle else NOOP


def breakout_strong(obs: np.ndarray) -> int:
    """Move the paddle to where the ball will come down (simulated with wall and brick bounces);
    of the two columns that return it, aim with the reachable one after which a brick breaks sooner
    (79.9 ± 14.4 over 100 episodes; 90 reach the 1000-step limit, the others lose the ball to sticky actions)."""
    paddle = int(np.argmax(obs[9, :, 0]))
    x, y, dx, dy, strike = _ball_state(obs)
    flight = _fly(obs[:, :, 3], x, y, dx, dy, strike)
    steps, bricks = flight.steps, flight.bricks
    if steps is None or bricks is None:  # both None or neither: it does not come down
        return _move_towards(paddle, x)

    def preference(column: int) -> tuple[bool, float, int]:
        """Reachable first (the paddle moves before the ball), then the sooner break, then the nearer."""
        distance = abs(column - paddle)
        if distance > steps + 1:
            return True, 0.0, distance
        back_dx = flight.dx if column == flight.columns[0] else -flight.dx
        return False, _fly(bricks, flight.columns[1], 8, back_dx, -1, False).first_break, distance

    return _move_towards(paddle, min(flight.columns, key=preference))


def breakout_imperfect(obs: np.ndarray) -> int:
    """Chase the ball's current column: no anticipation, so a diagonal ball often outruns the paddle
    (8.6 ± 9.2 over 100 episodes, at most 670 steps)."""
    paddle = int(np.argmax(obs[9, :, 0]))
    return _move_towards(paddle, int(np.argmax(obs[:, :, 1].max(axis=0))))


# --- Freeway --------------------------------------------------------------------------------------
# Channels chicken 0 (always column 4), car 1, then speed1..speed5 2–6: a car's trail cell (behind
# it, so it gives the direction) in the channel of its speed s, the car moving one cell every s + 1
# frames from an unseen phase. Rows 1–8 hold one car each and wrap around. The minimal action set is
# (noop, up, down); the chicken moves at most once every 3 frames (a timer it does not see), is sent
# back to row 9 when a car is on its cell, and scores +1 on reaching row 0.

UP, DOWN = 1, 2
CHICKEN_COLUMN = 4
MOVE_PERIOD = 3
"""Frames between two moves of the chicken."""


def _car_reaches(obs: np.ndarray, row: int, frames: int) -> bool:
    """Whether the car of `row` can be on the chicken's column within `frames` frames (this one
    first), in the worst case of its unseen phase: it moves now, then every s + 1 frames."""
    if not 1 <= row <= 8:
        return False
    x = int(np.flatnonzero(obs[row, :, 1])[0])
    channel = next(c for c in range(2, 7) if obs[row, :, c].any())
    direction = 1 if obs[row, (x - 1) % 10, channel] else -1  # the trail is behind the car
    distance = (CHICKEN_COLUMN - x) * direction % 10
    period = channel  # speed s = channel − 1
    return distance == 0 or (frames - 1) // period + 1 >= distance


def freeway_strong(obs: np.ndarray) -> int:
    """Step up when the next lane stays clear for the 3 frames the chicken must then wait there;
    step back down when a car is about to reach it and the lane below is clear; else wait
    (65.9 ± 1.9 crossings over 100 episodes, min 61)."""
    row = int(np.argmax(obs[:, CHICKEN_COLUMN, 0]))
    if not _car_reaches(obs, row - 1, MOVE_PERIOD):
        return UP
    if _car_reaches(obs, row, 1) and not _car_reaches(obs, row + 1, MOVE_PERIOD):
        return DOWN
    return NOOP


def freeway_imperfect(obs: np.ndarray) -> int:
    """Always step up: never waits, so it walks into the cars in its way (15.7 ± 12.7, min 0)."""
    return UP


# --- the presets ----------------------------------------------------------------------------------

DEFAULTS: dict[str, object] = {
    # MinAtar's DQN (Young & Tian 2019, §4 and their dqn.py): a 3×3 conv of 16 filters (the torso)
    # then one dense layer of 128; step size 0.00025 (theirs is RMSProp's, ours Adam's), batch 32,
    # replay 100k, the target network refreshed every 1000 steps (one gradient step per frame), ε
    # annealed to 0.1. Ours: 100k steps for their 5M frames, and the shared ENV_DEFAULTS' protocol.
    "hidden": (128,),
    "bc_hidden": (128,),
    "learning_rate": 2.5e-4,
    "batch_size": 32,
    "replay_capacity": 100_000,
    "target_update_period": 1000,
    "epsilon_end": 0.1,
    "total_steps": 100_000,
    "eval_every": 5_000,
    "demo_episodes": 10,
    "early_stop_window": 0,
}
"""The Config defaults of the MinAtar presets."""

# MinAtar has no step limit and a good player never loses Breakout's ball (the bricks refill), so
# the limit is what ends the strong expert's episodes (90 of 100): 1000 steps is ~84 bricks, three
# walls' worth, and 10 demonstrated episodes fill a tenth of the 100k-step budget.
register_task(
    TaskSpec(
        "minatar-breakout",
        "MinAtar/Breakout-v1",
        "minatar-breakout",
        1000,
        defaults=DEFAULTS,
        experts={"strong": breakout_strong, "imperfect": breakout_imperfect},
        keys={"": 0, "left": 1, "right": 2},
        fps=4,  # the pace measured for a person reacting in 0.25 s (benchmarks/play_pace.py)
        doc="MinAtar Breakout (minimal actions: noop, left, right), +1 per brick, 1000-step limit",
    )
)

# Freeway ends itself after 2501 frames, on a clock the frame does not show; the 2500-step limit ends
# it one frame earlier as a truncation, which is what an unseen clock is to the agent.
register_task(
    TaskSpec(
        "minatar-freeway",
        "MinAtar/Freeway-v1",
        "minatar-freeway",
        2500,
        defaults=DEFAULTS,
        experts={"strong": freeway_strong, "imperfect": freeway_imperfect},
        keys={"": 0, "up": 1, "down": 2},
        fps=8,  # the pace measured for a person reacting in 0.25 s (benchmarks/play_pace.py)
        doc="MinAtar Freeway (minimal actions: noop, up, down), +1 per crossing, 2500-step limit",
    )
)
