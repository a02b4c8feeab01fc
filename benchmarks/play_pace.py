"""How fast a person can play each MinAtar preset: a player who reacts in 0.25 s, simulated at
several paces, against the preset's strong scripted expert acting at once.

    python benchmarks/play_pace.py [--episodes 20] [--reaction 0.25] [--keep 0.8] [--json]
    python benchmarks/play_pace.py --quick      # 2 episodes of at most 60 steps, for the tests

The window (`demos play`) shows frame k from the tick after step k − 1 to the next: at f steps per
second, from (k − 1)/f to k/f, and the keys down at k/f choose step k's action. A person who
reacts in τ seconds acts at k/f on the frame on screen at k/f − τ: frame k − d, d = ⌈τ·f⌉ − 1
steps old (d = 0 up to 1/τ steps/s, d = 1 up to 2/τ, …). The player's intent is the preset's
strong expert: at step k it plays `strong(frame k − d)` (the first frame while k < d), so d = 0
is the expert itself. For d = 0, 1, 2, … the episodes are played with seeds 0, 1, … on the task
env, sticky actions and all; the pace chosen for the preset is the fastest pace whose delay keeps
at least `--keep` of the expert's mean return, (d + 1)/τ steps/s for the largest such d (all
smaller delays keeping it too). The presets' `fps` are the paces this chose (docs/DEMONSTRATIONS.md).
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from dqfd_bc_keras.envs.episodes import play
from dqfd_bc_keras.envs.make import make_task
from dqfd_bc_keras.tasks import TASKS

PRESETS = [name for name, spec in TASKS.items() if spec.env_id.startswith("MinAtar/")]
DELAYS = (0, 1, 2, 3, 4)
"""Steps a frame is old when the player acts on it (0: the expert itself)."""


def delay_at(fps: float, reaction: float) -> int:
    """Steps behind the game a player who reacts in `reaction` s acts at `fps` steps/s: ⌈τ·f⌉ − 1."""
    return max(0, math.ceil(round(reaction * fps, 9)) - 1)


def fastest_pace(delay: int, reaction: float) -> float:
    """The fastest pace (steps/s) at which the player is `delay` steps behind: (d + 1)/τ."""
    return (delay + 1) / reaction


class Delayed:
    """`expert` acting on the frame `delay` steps old (the first one while the episode is younger):
    a policy for `envs.episodes.play`, and its watcher, which keeps the frames seen."""

    def __init__(self, expert: Callable[[np.ndarray], int], delay: int) -> None:
        self.expert, self.delay, self.frames = expert, delay, []

    def __call__(self, obs: np.ndarray) -> int:
        return self.expert(self.frames[max(0, len(self.frames) - 1 - self.delay)])

    def reset(self, obs: np.ndarray, seed: int | None) -> None:
        self.frames = [obs]

    def step(self, action, next_obs, reward, terminated, truncated, info) -> None:
        self.frames.append(next_obs)


def measure(task: str, episodes: int, max_steps: int | None) -> dict[int, list[float]]:
    """Per delay, the returns of `episodes` episodes (seeds 0, 1, …) of the delayed strong expert."""
    env = make_task(task, max_steps=max_steps)
    expert = TASKS[task].experts["strong"]
    returns = {}
    for delay in DELAYS:
        player = Delayed(expert, delay)
        returns[delay] = play(env, player, range(episodes), watcher=player).returns
    env.close()
    return returns


def chosen_pace(returns: dict[int, list[float]], reaction: float, keep: float) -> tuple[float, int]:
    """The fastest pace whose delay, and every smaller one, keeps `keep` of the expert's mean
    return; and that delay."""
    expert = statistics.fmean(returns[0])
    delay = 0
    while delay + 1 in returns and statistics.fmean(returns[delay + 1]) >= keep * expert:
        delay += 1
    return fastest_pace(delay, reaction), delay


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=20, help="episodes per preset and delay")
    parser.add_argument("--reaction", type=float, default=0.25, help="the player's reaction time, seconds")
    parser.add_argument("--keep", type=float, default=0.8, help="share of the expert's mean return to keep")
    parser.add_argument("--tasks", help="comma-separated presets (default: every MinAtar preset)")
    parser.add_argument("--json", action="store_true", help="print the numbers as JSON")
    parser.add_argument("--quick", action="store_true", help="2 episodes of at most 60 steps, for the tests")
    args = parser.parse_args(argv)
    episodes, max_steps = (2, 60) if args.quick else (args.episodes, None)
    report = {"reaction_s": args.reaction, "keep": args.keep, "episodes": episodes, "max_steps": max_steps}
    report["presets"] = {}
    for task in args.tasks.split(",") if args.tasks else PRESETS:
        returns = measure(task, episodes, max_steps)
        pace, delay = chosen_pace(returns, args.reaction, args.keep)
        expert = statistics.fmean(returns[0])
        report["presets"][task] = {
            "pace": pace,
            "delay": delay,
            "preset_fps": TASKS[task].fps,
            "delays": {
                d: {
                    "up_to_fps": fastest_pace(d, args.reaction),
                    "mean": statistics.fmean(r),
                    "std": statistics.pstdev(r),
                    "share": statistics.fmean(r) / expert if expert else None,
                }
                for d, r in returns.items()
            },
        }
    if args.json:
        print(json.dumps(report, indent=1))
        return 0
    print(f"a player reacting in {args.reaction:g} s, the strong expert's intent, {episodes} episodes a delay")
    for task, row in report["presets"].items():
        cells = [
            f"d={d} (≤{v['up_to_fps']:g}/s) {v['mean']:.1f}±{v['std']:.1f} "
            + ("" if v["share"] is None else f"{v['share']:.0%}")
            for d, v in row["delays"].items()
        ]
        print(f"{task:24} pace {row['pace']:g} steps/s (preset {row['preset_fps']:g}) | " + " | ".join(cells))
    return 0


if __name__ == "__main__":
    sys.exit(main())
