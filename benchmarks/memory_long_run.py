"""Resident memory over a long MountainCar run: does anything grow with the step count?

    python benchmarks/memory_long_run.py                 # 1,000,000 steps (~45 min on one core)
    python benchmarks/memory_long_run.py --quick         # 5,000 steps, for the tests

Runs `train.py --task mountaincar` in a child process and samples its resident set size
(/proc/PID/status, VmRSS) every few seconds beside the env step the run has logged. Prints the
median and peak RSS over each tenth of the budget and the ratio of the last tenth's median to
the second's (the goal: within 10%). `--json FILE` keeps the samples, `--samples FILE`
summarises them again. Linux only (it reads /proc).
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def rss_mb(pid: int) -> float | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except OSError:
        return None
    return None


def last_env_step(metrics: Path) -> int:
    """The env step of the last logged episode (reads only the file's tail)."""
    try:
        with metrics.open("rb") as f:
            f.seek(0, 2)
            f.seek(max(0, f.tell() - 400))
            line = f.read().decode(errors="replace").strip().splitlines()[-1]
        return int(line.split(",")[1])
    except (OSError, IndexError, ValueError):
        return 0


def measure(steps: int, every: float) -> list[tuple[int, float]]:
    """(env step, RSS in MB) samples of one run of `steps` env steps."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run"
        process = subprocess.Popen(
            [
                sys.executable,
                str(REPO / "train.py"),
                "--task",
                "mountaincar",
                "--steps",
                str(steps),
                "--quiet",
                "--set",
                f"checkpoint_every={max(steps // 10, 1000)}",
                "--set",
                f"eval_every={max(steps // 10, 1000)}",
                "--out",
                str(out),
            ],
            cwd=REPO,
        )
        samples = []
        while process.poll() is None:
            rss = rss_mb(process.pid)
            if rss is not None:
                samples.append((last_env_step(out / "metrics.csv"), rss))
            time.sleep(every)
        if process.returncode != 0:
            raise SystemExit(f"train.py exited with {process.returncode}")
    return samples


def summarise(steps: int, samples: list[tuple[int, float]]) -> list[str]:
    """The curve per tenth of the budget: median and peak RSS (checkpoint saves make short peaks),
    and the median of the last tenth ÷ the median of the second (from 10% of the budget on)."""
    lines = [
        f"MountainCar, {steps:,} env steps: resident memory (MB) per tenth of the budget",
        "  env steps               median    peak",
    ]
    tenths: dict[int, list[float]] = {}
    for step, rss in samples:
        tenths.setdefault(min(9, step * 10 // steps), []).append(rss)
    for tenth, values in sorted(tenths.items()):
        lines.append(
            f"  {tenth * steps // 10:>9,}–{(tenth + 1) * steps // 10:<9,}  {statistics.median(values):7.0f} "
            f"{max(values):7.0f}"
        )
    if 1 in tenths and 9 in tenths:
        ratio = statistics.median(tenths[9]) / statistics.median(tenths[1])
        lines.append(
            f"RSS over the last tenth ÷ RSS over {steps // 10:,}–{2 * steps // 10:,} steps (medians): {ratio:.3f}"
        )
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1_000_000)
    parser.add_argument("--every", type=float, default=5.0, help="seconds between samples")
    parser.add_argument("--quick", action="store_true", help="5,000 steps, a sample every 0.1 s")
    parser.add_argument("--json", help="also write the samples to this file")
    parser.add_argument("--samples", help="summarise the samples saved by an earlier --json instead of running")
    args = parser.parse_args(argv)
    if args.samples:
        saved = json.loads(Path(args.samples).read_text())
        steps, samples = saved["steps"], saved["samples"]
    else:
        steps, every = (5_000, 0.1) if args.quick else (args.steps, args.every)
        samples = measure(steps, every)
    print("\n".join(summarise(steps, samples)))
    if args.json:
        Path(args.json).write_text(json.dumps({"steps": steps, "samples": samples}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
