"""Run the two sides of a benchmark (ours, SB3) interleaved, each in its own process, and summarise.

A benchmark script calls `main(...)` with a function per side. The parent imports neither
TensorFlow nor torch: for round r = 1..R it starts `sys.executable <script> <its args> --side S`
once per side, ours first in odd rounds and SB3 first in even ones (drift on a shared machine
then falls on both sides alike). A child runs one side, prints its figures as one JSON line and
exits, so TensorFlow and torch never share a process (the SB3 child also keeps out the TensorFlow
that SB3's tensorboard import would load) and every child starts from the same state and the
same thread settings (`THREAD_ENV`; the SB3 side also calls `torch.set_num_threads(1)`).
The parent reports, per side and figure, the median, min and max over rounds; each ratio
ours ÷ SB3 is computed per round (the two sides of one round are paired) and summarised the same
way. It also reports the versions that ran, the commit (and whether the package has uncommitted
edits), the CPU count, the load average at start and end and the thread settings. Without SB3
(or torch) installed, the SB3 side and the ratios are None and the benchmark still succeeds.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import importlib.util
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from collections.abc import Callable

SIDES = ("ours", "sb3")
THREAD_ENV = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "DQFD_TF_THREADS": "1"}
"""Set in every child's environment, so both sides run on one thread per process."""

VERSIONS = {
    "tensorflow": "tensorflow",
    "keras": "keras",
    "torch": "torch",
    "stable-baselines3": "stable_baselines3",
    "gymnasium": "gymnasium",
    "numpy": "numpy",
}
"""Reported name -> import name (the distribution may differ, e.g. tensorflow_cpu)."""


# --- pure helpers (no processes) ------------------------------------------------------------------


def order(rounds: int, sides=SIDES) -> list[list[str]]:
    """The sides in the order each round runs them: the first place alternates across rounds."""
    sides = list(sides)
    return [sides if r % 2 == 0 else sides[::-1] for r in range(rounds)] if len(sides) > 1 else [sides] * rounds


def spread(values: list[float], digits: int) -> dict:
    """Median, min, max and the values themselves (rounded to `digits`; the median of the rounded values)."""
    values = [round(float(v), digits) for v in values]
    return {
        "median": round(statistics.median(values), digits),
        "min": min(values),
        "max": max(values),
        "per_round": values,
    }


def summarise(
    per_round: dict[str, list[dict] | None], ratios: dict[str, tuple[str, str]], digits: int = 3, ratio_digits: int = 4
) -> dict:
    """`per_round[side]`: one dict of figures per round (or None for an absent side).

    `ratios`: name -> (figure of ours, figure of SB3); each is ours ÷ SB3 within one round, then
    summarised over rounds. Returns {"sides": {side: {figure: spread}}, "ratios": {name: spread}}."""
    sides = {}
    for side, rounds in per_round.items():
        if rounds is None:
            sides[side] = None
            continue
        sides[side] = {figure: spread([r[figure] for r in rounds], digits) for figure in rounds[0]}
    out_ratios = {}
    for name, (ours_figure, sb3_figure) in ratios.items():
        ours, sb3 = per_round.get("ours"), per_round.get("sb3")
        if ours is None or sb3 is None:
            out_ratios[name] = None
            continue
        paired = [a[ours_figure] / b[sb3_figure] for a, b in zip(ours, sb3, strict=True)]
        out_ratios[name] = {"of": f"ours {ours_figure} / sb3 {sb3_figure}", **spread(paired, ratio_digits)}
    return {"sides": sides, "ratios": out_ratios}


# --- environment ----------------------------------------------------------------------------------


def versions() -> dict[str, str | None]:
    """Installed versions, read from package metadata: nothing is imported."""
    found = {"python": platform.python_version()}
    dists = importlib.metadata.packages_distributions()
    for name, module in VERSIONS.items():
        found[name] = None
        for dist in dists.get(module, [module]):
            try:
                version = importlib.metadata.version(dist)
            except importlib.metadata.PackageNotFoundError:
                continue
            plain = dist.lower().replace("-", "_") == module
            found[name] = version if plain else f"{version} ({dist})"
            break
    return found


def sb3_installed() -> bool:
    """SB3 and torch importable (checked without importing them)."""
    return all(importlib.util.find_spec(m) is not None for m in ("stable_baselines3", "torch", "gymnasium"))


def code(script: str) -> dict:
    """The commit measured and whether the package differs from it (uncommitted edits change our figures)."""
    repo = os.path.dirname(os.path.dirname(os.path.abspath(script)))
    try:
        commit = subprocess.run(
            ["git", "-C", repo, "rev-parse", "--short", "HEAD"], capture_output=True, text=True, timeout=30
        )
        status = subprocess.run(
            ["git", "-C", repo, "status", "--porcelain", "--", "dqfd_bc_keras"],
            capture_output=True,
            text=True,
            timeout=30,
        )
    except (OSError, subprocess.SubprocessError):
        return {"commit": None, "package_modified": None}
    if commit.returncode != 0:
        return {"commit": None, "package_modified": None}
    return {"commit": commit.stdout.strip(), "package_modified": bool(status.stdout.strip())}


def in_process() -> dict:
    """What this (child) process loaded and its thread pools: TensorFlow and torch must not meet."""
    info = {
        "tensorflow_imported": sys.modules.get("tensorflow") is not None,
        "torch_imported": sys.modules.get("torch") is not None,
    }
    if info["tensorflow_imported"]:
        from dqfd_bc_keras import runtime

        info["tf_intra_op_threads"], info["tf_inter_op_threads"] = runtime.tensorflow_threads()
    if info["torch_imported"]:
        import torch

        info["torch_threads"] = torch.get_num_threads()
    return info


def child_env() -> dict[str, str]:
    return {**os.environ, **THREAD_ENV}


def run_side(script: str, argv: list[str], side: str, round_no: int) -> dict:
    """One side in a fresh process: {"figures": its figures or None (absent), "process": `in_process()`}."""
    command = [sys.executable, script, *argv, "--side", side]
    done = subprocess.run(command, capture_output=True, text=True, env=child_env())
    lines = [line for line in done.stdout.splitlines() if line.strip()]
    if done.returncode != 0 or not lines:
        errors = [line.strip() for line in done.stderr.splitlines() if line.strip()]
        last = errors[-1] if errors else "(no stderr)"
        sys.exit(
            f"{os.path.basename(script)}: the {side} side failed in round {round_no} (exit {done.returncode}): {last}"
        )
    try:
        return json.loads(lines[-1])
    except json.JSONDecodeError:
        sys.exit(f"{os.path.basename(script)}: the {side} side printed no JSON in round {round_no}: {lines[-1][:200]}")


# --- the entry point the scripts share ---------------------------------------------------------------


def add_arguments(parser: argparse.ArgumentParser, rounds: int = 3) -> None:
    parser.add_argument(
        "--rounds",
        type=int,
        default=rounds,
        help="rounds; each runs every side once, in its own process (default %(default)s)",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object (the last stdout line)")
    parser.add_argument(
        "--quick",
        action="store_true",
        help="a tiny budget and one or two rounds: checks that the benchmark runs (CI), its figures mean nothing",
    )
    parser.add_argument("--side", choices=SIDES, help=argparse.SUPPRESS)  # a child: run one side, print JSON


def run_child(side: str, sides: dict[str, Callable[[], dict | None]]) -> int:
    """The child's job: measure `side` in this process, print its figures as one JSON line."""
    if side == "sb3":
        # SB3's logger imports tensorboard, which imports TensorFlow when it is installed: keep it
        # out (tensorboard falls back to its stub), so TensorFlow and torch never share a process.
        sys.modules.setdefault("tensorflow", None)
    else:
        from dqfd_bc_keras import runtime

        runtime.configure()  # as the command lines do, before the side loads TensorFlow
    print(json.dumps({"figures": sides[side](), "process": in_process()}))
    return 0


def run_rounds(
    script: str, argv: list[str], plan: list[list[str]], verbose: bool
) -> tuple[dict[str, list[dict] | None], dict[str, dict]]:
    """Each round's sides in their own processes, in the planned order: figures per side and round
    (None for a side that measured nothing), and each side's first process description."""
    per_round: dict[str, list[dict] | None] = {side: [] for side in SIDES}
    processes: dict[str, dict] = {}
    for r, sides_in_round in enumerate(plan, start=1):
        for side in sides_in_round:
            child = run_side(script, argv, side, r)
            figures = child["figures"]
            processes.setdefault(side, child["process"])
            if figures is None:
                per_round[side] = None
            elif per_round[side] is not None:
                per_round[side].append(figures)
            if verbose and figures is not None:
                print(f"  round {r} {side:4s} " + "  ".join(f"{k} {v:.1f}" for k, v in figures.items()), flush=True)
    return per_round, processes


def main(
    name: str,
    script: str,
    argv: list[str],
    args: argparse.Namespace,
    sides: dict[str, Callable[[], dict | None]],
    ratios: dict[str, tuple[str, str]],
    settings: dict,
    describe: Callable[[dict], list[str]] | None = None,
) -> int:
    """Run as a child (`--side`) or as the parent that interleaves the children.

    `sides[side]()` measures one side in this process and returns its figures (or None: absent).
    `ratios` as in `summarise`; the first one is the headline `ratio`."""
    if args.side is not None:
        return run_child(args.side, sides)
    if args.rounds < 1:
        sys.exit(f"{name}: --rounds must be ≥ 1")
    present = [side for side in SIDES if side != "sb3" or sb3_installed()]
    load_start, start = os.getloadavg(), time.perf_counter()
    plan = order(args.rounds, present)
    if not args.json:
        print(
            f"{name}: {args.rounds} rounds, each side in its own process, order per round: "
            + "; ".join(",".join(sides_) for sides_ in plan),
            flush=True,
        )
    per_round, processes = run_rounds(script, argv, plan, verbose=not args.json)
    for side in SIDES:
        if side not in present or not per_round[side]:
            per_round[side] = None
    summary = summarise(per_round, ratios)
    headline = next(iter(ratios))
    report = {
        "benchmark": name,
        "rounds": args.rounds,
        "order": plan,
        "settings": settings,
        "sides": summary["sides"],
        "ratio": summary["ratios"][headline],
        "ratios": summary["ratios"],
        "versions": versions(),
        "code": code(script),
        "machine": {
            "cpu_count": os.cpu_count(),
            "loadavg_start": [round(x, 2) for x in load_start],
            "loadavg_end": [round(x, 2) for x in os.getloadavg()],
            "threads": dict(THREAD_ENV),
            "processes": processes,
        },
        "seconds": round(time.perf_counter() - start, 1),
    }
    if args.json:
        print(json.dumps(report))
    else:
        print(table(report))
        for line in describe(report) if describe else []:
            print(line)
    return 0


def table(report: dict) -> str:
    """The report as readable lines."""
    lines = [f"{'':5s} {'figure':34s} {'median':>9s} {'min':>9s} {'max':>9s}"]
    for side, figures in report["sides"].items():
        if figures is None:
            lines.append(f"{side:5s} absent (SB3: pip install -r benchmarks/requirements.txt)")
            continue
        for figure, s in figures.items():
            lines.append(f"{side:5s} {figure:34s} {s['median']:9.1f} {s['min']:9.1f} {s['max']:9.1f}")
    for name, s in report["ratios"].items():
        if s is None:
            lines.append(f"ratio {name:34s} None (no SB3 side)")
        else:
            lines.append(
                f"ratio {name:34s} {s['median']:8.2f}x {s['min']:8.2f}x {s['max']:8.2f}x   "
                f"(per round: {', '.join(f'{v:.2f}' for v in s['per_round'])})"
            )
    m = report["machine"]
    lines.append(
        "versions: "
        + ", ".join(f"{k} {v}" for k, v in report["versions"].items())
        + f"; commit {report['code']['commit']}"
        + (" with uncommitted package edits" if report["code"]["package_modified"] else "")
    )
    lines.append(
        f"machine: {m['cpu_count']} CPUs, load average {m['loadavg_start'][0]:.2f} at start, "
        f"{m['loadavg_end'][0]:.2f} at end; "
        + " ".join(f"{k}={v}" for k, v in m["threads"].items())
        + f"; {report['seconds']:.0f} s"
    )
    return "\n".join(lines)
