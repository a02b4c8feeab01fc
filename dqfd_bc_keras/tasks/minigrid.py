"""MiniGrid's Empty-8x8 room (the `minigrid` package): a sparse reward, 1 − 0.9·steps/256 on reaching
the goal, and a scripted teacher that takes the long way round, so an agent can beat it by finding
the short one (issue W's study).

The room never changes: the agent starts in the top-left corner facing east, the goal is in the
bottom-right one. The observation the networks see is MiniGrid's Dict flattened: `direction` one-hot
(4), then the 7×7×3 egocentric `image` (object, colour, state per cell; the text `mission` is
dropped). The agent stands at the view's bottom centre, column 3, row 6, so the cell ahead is column
3, row 5.
"""

from __future__ import annotations

import numpy as np

from dqfd_bc_keras.tasks.registry import ENV_DEFAULTS, TaskSpec, register_task

LEFT, RIGHT, FORWARD = 0, 1, 2
"""MiniGrid's first three actions (the others, pickup, drop, toggle and done, do nothing here)."""
AHEAD = 4 + (3 * 7 + 5) * 3
"""The flattened observation's index of the object id in the cell ahead (after the 4-way direction)."""
WALL = 2
"""MiniGrid's object id of a wall."""


def strong(obs: np.ndarray) -> int:
    """Forward until a wall is ahead, then turn right: east along the top wall, south along the
    right one, into the goal in 11 steps, the shortest path (0.961 every episode)."""
    return RIGHT if obs[AHEAD] == WALL else FORWARD


def imperfect(obs: np.ndarray) -> int:
    """Forward until a wall is ahead, then turn left: round three walls of the room, 24 steps
    where 11 suffice (0.916 every episode)."""
    return LEFT if obs[AHEAD] == WALL else FORWARD


register_task(
    TaskSpec(
        "minigrid-empty",
        "minigrid:MiniGrid-Empty-8x8-v0",
        "minigrid-empty",
        256,
        defaults={**ENV_DEFAULTS, "eval_every": 1_000},
        experts={"strong": strong, "imperfect": imperfect},
        keys={"left": LEFT, "right": RIGHT, "up": FORWARD},
        fps=4,
        doc="MiniGrid-Empty-8x8 (minigrid package), reward 1 − 0.9·steps/256 at the goal, MiniGrid's own "
        "256-step limit; a teacher that turns left at walls (24 steps) where right is the shortest (11)",
    )
)
