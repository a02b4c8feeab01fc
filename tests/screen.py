"""A virtual X screen (Xvfb), real key presses on it (xdotool) and its pixels (Pillow's ImageGrab):
how the tests of `demos play` and `demos show` and docs/play_screenshot.py use the window as a
person would. Light: imports neither TensorFlow nor the package. Debian's xvfb and xdotool;
`.ci/run` installs them where they are missing."""

from __future__ import annotations

import contextlib
import os
import shutil
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


@contextlib.contextmanager
def virtual_screen(size: str = "1024x768") -> Iterator[dict[str, str]]:
    """A screen of its own (Xvfb picks a free display number); yields the environment a command
    needs to open its window there."""
    missing = [tool for tool in ("Xvfb", "xdotool") if shutil.which(tool) is None]
    if missing:
        raise RuntimeError(f"{missing} not installed: apt-get install xvfb xdotool (as .ci/run does)")
    read, write = os.pipe()
    # -noreset: by default the server resets when its last client leaves (the window of a killed
    # `play`, an xdotool call ending), and a client connecting meanwhile is refused ("Can't open display").
    server = subprocess.Popen(
        ["Xvfb", "-displayfd", str(write), "-screen", "0", f"{size}x24", "-nolisten", "tcp", "-noreset"],
        pass_fds=(write,),
        stderr=subprocess.DEVNULL,
    )
    os.close(write)
    with os.fdopen(read) as answer:
        display = f":{answer.readline().strip()}"
    env = {**os.environ, "DISPLAY": display, "SDL_AUDIODRIVER": "dummy", "PYTHONPATH": str(REPO)}
    env.pop("SDL_VIDEODRIVER", None)
    try:
        yield env
    finally:
        server.terminate()
        server.wait()


def xdotool(env: dict[str, str], *args: str, check: bool = True) -> str:
    """What `xdotool ARGS` printed on the screen of `env`; with `check`, its failure is an error naming it."""
    done = subprocess.run(["xdotool", *args], env=env, capture_output=True, text=True, timeout=30)
    if check and done.returncode != 0:
        raise RuntimeError(f"xdotool {' '.join(args)}: {done.stderr.strip()}")
    return done.stdout


def focus(env: dict[str, str], process: subprocess.Popen, timeout: float = 60.0) -> str:
    """The id of `process`'s window once it is shown, given the keyboard (with no window manager,
    nothing else gives it); a `RuntimeError` with the process's stderr if it shows none."""
    deadline = time.monotonic() + timeout
    while process.poll() is None and time.monotonic() < deadline:
        for window in xdotool(env, "search", "--onlyvisible", "--pid", str(process.pid), check=False).split():
            xdotool(env, "windowfocus", window, check=False)
            if xdotool(env, "getwindowfocus", check=False).strip() == window:
                return window
        time.sleep(0.1)
    process.kill()
    _, stderr = process.communicate()
    raise RuntimeError(f"no window was shown: {stderr or '(nothing on stderr)'}")


def launch(env: dict[str, str], *args: object) -> tuple[subprocess.Popen, str]:
    """`python -m dqfd_bc_keras.demos ARGS` on the screen of `env`, once its window is shown and has
    the keyboard: the process (its output piped, as text) and its window's id."""
    process = subprocess.Popen(
        [sys.executable, "-m", "dqfd_bc_keras.demos", *map(str, args)],
        env=env,
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    return process, focus(env, process)


def grab(env: dict[str, str], window: str):  # -> PIL.Image.Image (Pillow imported only here)
    """What `window` shows on the screen of `env`, as a person sees it (with no window manager the
    window's geometry is its content)."""
    from PIL import ImageGrab

    geometry = dict(line.split("=") for line in xdotool(env, "getwindowgeometry", "--shell", window).split())
    x, y, w, h = (int(geometry[k]) for k in ("X", "Y", "WIDTH", "HEIGHT"))
    return ImageGrab.grab(bbox=(x, y, x + w, y + h), xdisplay=env["DISPLAY"])
