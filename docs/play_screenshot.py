"""The screenshot of `demos play` in docs/DEMONSTRATIONS.md, taken as a person would see it.

    .venv/bin/python docs/play_screenshot.py --out docs/figures/play_window.png [--task cartpole]
    .venv/bin/python docs/play_screenshot.py --out freeway.png --task minatar-freeway --press Up,Up,Down

Starts a virtual screen (Xvfb), runs `python -m dqfd_bc_keras.demos play` on it, plays with
real key presses (xdotool: `--press`, by default Left, then Right, then Left, each held for a
moment), grabs the window's pixels from the screen mid-episode (Pillow's ImageGrab), then quits
with Escape; what was recorded goes with its scratch directory. Needs Debian's xvfb and xdotool
(`.ci/run` installs them).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(REPO), str(REPO / "tests")]

from screen import focus, grab, virtual_screen, xdotool  # noqa: E402  (after the path: run as a script)

from dqfd_bc_keras.files import atomic_path  # noqa: E402


def screenshot(task: str, out: Path, hold: float, keys: list[str]) -> tuple[int, int]:
    """Play `task` on a virtual screen pressing `keys` (X's key names) in turn, grab the window into
    `out`; returns its size."""
    with virtual_screen("1024x900") as env, tempfile.TemporaryDirectory() as scratch:
        play = subprocess.Popen(
            [sys.executable, "-m", "dqfd_bc_keras.demos", "play", "--task", task, "--out", f"{scratch}/d.npz"],
            env=env,
            cwd=REPO,
            stdout=subprocess.DEVNULL,
        )
        try:
            window = focus(env, play)
            for key in keys:
                xdotool(env, "keydown", key)
                time.sleep(hold)
                xdotool(env, "keyup", key)
            image = grab(env, window)
            xdotool(env, "key", "Escape")
            play.wait(timeout=60)
        finally:
            play.kill()
    with atomic_path(out) as tmp:
        image.save(tmp, format="PNG")
    return image.size


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, required=True, help="the PNG to write")
    parser.add_argument("--task", default="cartpole")
    parser.add_argument("--hold", type=float, default=0.4, help="seconds each key is held")
    parser.add_argument("--press", default="Left,Right,Left", help="the keys held in turn (X's names: Up, space, …)")
    args = parser.parse_args()
    width, height = screenshot(args.task, args.out, args.hold, args.press.split(","))
    print(f"wrote {args.out} ({width}x{height})")


if __name__ == "__main__":
    main()
