"""The MinAtar presets (tasks/minatar.py, tasks/minatar_*.py): registered, their Gymnasium ids, their experts' play."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.wrappers import TimeLimit

import dqfd_bc_keras.tasks.minatar as minatar_tasks
import dqfd_bc_keras.tasks.minatar_asterix as asterix
import dqfd_bc_keras.tasks.minatar_seaquest as seaquest
import dqfd_bc_keras.tasks.minatar_space_invaders as space_invaders
from dqfd_bc_keras.demos.keys import env_keys
from dqfd_bc_keras.envs.make import make_task
from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.experiments.lab_settings import lab_settings
from dqfd_bc_keras.tasks import TASKS, find_preset

pytest.importorskip("minatar")
REPO = Path(__file__).resolve().parents[1]
PRESETS = ("minatar-breakout", "minatar-freeway", "minatar-asterix", "minatar-seaquest", "minatar-space-invaders")
MODULES = {
    "minatar-breakout": "minatar",
    "minatar-freeway": "minatar",
    "minatar-asterix": "minatar_asterix",
    "minatar-seaquest": "minatar_seaquest",
    "minatar-space-invaders": "minatar_space_invaders",
}
"""The module of dqfd_bc_keras.tasks that registers each preset."""
FRAMES = {
    "minatar-breakout": (4, 3),
    "minatar-freeway": (7, 3),
    "minatar-asterix": (4, 5),
    "minatar-seaquest": (10, 6),
    "minatar-space-invaders": (6, 4),
}
"""Channels and actions (the minimal action sets)."""
STUDIED = ("minatar-breakout", "minatar-freeway")
"""The presets with lab settings (the pixels study's grid teachers)."""

# The 100-episode measurement (seeds 0–99, one env, `TimeLimit(max_steps)`): mean, std.
MEASURED = {
    ("minatar-breakout", "strong"): (79.93, 14.36),
    ("minatar-breakout", "imperfect"): (8.58, 9.21),
    ("minatar-freeway", "strong"): (65.85, 1.93),
    ("minatar-freeway", "imperfect"): (15.72, 12.65),
    ("minatar-asterix", "strong"): (56.20, 16.86),
    ("minatar-asterix", "imperfect"): (28.58, 18.12),
    ("minatar-seaquest", "strong"): (53.09, 16.15),
    ("minatar-seaquest", "imperfect"): (11.03, 7.42),
    ("minatar-space-invaders", "strong"): (151.43, 27.59),
    ("minatar-space-invaders", "imperfect"): (22.56, 1.80),
}
EPISODES = {
    "minatar-breakout": 20,
    "minatar-freeway": 8,
    "minatar-asterix": 4,
    "minatar-seaquest": 4,
    "minatar-space-invaders": 3,
}
"""Few enough that the band test takes seconds (Freeway's episodes are 2500 steps, the strong rules
of Asterix, Seaquest and SpaceInvaders mostly play their 1000 at about a millisecond a step)."""
STRONGER_BY = {
    "minatar-breakout": 30,
    "minatar-freeway": 30,
    "minatar-asterix": 15,
    "minatar-seaquest": 20,
    "minatar-space-invaders": 60,
}
"""How much more the strong expert's mean over those episodes must be than the imperfect one's (for the
three later games, about half the gap of their 100-episode means)."""
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
    assert find_preset(f"dqfd_bc_keras.tasks.{MODULES[task]}:{task}") is spec
    assert spec.env_id.endswith("-v1") and spec.defaults is minatar_tasks.DEFAULTS  # its pace: test_play_pace.py
    env = gym.make(spec.env_id)  # the id resolves after the import, without minatar.gym.register_envs()
    channels, actions = FRAMES[task]
    assert env.observation_space.shape == (10, 10, channels)
    assert env.action_space.n == actions  # the minimal action sets
    env.close()


@pytest.mark.parametrize("task", PRESETS)
def test_the_presets_keys_are_the_games_own(task: str) -> None:
    env = make_task(task)
    assert env_keys(env)[0] == dict(TASKS[task].keys)  # MinAtar's letters: space fires, "" is no-op
    env.close()


def test_the_presets_record_their_teachers_and_stay_out_of_the_vector_suites() -> None:
    for task in STUDIED:  # the MinAtar study is its own suite (its SB3 baseline differs)
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


@pytest.mark.slow
@pytest.mark.parametrize("task", PRESETS)
def test_the_experts_returns_are_in_their_measured_bands(task: str) -> None:
    n = EPISODES[task]
    means = {}
    for expert in ("strong", "imperfect"):
        mean, std = MEASURED[task, expert]
        means[expert] = play(task, expert, n).mean()
        margin = BAND_SE * std / np.sqrt(n)
        assert mean - margin <= means[expert] <= mean + margin, (expert, means[expert], mean, margin)
    assert means["strong"] > means["imperfect"] + STRONGER_BY[task]


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


def asterix_frame(
    player: tuple[int, int], enemies: list[tuple[int, int, int]] = (), golds: list[tuple[int, int, int]] = ()
) -> np.ndarray:
    """An Asterix frame: the player's cell; (row, column, direction) of enemies and treasures, each
    with its trail behind it (direction 0: none, as on entering)."""
    frame = np.zeros((10, 10, 4), np.uint8)
    frame[(*player, 0)] = 1
    for channel, entities in ((1, enemies), (3, golds)):
        for y, x, direction in entities:
            frame[y, x, channel] = 1
            if direction and 0 <= x - direction <= 9:
                frame[y, x - direction, 2] = 1
    return frame


def test_asterix_danger_reads_directions_from_trails_and_fears_empty_rows_edges() -> None:
    frame = asterix_frame((4, 5), enemies=[(2, 5, -1), (3, 0, 0)], golds=[(6, 4, 1)])
    now = asterix.danger(frame, 1)
    assert np.flatnonzero(now[2]).tolist() == [4, 5]  # the trail on its right: it moves left
    assert np.flatnonzero(now[3]).tolist() == [0, 1]  # no trail, on the left edge: it has just entered
    assert not now[6].any()  # a treasure is no danger, and its row is taken: nothing can enter it
    for row in (1, 4, 5, 7, 8):  # an enemy may enter an empty row from either edge and move at once
        assert np.flatnonzero(now[row]).tolist() == [0, 1, 8, 9]
    assert np.flatnonzero(asterix.danger(frame, 2)[2]).tolist() == [3, 4, 5]


def test_asterix_strong_looks_ahead_where_the_imperfect_rule_walks_into_a_dead_end() -> None:
    # Against the left wall on row 4, a treasure up on row 1; enemies two cells away on rows 2–4,
    # coming left. Up is safe this step, but there every next cell may be an enemy's (the wall, rows
    # 2 and 4, the enemy in row 3 reaching column 0); row 5, taken by a treasure far right, is safe.
    frame = asterix_frame((4, 0), enemies=[(2, 2, -1), (3, 2, -1), (4, 2, -1)], golds=[(1, 0, 0), (5, 9, 1)])
    assert not asterix.danger(frame, 1)[3, 0] and asterix.danger(frame, 2)[[2, 3, 4], 0].all()
    assert asterix.asterix_imperfect(frame) == asterix.UP  # the nearest treasure, safe for one step
    assert asterix.asterix_strong(frame) != asterix.UP


def seaquest_frame(
    sub: tuple[int, int],
    facing: int,
    oxygen: int = 10,
    divers: int = 0,
    fish: list[tuple[int, int, int]] = (),
    subs: list[tuple[int, int, int]] = (),
    people: list[tuple[int, int, int]] = (),
    bullets: list[tuple[int, int]] = (),
) -> np.ndarray:
    """A Seaquest frame: the player's front cell and facing, the gauges, (row, column, direction) of
    fish, enemy subs and divers (with trails), enemy bullets' cells."""
    frame = np.zeros((10, 10, 10), np.uint8)
    frame[(*sub, 0)] = 1
    frame[sub[0], sub[1] - facing, 1] = 1
    frame[9, :oxygen, 7] = 1
    frame[9, 9 - divers : 9, 8] = 1
    for channel, entities in ((5, fish), (6, subs), (9, people)):
        for y, x, direction in entities:
            frame[y, x, channel] = 1
            if 0 <= x - direction <= 9:
                frame[y, x - direction, 3] = 1
    for y, x in bullets:
        frame[y, x, 4] = 1
    return frame


def test_seaquest_reads_the_frame_and_takes_ambiguous_directions_both_ways() -> None:
    frame = seaquest_frame((2, 5), 1, oxygen=7, divers=2, fish=[(5, 6, -1)], people=[(5, 4, -1)])
    scene = seaquest.read(frame)
    assert (scene.y, scene.x, scene.facing, scene.oxygen, scene.divers) == (2, 5, 1, 7, 2)
    assert scene.enemies == [(5, 6, 1), (5, 6, -1)]  # the diver's trail is on the fish's left too
    assert np.flatnonzero(seaquest.danger(scene, 1)[5]).tolist() == [5, 6, 7]
    # A bullet moves as the enemy subs of its row do; with none there (its sub shot), either way.
    frame = seaquest_frame((5, 5), 1, subs=[(5, 9, -1)], bullets=[(5, 7), (2, 4)])
    assert sorted(seaquest.read(frame).bullets) == [(2, 4, -1), (2, 4, 1), (5, 7, -1)]


def test_seaquest_strong_surfaces_on_low_oxygen_with_a_diver_and_never_without() -> None:
    low = seaquest_frame((3, 5), -1, oxygen=2, divers=1, fish=[(6, 1, 1)])
    assert seaquest.seaquest_strong(low) == seaquest.UP
    assert seaquest.seaquest_imperfect(low) != seaquest.UP  # it does not watch the oxygen
    no_diver = seaquest_frame((1, 5), -1, oxygen=2, fish=[(6, 1, 1)])  # surfacing would end the game
    assert seaquest.seaquest_strong(no_diver) != seaquest.UP


def test_seaquest_fires_at_an_enemy_ahead_in_its_row() -> None:
    frame = seaquest_frame((4, 5), -1, fish=[(4, 1, 1)])  # facing left, the fish coming from the left
    assert seaquest.seaquest_strong(frame) == seaquest.seaquest_imperfect(frame) == seaquest.FIRE


def space_invaders_frame(
    cannon: int,
    aliens: list[tuple[int, int]],
    direction: int = -1,
    bullets: list[tuple[int, int]] = (),
    enemy_bullets: list[tuple[int, int]] = (),
) -> np.ndarray:
    """A SpaceInvaders frame: the cannon's column, the aliens' cells and the block's direction, bullets."""
    frame = np.zeros((10, 10, 6), np.uint8)
    frame[9, cannon, 0] = 1
    for y, x in aliens:
        frame[y, x, 1] = frame[y, x, 2 if direction < 0 else 3] = 1
    for channel, cells in ((4, bullets), (5, enemy_bullets)):
        for y, x in cells:
            frame[y, x, channel] = 1
    return frame


def test_space_invaders_strong_leads_a_fast_alien_where_the_imperfect_rule_fires_under_it() -> None:
    # The last alien moves every frame: at (5, 2) going right, a bullet fired now from column 6 meets
    # it on row 5 (the bullet on row 8 − k after k steps, the alien at column 3 + k); from under it, none does.
    ahead, under = space_invaders_frame(6, [(5, 2)], 1), space_invaders_frame(2, [(5, 2)], 1)
    assert space_invaders.hit_rows(ahead, np.zeros(10, int)).tolist() == [[-1] * 6 + [5] + [-1] * 3]
    assert space_invaders.space_invaders_strong(ahead) == space_invaders.FIRE
    assert space_invaders.space_invaders_imperfect(ahead) == space_invaders.LEFT  # to the alien's column
    assert space_invaders.space_invaders_imperfect(under) == space_invaders.FIRE
    assert space_invaders.space_invaders_strong(under) == space_invaders.RIGHT


def test_space_invaders_dodges_a_landing_bullet_and_knows_its_cool_down() -> None:
    frame = space_invaders_frame(5, [(2, 4), (2, 5)], enemy_bullets=[(8, 5)])  # lands on the cannon next step
    strong, imperfect = space_invaders.space_invaders_strong, space_invaders.space_invaders_imperfect
    assert strong(frame) == imperfect(frame) == space_invaders.LEFT
    # A shot k steps ago is on row 8 − k; the cannon fires again 5 steps after the last.
    waits = [space_invaders._wait(space_invaders_frame(5, [(0, 5)], bullets=[(row, 5)])) for row in (8, 7, 5, 4)]
    assert waits == [4, 3, 1, 0]
