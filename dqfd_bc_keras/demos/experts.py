"""Demonstrators: the task presets' scripted experts (each family's rules live in its module of
`tasks/`), and `make_demonstrator`, which also turns a user's rule (`module:function`) or a saved
`.keras` Q-network or BC model into a demonstrator for any task. They are built and played in
`recording.py`; this module is their public face, and `python -m dqfd_bc_keras.demos.experts` prints
the scripted experts' returns (`commands/experts.py`).

Each scripted rule reads only the leading physical features of the observation, so it also works
on observations from a time-aware wrapper that appends a remaining-time feature at the end.
"""

from __future__ import annotations

from dqfd_bc_keras.choices import EXPERT_NAMES
from dqfd_bc_keras.demos.recording import Demonstrator, expert_returns, make_demonstrator, make_expert, try_demonstrator

__all__ = ["EXPERT_NAMES", "Demonstrator", "expert_returns", "make_demonstrator", "make_expert", "try_demonstrator"]

if __name__ == "__main__":
    from dqfd_bc_keras.commands.experts import cli

    raise SystemExit(cli())
