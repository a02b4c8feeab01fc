"""What a person is told at `demos play`: the controls in `--help`, the keys by their names on the
keyboard (in the window and with `--list-keys`), the episodes counted on from the file `--append`
continues, and what is refused in one line before the window opens (an `--out` that could not be
written, a video driver with no display), so that nothing played is lost."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from helpers import call

from dqfd_bc_keras import demos
from dqfd_bc_keras.demos.human import CONTROLS_TEXT
from dqfd_bc_keras.demos.window import Window


def test_help_says_every_control_and_how_to_see_a_tasks_keys():
    answer = call("dqfd_bc_keras.demos", "play", "--help")
    assert answer.returncode == 0
    for said in (
        "Enter (or an action key)  start an episode",
        "P                         pause, and go on",
        "Backspace                 discard the episode in play",
        "Esc, or close the window  quit",
        "--list-keys prints them with the pace",
    ):
        assert said in answer.stdout, said


@pytest.mark.parametrize(
    ("flags", "keys"),
    [
        (["--task", "minatar-breakout"], "no key = NOOP · Left arrow = LEFT · Right arrow = RIGHT (from preset"),
        (["--task", "cartpole"], "Left arrow = action 0 · Right arrow = action 1 · no key = the last action"),
        (["--env", "MinAtar/Seaquest-v1", "--max-steps", "100"], "Down arrow = DOWN · Space = FIRE (from preset"),
        (["--task", "cartpole", "--keys", '{"up+space": 1, "a": 0}'], "Up arrow + Space = action 1 · A = action 0"),
    ],
)
def test_list_keys_names_the_keys_as_the_keyboard_does(flags, keys, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)  # no window is opened
    answer = call("dqfd_bc_keras.demos", "play", *flags, "--list-keys")
    assert answer.returncode == 0, answer.stderr
    lines = answer.stdout.splitlines()
    assert lines[0].startswith("keys: ") and keys in lines[0]
    assert lines[1].startswith("pace: ") and lines[2] == CONTROLS_TEXT  # the window's own lines


def test_python_is_told_what_list_keys_prints(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    answer = call("dqfd_bc_keras.demos", "play", "--env", "CartPole-v1", "--fps", "12", "--list-keys")
    assert answer.stdout.splitlines() == demos.controls("CartPole-v1", fps=12)
    assert demos.controls("CartPole-v1", fps=12)[1] == "pace: 12 steps/s (--fps changes it)"


def test_play_without_out_says_it_is_needed():
    answer = call("dqfd_bc_keras.demos", "play", "--task", "cartpole")
    assert answer.returncode == 2 and "--out is required (the file to write), unless --list-keys" in answer.stderr


@pytest.fixture
def person(monkeypatch) -> list[list[str]]:
    """A person at a window under SDL's headless driver who taps Right between every two frames
    (pygame's events, posted: each tap starts an episode and pushes); returns the lines of every screen drawn."""
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    monkeypatch.setenv("SDL_AUDIODRIVER", "dummy")
    screens: list[list[str]] = []
    poll, draw = Window.poll, Window.draw

    def press(window: Window):
        for kind in (window.pg.KEYDOWN, window.pg.KEYUP):
            window.pg.event.post(window.pg.event.Event(kind, key=window.pg.K_RIGHT, mod=0))
        return poll(window)

    def look(window: Window, frame, lines):
        screens.append(list(lines))
        draw(window, frame, lines)

    monkeypatch.setattr(Window, "poll", press)
    monkeypatch.setattr(Window, "draw", look)
    return screens


def test_append_counts_the_files_episodes_from_its_first_screen(person, tmp_path):
    out, reported = tmp_path / "mine.npz", []
    demos.play("minatar-breakout", out, episodes=1, max_steps=4, fps=1000, report=None)
    first_session = len(person)
    assert "episode 1 of 1 (seed 0) · 0 saved in mine.npz" in person[0][0]
    assert person[0][3] == "keys: no key = NOOP · Left arrow = LEFT · Right arrow = RIGHT"

    played = demos.play("minatar-breakout", out, episodes=2, max_steps=4, fps=1000, append=True, report=reported.append)
    assert played.n_episodes == 3 and played.meta.episode_seeds == [0, 1, 2]
    assert "episode 2 of 3 (seed 1) · 1 saved in mine.npz" in person[first_session][0]  # before anything is played
    assert "episode 3 of 3 (seed 2) · 2 saved in mine.npz" in person[-1][0]
    assert [line.split(":")[0] for line in reported] == ["episode 2 of 3 (seed 1)", "episode 3 of 3 (seed 2)"]
    assert reported[-1].endswith("holds 3 episode(s)")


@pytest.mark.parametrize(
    ("out", "says"),
    [
        ("a-file/mine.npz", "a-file/mine.npz: a-file is a file, not a folder"),
        ("a-file/deeper/mine.npz", "a-file/deeper/mine.npz: a-file is a file, not a folder"),
        ("a-folder", None),  # not an .npz: refused by name
        ("a-folder.npz", "a-folder.npz: is a directory, not a file"),
    ],
)
def test_an_out_that_cannot_be_written_is_refused_before_the_window_opens(out, says, tmp_path, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)  # were the window opened first, it would say there is no display
    (tmp_path / "a-file").write_text("the user's")
    (tmp_path / "a-folder").mkdir()
    (tmp_path / "a-folder.npz").mkdir()
    answer = call("dqfd_bc_keras.demos", "play", "--task", "cartpole", "--out", out, cwd=tmp_path)
    assert answer.returncode == 2 and answer.stderr.count("\n") == 1, answer.stderr
    assert (says or "--out must be an .npz file") in answer.stderr
    assert (tmp_path / "a-file").read_text() == "the user's"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a-file", "a-folder", "a-folder.npz"]  # nothing left behind


def test_a_folder_without_write_permission_is_refused_before_the_window_opens(tmp_path, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o555)
    if os.geteuid() == 0:  # root writes into any folder but Linux's sysfs, which takes no new file
        locked = Path("/sys")
        if not locked.is_dir():
            pytest.skip("running as root, without /sys: no folder refuses a file")
    answer = call("dqfd_bc_keras.demos", "play", "--task", "cartpole", "--out", locked / "mine.npz")
    assert answer.returncode == 2 and answer.stderr == f"error: {locked / 'mine.npz'}: Permission denied\n"


@pytest.mark.parametrize("driver", ["x11", "wayland"])
@pytest.mark.parametrize("command", ["play", "show"])
def test_a_video_driver_with_no_display_is_one_line(command, driver, tmp_path, monkeypatch):
    monkeypatch.setenv("SDL_VIDEODRIVER", driver)
    for name in ("DISPLAY", "WAYLAND_DISPLAY"):
        monkeypatch.delenv(name, raising=False)
    path = tmp_path / "d.npz"
    demos.save(demos.record("cartpole", "imperfect", episodes=1, max_steps=20), path)
    args = ["--task", "cartpole", "--out", tmp_path / "new.npz"] if command == "play" else [path]
    answer = call("dqfd_bc_keras.demos", command, *args)
    assert answer.returncode == 2 and answer.stderr.count("\n") == 1, answer.stderr
    assert f"cannot open a window (no display: SDL_VIDEODRIVER={driver} says '{driver} not available')" in answer.stderr
    assert "xvfb-run" in answer.stderr and not (tmp_path / "new.npz").exists()
