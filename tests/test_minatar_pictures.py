"""What a person sees of MinAtar: each cell in MinAtar's own colours (its GUI's cubehelix palette,
black where no channel is on), 48 pixels a side. Checked by the pixels a person gets: a screenshot
of the play window on a virtual screen (Xvfb) played with real key presses, one of `demos show`'s
window, and the frames of the videos `demos show --video` and `evaluate.py --video` write, read back."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
from helpers import REPO, call
from screen import grab, launch, virtual_screen, xdotool

from dqfd_bc_keras import demos
from dqfd_bc_keras.envs.make import make_plain_env, make_task
from dqfd_bc_keras.envs.minatar_pixels import CELL, palette, pixels
from dqfd_bc_keras.seeds import EVAL_SEED
from dqfd_bc_keras.tasks import TASKS

pytest.importorskip("minatar")
CHANNELS = {
    "minatar-breakout": 4,
    "minatar-freeway": 7,
    "minatar-asterix": 4,
    "minatar-seaquest": 10,
    "minatar-space-invaders": 6,
}
GAME = slice(0, 10 * CELL), slice(60, 60 + 10 * CELL)
"""Where the play window draws a MinAtar frame: 480×480 at the top, centred in the 600-pixel-wide window."""


def test_the_palette_is_minatars_cubehelix_black_first():
    """seaborn's `color_palette("cubehelix", n)`, which MinAtar draws with, is matplotlib's `cubehelix`
    colormap at n evenly spaced points inside (0, 1); computed without either."""
    from matplotlib import colormaps

    for n in set(CHANNELS.values()):
        expected = colormaps["cubehelix"](np.linspace(0, 1, n + 2)[1:-1])[:, :3]
        assert palette(n).dtype == np.uint8 and palette(n).shape == (n + 1, 3)
        np.testing.assert_array_equal(palette(n)[0], [0, 0, 0])
        np.testing.assert_array_equal(palette(n)[1:], np.round(expected * 255))
        assert len({tuple(c) for c in palette(n)}) == n + 1  # every channel its own colour
    assert palette(4)[1:].tolist() == [[22, 61, 78], [84, 121, 47], [208, 126, 147], [193, 202, 243]]  # Breakout's


def test_a_cell_takes_the_colour_of_its_last_channel_on_scaled_by_whole_cells():
    state = np.zeros((10, 10, 4), bool)
    state[9, 2, 0] = True  # the paddle alone
    state[3, 5, 1] = state[3, 5, 3] = True  # the ball on a brick: the brick's colour, as MinAtar draws it
    image = pixels(state)
    assert image.shape == (480, 480, 3) and image.dtype == np.uint8
    cells = image.reshape(10, CELL, 10, CELL, 3)
    assert (cells == cells[:, :1, :, :1]).all()  # every cell one colour
    np.testing.assert_array_equal(cells[9, 0, 2, 0], palette(4)[1])
    np.testing.assert_array_equal(cells[3, 0, 5, 0], palette(4)[4])
    assert (cells[:, 0, :, 0].any(-1)).sum() == 2  # black elsewhere


@pytest.mark.parametrize("task", sorted(CHANNELS))
def test_each_games_frame_is_minatars_own_picture_scaled_up(task):
    """The task env's frame, cell by cell, is MinAtar's own `rgb_array` (its floats in [0, 1] as bytes)."""
    pytest.importorskip("seaborn")  # MinAtar's own rgb_array needs it; ours does not
    env = make_task(task, render_mode="rgb_array")
    obs, _ = env.reset(seed=3)
    expert = TASKS[task].experts["strong"]
    for _ in range(30):
        obs, *_ = env.step(expert(obs))
    frame, theirs = env.render(), env.unwrapped.render()
    env.close()
    assert frame.shape == (480, 480, 3) and frame.dtype == np.uint8 and theirs.shape == (10, 10, 3)
    np.testing.assert_array_equal(frame[::CELL, ::CELL], np.round(theirs * 255))
    assert frame.any() and len(np.unique(frame.reshape(-1, 3), axis=0)) >= 3  # lit: black and two colours or more


def frames_of(dataset: demos.DemoDataset) -> list[np.ndarray]:
    """Every state an episode of `dataset` passed through, as MinAtar draws it."""
    shape = dataset.meta.obs_shape
    states = [o.reshape(shape) for o in dataset.obs] + [o.reshape(shape) for o in dataset.next_obs]
    return [pixels(np.asarray(s, bool)) for s in states]


def assert_shows_a_frame(image: np.ndarray, dataset: demos.DemoDataset) -> None:
    """The window's game area is, pixel for pixel, one of the recorded states in MinAtar's colours."""
    game = image[GAME]
    colours = {tuple(c) for c in np.unique(game.reshape(-1, 3), axis=0)}
    n = dataset.meta.obs_shape[-1]
    assert colours <= {tuple(c) for c in palette(n)} and len(colours) >= 3, colours  # lit, in MinAtar's colours
    assert any(np.array_equal(game, frame) for frame in frames_of(dataset))


@pytest.mark.slow
def test_a_person_plays_breakout_and_sees_it_in_minatars_colours(tmp_path):
    """The acceptance: Breakout played in a real window with real key presses; the screenshot taken
    while paused shows one of the states the file recorded, cell for cell in MinAtar's colours."""
    out = tmp_path / "breakout.npz"
    with virtual_screen() as screen:
        process, window = launch(screen, "play", "--task", "minatar-breakout", "--episodes", 1, "--out", out)
        xdotool(screen, "keydown", "Left")  # starts the episode; the paddle goes left, the ball is lost
        time.sleep(0.6)
        xdotool(screen, "key", "p")
        time.sleep(0.5)  # paused: the frame stays
        image = np.asarray(grab(screen, window).convert("RGB"))
        xdotool(screen, "key", "p")
        _, stderr = process.communicate(timeout=120)
        xdotool(screen, "keyup", "Left")
    assert process.returncode == 0, stderr
    assert image.shape[:2] == (606, 600)  # the 480-pixel frame and five lines of text
    assert_shows_a_frame(image, demos.load(out))


@pytest.mark.slow
def test_demos_show_draws_the_replay_in_minatars_colours(tmp_path):
    path = tmp_path / "d.npz"
    assert call("dqfd_bc_keras.demos", "record", "--task", "minatar-freeway", "--expert", "strong",
                "--episodes", 1, "--max-steps", 40, "--out", path).returncode == 0  # fmt: skip
    with virtual_screen() as screen:
        process, window = launch(screen, "show", path)
        time.sleep(1.0)  # a few steps in, at the preset's 8 steps/s
        xdotool(screen, "key", "p")
        time.sleep(0.5)
        image = np.asarray(grab(screen, window).convert("RGB"))
        xdotool(screen, "key", "Escape")
        _, stderr = process.communicate(timeout=60)
    assert process.returncode == 0, stderr
    assert_shows_a_frame(image, demos.load(path))


def video_frames(path: Path) -> tuple[np.ndarray, float]:
    """An MP4's frames as read back (ffmpeg, as moviepy wrote it) and its frame rate."""
    import imageio.v3 as iio

    return iio.imread(path), float(iio.immeta(path)["fps"])


def assert_close(frame: np.ndarray, expected: np.ndarray) -> None:
    """A decoded video frame is `expected` up to the codec's loss (a few levels; 48-pixel cells keep their colour)."""
    error = np.abs(frame.astype(int) - expected.astype(int))
    assert error.mean() < 3 and error.max() < 40, (error.mean(), error.max())


def test_show_video_holds_each_state_in_minatars_colours(tmp_path):
    path = tmp_path / "d.npz"
    assert call("dqfd_bc_keras.demos", "record", "--task", "minatar-breakout", "--expert", "strong",
                "--episodes", 1, "--max-steps", 30, "--out", path).returncode == 0  # fmt: skip
    answer = call("dqfd_bc_keras.demos", "show", path, "--video", tmp_path / "videos")
    assert answer.returncode == 0, answer.stderr
    (video,) = (tmp_path / "videos").glob("*.mp4")
    frames, fps = video_frames(video)
    dataset = demos.load(path)
    pictures = frames_of(dataset)
    expected = [pictures[0], *pictures[len(dataset) :]]  # the reset's state, then each step's
    assert frames.shape == (len(dataset) + 1, 480, 480, 3) and fps == TASKS["minatar-breakout"].fps
    for frame, picture in zip(frames, expected, strict=True):
        assert_close(frame, picture)


@pytest.mark.slow
def test_evaluate_video_shows_the_model_playing_in_minatars_colours(tmp_path):
    answer = call("evaluate.py", REPO / "models" / "minatar-breakout", "--episodes", 1, "--video", tmp_path / "videos")
    assert answer.returncode == 0, answer.stderr
    (video,) = (tmp_path / "videos").glob("*.mp4")
    frames, fps = video_frames(video)
    env = make_plain_env("minatar-breakout")
    obs, _ = env.reset(seed=EVAL_SEED)  # the first episode's reset
    env.close()
    assert frames.shape[1:] == (480, 480, 3) and len(frames) > 1 and fps == TASKS["minatar-breakout"].fps
    assert_close(frames[0], pixels(obs))
    lit = [len(np.unique(f.reshape(-1, 3) // 32, axis=0)) for f in frames]
    assert min(lit) >= 3  # no black frame: black, the bricks, the paddle (and the ball) in every one
