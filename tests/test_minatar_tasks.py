"""The MinAtar presets (tasks/minatar.py): registered, their Gymnasium ids, their experts' play."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.wrappers import TimeLimit

import dqfd_bc_keras.tasks.minatar as minatar_tasks
from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.experiments.lab_settings import lab_settings
from dqfd_bc_keras.tasks import TASKS, find_preset

pytest.importorskip("minatar")
REPO = Path(__file__).resolve().parents[1]
PRESETS = ("minatar-breakout", "minatar-freeway")

# The 100-episode measurement (seeds 0–99, one env, `TimeLimit(max_steps)`): mean, std.
MEASURED = {
    ("minatar-breakout", "strong"): (79.93, 14.36),
    ("minatar-breakout", "imperfect"): (8.58, 9.21),
    ("minatar-freeway", "strong"): (65.85, 1.93),
    ("minatar-freeway", "imperfect"): (15.72, 12.65),
}
EPISODES = {"minatar-breakout": 20, "minatar-freeway": 8}
"""Few enough that the band test takes seconds (Freeway's episodes are 2500 steps)."""
BAND_SE = 4.0
"""A band is the 100-episode mean ± 4 standard errors of an n-episode mean (std/√n): a subset of the
measured seeds misses it with a chance of about 1e-4, a rule that plays differently does not."""


def play(task: str, expert: str, episodes: int) -> np.ndarray:
    """Plain returns of `expert` on seeds 0.. as measured: one env, the preset's limit, uint8 frames."""
    spec = TASKS[task]
    env = TimeLimit(gym.make(spec.env_id), spec.max_steps)
    returns = np.zeros(episodes)
    for seed in range(episodes):
        obs, _ = env.reset(seed=seed)
        done = False
        while not done:
            obs, reward, terminated, truncated, _ = env.step(spec.experts[expert](np.asarray(obs, np.uint8)))
            returns[seed] += float(reward)
            done = terminated or truncated
    env.close()
    return returns


@pytest.mark.parametrize("task", PRESETS)
def test_the_presets_are_registered_with_their_env_and_experts(task: str) -> None:
    spec = find_preset(task)
    assert spec is TASKS[task] and spec.family == task and set(spec.experts) == {"strong", "imperfect"}
    assert spec.fall_penalty is None and spec.goal_reward is None and spec.solved_return is None
    assert find_preset(f"dqfd_bc_keras.tasks.minatar:{task}") is spec
    env = gym.make(spec.env_id)  # the id resolves after the import, without minatar.gym.register_envs()
    assert env.observation_space.shape == (10, 10, {"minatar-breakout": 4, "minatar-freeway": 7}[task])
    assert env.action_space.n == 3  # the minimal action sets: (noop, left, right), (noop, up, down)
    env.close()


def test_the_presets_record_their_teachers_and_stay_out_of_the_vector_suites() -> None:
    for task in PRESETS:  # the MinAtar study is its own suite (its SB3 baseline differs)
        lab = lab_settings(task)
        assert lab.efficiency_demos is None and lab.teacher_return is None
        measured = {(name, 0.0): MEASURED[task, name][0] for name in ("strong", "imperfect")}
        assert lab.grid_teachers == measured


def test_the_ids_are_those_minatar_registers(monkeypatch: pytest.MonkeyPatch) -> None:
    import gymnasium.envs.registration as registration
    import minatar.gym

    ours = {env_id: spec for env_id, spec in gym.registry.items() if env_id.startswith("MinAtar/")}
    monkeypatch.setattr(registration, "registry", {})
    minatar.gym.register_envs()
    theirs = registration.registry
    assert set(ours) == set(theirs) and len(ours) == 10
    for env_id, spec in theirs.items():
        assert (ours[env_id].entry_point, ours[env_id].kwargs) == (spec.entry_point, spec.kwargs)


def test_without_minatar_making_an_env_is_one_line_saying_how_to_install_it(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "minatar", None)  # `import minatar` now raises ImportError
    monkeypatch.setitem(sys.modules, "minatar.gym", None)
    with pytest.raises(ConfigError, match=r"^the MinAtar tasks need the minatar package: pip install minatar$"):
        minatar_tasks.require_minatar()


def test_the_package_imports_without_minatar_and_registers_no_ids() -> None:
    code = (
        "import sys; sys.modules['minatar'] = None; import gymnasium, dqfd_bc_keras.tasks.minatar; "
        "from dqfd_bc_keras.tasks import TASKS; "
        "print('minatar-breakout' in TASKS, any(i.startswith('MinAtar/') for i in gymnasium.registry))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["True", "False"]


def test_require_minatar_without_seaborn_logs_nothing_and_leaves_logging_unconfigured() -> None:
    code = (
        "import sys, logging; sys.modules['seaborn'] = None; import dqfd_bc_keras.tasks.minatar as m; "
        "m.require_minatar(); import minatar.gym; root = logging.getLogger(); "
        "print(root.handlers, logging.getLevelName(root.level))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stderr == "" and done.stdout.split() == ["[]", "WARNING"]


@pytest.mark.parametrize("task", PRESETS)
def test_the_experts_answer_valid_actions_on_played_frames(task: str) -> None:
    spec = TASKS[task]
    env = gym.make(spec.env_id)
    rng = np.random.default_rng(0)
    obs, _ = env.reset(seed=0)
    for step in range(300):  # random play, so that the frames are not only the experts' own
        frame = np.asarray(obs, np.uint8)
        for expert in spec.experts.values():
            action = expert(frame)
            assert isinstance(action, int) and 0 <= action < env.action_space.n
            assert expert(frame.astype(bool)) == action  # minatar's own bool frames read the same
        obs, _, terminated, _, _ = env.step(int(rng.integers(env.action_space.n)))
        if terminated:
            obs, _ = env.reset(seed=step)
    env.close()


@pytest.mark.parametrize("task", PRESETS)
def test_the_experts_returns_are_in_their_measured_bands(task: str) -> None:
    n = EPISODES[task]
    means = {}
    for expert in ("strong", "imperfect"):
        mean, std = MEASURED[task, expert]
        means[expert] = play(task, expert, n).mean()
        margin = BAND_SE * std / np.sqrt(n)
        assert mean - margin <= means[expert] <= mean + margin, (expert, means[expert], mean, margin)
    assert means["strong"] > means["imperfect"] + 30


def breakout_frame(paddle: int, ball: tuple[int, int], trail: tuple[int, int], brick_rows: bool = False) -> np.ndarray:
    """A Breakout frame: (row, column) cells of the ball and its trail, the paddle's column on row 9."""
    frame = np.zeros((10, 10, 4), np.uint8)
    frame[9, paddle, 0] = 1
    frame[(*ball, 1)] = 1
    frame[(*trail, 2)] = 1
    if brick_rows:
        frame[1:4, :, 3] = 1
    return frame


def test_strong_breakout_moves_to_where_the_ball_comes_down_not_where_it_is() -> None:
    # The ball at row 4, column 6, came from (3, 7): falling to the left, it passes (5, 5), (6, 4),
    # (7, 3), (8, 2) and comes down to column 1 or 2, left of the paddle at 3; it is now right of it.
    frame = breakout_frame(paddle=3, ball=(4, 6), trail=(3, 7))
    assert minatar_tasks.breakout_strong(frame) == minatar_tasks.LEFT
    assert minatar_tasks.breakout_imperfect(frame) == minatar_tasks.RIGHT


def test_strong_breakout_follows_the_ball_off_the_wall() -> None:
    # Falling left from (5, 1): (6, 0), then the wall turns it and it stays in column 0: (7, 0),
    # (8, 1), down to column 1 or 2. A paddle at 6 has 4 moves by then (3 steps before the one onto
    # row 9, the paddle moving first on each): it can reach column 2, to its left; one at 0 moves right.
    assert minatar_tasks.breakout_strong(breakout_frame(paddle=6, ball=(5, 1), trail=(4, 2))) == minatar_tasks.LEFT
    assert minatar_tasks.breakout_strong(breakout_frame(paddle=0, ball=(5, 1), trail=(4, 2))) == minatar_tasks.RIGHT


def test_strong_breakout_reads_the_start_frame_as_falling() -> None:
    # The start: the ball on row 3's bricks at column 0, its trail on the same cell, falling right:
    # (4, 1) … (8, 5), down to column 5 or 6, right of the paddle at 4.
    frame = breakout_frame(paddle=4, ball=(3, 0), trail=(3, 0), brick_rows=True)
    env = gym.make("MinAtar/Breakout-v1")
    starts = {np.asarray(env.reset(seed=seed)[0], np.uint8).tobytes() for seed in range(20)}
    env.close()
    assert frame.tobytes() in starts
    assert minatar_tasks.breakout_strong(frame) == minatar_tasks.RIGHT


def freeway_frame(chicken_row: int, cars: dict[int, tuple[int, int]]) -> np.ndarray:
    """A Freeway frame: the chicken's row; per car row, its column and signed speed (+ moves right)."""
    frame = np.zeros((10, 10, 7), np.uint8)
    frame[chicken_row, 4, 0] = 1
    for row in range(1, 9):
        x, speed = cars.get(row, (0, 1))  # a car at column 0 moving right: 4 cells away from the chicken's
        frame[row, x, 1] = 1
        frame[row, (x - np.sign(speed)) % 10, 1 + abs(speed)] = 1
    return frame


def test_strong_freeway_waits_for_a_car_about_to_cross_and_goes_behind_one_that_passed() -> None:
    coming = freeway_frame(9, {8: (5, -1)})  # one cell right of the chicken's column, moving left
    passed = freeway_frame(9, {8: (5, 1)})  # one cell right, moving away
    assert minatar_tasks.freeway_strong(coming) == minatar_tasks.NOOP
    assert minatar_tasks.freeway_strong(passed) == minatar_tasks.UP
    assert minatar_tasks.freeway_imperfect(coming) == minatar_tasks.UP
    # A slow car (speed 5: one cell every 6 frames) two cells away cannot arrive within 3 frames; a
    # fast one (speed 1: every 2 frames) can, moving on frames 0 and 2.
    assert minatar_tasks.freeway_strong(freeway_frame(9, {8: (6, -5)})) == minatar_tasks.UP
    assert minatar_tasks.freeway_strong(freeway_frame(9, {8: (6, -1)})) == minatar_tasks.NOOP
    # In lane 5, a car one cell away and a clear lane 6 below: step back down.
    assert minatar_tasks.freeway_strong(freeway_frame(5, {4: (4, 1), 5: (3, 1)})) == minatar_tasks.DOWN
