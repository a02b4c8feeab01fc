"""The replay's memory per 100,000 transitions: vectors, MinAtar's frames and Atari's stacked frames.

    python benchmarks/memory_frames.py             # 100,000 transitions of each (~1 GB peak for Atari)
    python benchmarks/memory_frames.py --quick     # 1,000 transitions, for the tests

Builds a `PrioritizedReplay` of `--transitions` self-generated rows (and a D_demo of 1% of that)
for each kind of observation, in a fresh child process each, and prints the bytes of its
variables (the table, the n-step view, the sum tree, the frame pool), the child's resident set
growth (/proc/self/status VmRSS; Linux only) and what storing s and s' as they are would cost: as
float32 (what a float table would hold) and as uint8 stacks (a frame copied once per stack). The
pool's bytes are computed from its shape, so they are exact; the RSS growth shows nothing else
is allocated.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
KINDS = {
    "cartpole (4 floats)": ((4,), 1),
    "MinAtar Breakout (10×10×4)": ((10, 10, 4), 1),
    "Atari (84×84, 4 stacked)": ((84, 84, 4), 4),
}


def measure(shape: list[int], stack: int, transitions: int) -> dict:
    """In this process: the replay's variable bytes and the RSS it added."""
    sys.path.insert(0, str(REPO))
    import numpy as np

    from dqfd_bc_keras.core.networks import NetworkInput
    from dqfd_bc_keras.core.replay import PrioritizedReplay, ReplaySettings
    from dqfd_bc_keras.envs.observations import Frames

    def rss() -> int:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
        return 0

    frames = None if len(shape) == 1 else Frames(tuple(shape), 1 / 255, stack)
    spec = NetworkInput(int(np.prod(shape)), frames)
    before = rss()
    replay = PrioritizedReplay(
        spec, 4, ReplaySettings(capacity=transitions, demo_capacity=max(1, transitions // 100), n_step=10)
    )
    grown = rss() - before
    parts = {"table": replay.table, "n_step_view": replay.n_step_view, "sum tree": replay.tree.leaf}
    if frames is not None:
        parts["frame pool"] = replay.frame_pool.pool
    sizes = {name: int(np.prod(v.shape)) * v.dtype.size for name, v in parts.items()}
    rows = replay.demo_capacity + replay.capacity
    values = int(np.prod(shape))
    return {
        "variables": sizes,
        "total": sum(sizes.values()) + replay.tree.block_sums.shape[0] * 4,
        "rss_growth": grown,
        "rows": rows,
        "as_float32": 2 * values * 4 * rows,
        "as_uint8_stacks": 2 * values * rows,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--transitions", type=int, default=100_000)
    parser.add_argument("--quick", action="store_true", help="1,000 transitions")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    transitions = 1_000 if args.quick else args.transitions
    if args.child:
        shape, stack = json.loads(args.child)
        print(json.dumps(measure(shape, stack, transitions)))
        return 0
    scale = 100_000 / transitions
    print(f"replay memory per 100,000 transitions (measured at {transitions:,}; MB = 10^6 bytes)")
    print(
        f"{'observation':30} {'variables':>10} {'of which frames':>16} {'RSS growth':>11} {'s,s′ float32':>13} "
        f"{'s,s′ uint8 stacks':>18}"
    )
    for name, (shape, stack) in KINDS.items():
        done = subprocess.run(
            [sys.executable, __file__, "--transitions", str(transitions), "--child", json.dumps([list(shape), stack])],
            capture_output=True,
            text=True,
            check=True,
        )
        m = json.loads(done.stdout.strip().splitlines()[-1])
        mb = lambda b: f"{b * scale / 1e6:,.1f}"
        print(
            f"{name:30} {mb(m['total']):>10} {mb(m['variables'].get('frame pool', 0)):>16} "
            f"{mb(m['rss_growth']):>11} {mb(m['as_float32']):>13} {mb(m['as_uint8_stacks']):>18}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
