"""Atari preprocessing: the wrappers by hand on a scripted toy game, then on ALE/Breakout-v5.

The toy game's frames, rewards and lives are written out per frame, so each expected step
(summed rewards, pooled frames, clipped rewards, ends, continued games) is computed here by hand.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from dqfd_bc_keras.envs.atari import ATARI_OPTIONS, AtariOptions, is_atari, make_atari, split_kwargs, wrap_atari
from dqfd_bc_keras.envs.atari_wrappers import AtariFrames, area_weights
from dqfd_bc_keras.errors import ConfigError

BREAKOUT = "ale_py:ALE/Breakout-v5"


class ToyGame(gym.Env):
    """A scripted game on a 4x4 screen: frame t is t everywhere but a bright pixel 100 + t at
    row t % 4, column 0; `rewards[t]` and `lives[t]` are paid / shown on frame t; the game is
    over on its last frame. It records every action and counts its resets."""

    observation_space = gym.spaces.Box(0, 255, (4, 4), np.uint8)
    action_space = gym.spaces.Discrete(3)

    def __init__(self, rewards: list[float], lives: list[int]) -> None:
        self.rewards, self.lives, self.actions, self.resets, self.t = rewards, lives, [], 0, 0

    @staticmethod
    def frame(t: int) -> np.ndarray:
        frame = np.full((4, 4), t, np.uint8)
        frame[t % 4, 0] = 100 + t
        return frame

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        self.t, self.resets = 0, self.resets + 1
        return self.frame(0), {"lives": self.lives[0]}

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict]:
        self.t += 1
        self.actions.append(action)
        over = self.t == len(self.rewards) - 1
        return self.frame(self.t), self.rewards[self.t], over, False, {"lives": self.lives[self.t]}


def toy_env(rewards: list[float], lives: list[int] | None = None, learning: bool = True, **options) -> gym.Env:
    options = {"noop_max": 0, "frame_skip": 1, "screen_size": 4, **options}
    return wrap_atari(ToyGame(rewards, lives or [3] * len(rewards)), AtariOptions(**options), learning)


# ---- the parts by hand -------------------------------------------------------------------------


def test_area_weights_average_each_cell_by_overlap():
    # 3 pixels to 2 cells of width 1.5: cell 0 = pixel 0 + half of pixel 1, over 1.5
    np.testing.assert_allclose(area_weights(3, 2), [[2 / 3, 1 / 3, 0], [0, 1 / 3, 2 / 3]])
    np.testing.assert_allclose(area_weights(4, 4), np.eye(4))
    np.testing.assert_allclose(area_weights(4, 2), [[0.5, 0.5, 0, 0], [0, 0, 0.5, 0.5]])
    for n_in in (210, 160):
        np.testing.assert_allclose(area_weights(n_in, 84).sum(axis=1), 1.0)


def test_frames_are_shrunk_by_area_average():
    frames = AtariFrames(ToyGame([0.0, 0.0], [3, 3]), noop_max=0, frame_skip=1, screen_size=2)
    obs, _ = frames.reset()  # frame 0: zeros with 100 at (0, 0): the top-left 2x2 cell averages to 25
    np.testing.assert_array_equal(obs, [[25, 0], [0, 0]])


def test_a_step_repeats_the_action_sums_rewards_and_pools_the_last_two_frames():
    game = ToyGame([0.0, 1.0, 2.0, 4.0, 0.0, 8.0, 0.0, 0.0], [3] * 8)
    frames = AtariFrames(game, noop_max=0, frame_skip=3, screen_size=4)
    frames.reset()
    obs, reward, terminated, _, _ = frames.step(2)
    assert (game.actions, reward, terminated) == ([2, 2, 2], 1.0 + 2.0 + 4.0, False)
    np.testing.assert_array_equal(obs, np.maximum(ToyGame.frame(2), ToyGame.frame(3)))
    obs, reward, terminated, _, _ = frames.step(1)  # frames 4..6
    assert reward == 8.0
    obs, reward, terminated, _, _ = frames.step(1)  # the game is over on frame 7: the step stops there
    assert (len(game.actions), reward, terminated) == (7, 0.0, True)
    np.testing.assert_array_equal(obs, ToyGame.frame(7))


def test_noop_starts_draw_their_count_from_the_seeded_env():
    for seed in (0, 1, 2):
        game = ToyGame([0.0] * 40, [3] * 40)
        obs, info = AtariFrames(game, noop_max=5, frame_skip=1, screen_size=4).reset(seed=seed)
        expected = int(np.random.default_rng(seed).integers(1, 6))  # gymnasium's np_random(seed)
        assert info["noops"] == expected == game.t and game.actions == [0] * expected
        np.testing.assert_array_equal(obs, ToyGame.frame(expected))


def test_rewards_are_clipped_to_their_sign_and_plain_reward_is_raw():
    env = toy_env([0.0, 5.0, -3.0, 0.5, 0.0, 0.0])
    env.reset()
    steps = [env.step(0) for _ in range(4)]
    assert [s[1] for s in steps] == [1.0, -1.0, 1.0, 0.0]
    assert [s[4]["plain_reward"] for s in steps] == [5.0, -3.0, 0.5, 0.0]


def test_plain_reward_is_the_sum_over_the_skipped_frames():
    env = toy_env([0.0, 4.0, -1.0, 2.0, -2.0, 0.0], frame_skip=2)
    env.reset()
    (_, r1, _, _, i1), (_, r2, _, _, i2) = env.step(0), env.step(0)
    assert (r1, i1["plain_reward"], r2, i2["plain_reward"]) == (1.0, 3.0, 0.0, 0.0)


def test_clip_rewards_false_keeps_the_raw_reward():
    env = toy_env([0.0, 5.0, 0.0], clip_rewards=False)
    env.reset()
    assert env.step(0)[1] == 5.0


# lives per frame: a life lost on frames 2 and 5, the game over on frame 7 (its last)
LIVES = [3, 3, 2, 2, 2, 1, 1, 0]
REWARDS = [0.0, 1.0, 3.0, 0.0, 2.0, 0.0, 7.0, 0.0]


def test_a_lost_life_ends_the_episode_and_the_next_reset_continues_the_game():
    env = toy_env(REWARDS, LIVES, frame_stack=3)
    game = env.unwrapped
    obs, info = env.reset(seed=0)
    assert info["new_game"] and game.resets == 1
    ends, plain = [], []
    for _ in range(3):  # three episodes: frames 1-2, 3-5, 6-7
        done = False
        while not done:
            obs, _, terminated, truncated, info = env.step(0)
            done = terminated or truncated
            plain.append(info["plain_reward"])
        ends.append((game.t, info["lives"]))
        last_frame, game_over = obs[..., -1], game.t == len(LIVES) - 1
        obs, info = env.reset(seed=123)  # a continuing reset ignores the seed
        if not game_over:
            assert not info["new_game"] and game.resets == 1 and info["lives"] == LIVES[game.t]
            np.testing.assert_array_equal(obs, np.repeat(last_frame[..., None], 3, axis=-1))
    assert ends == [(2, 2), (5, 1), (7, 0)]
    assert info["new_game"] and game.resets == 2 and game.t == 0  # the game was over: a real reset
    assert sum(plain) == sum(REWARDS)  # no step of the game went missing


def test_a_reset_that_does_not_follow_a_lost_life_is_a_real_reset():
    env = toy_env(REWARDS, LIVES)
    env.reset()
    env.step(0)  # frame 1: no life lost; say our time limit truncates here
    _, info = env.reset()
    assert info["new_game"] and env.unwrapped.resets == 2 and env.unwrapped.t == 0


def test_the_plain_env_ends_only_at_game_over_with_raw_rewards():
    env = toy_env(REWARDS, LIVES, learning=False)
    env.reset()
    steps = [env.step(0) for _ in range(7)]
    assert [s[2] for s in steps] == [False] * 6 + [True]
    assert [s[1] for s in steps] == REWARDS[1:]


def test_terminal_on_life_loss_false_keeps_the_game_one_episode():
    env = toy_env(REWARDS, LIVES, terminal_on_life_loss=False)
    env.reset()
    assert [env.step(0)[2] for _ in range(7)] == [False] * 6 + [True]


def test_the_stack_shifts_by_one_frame_newest_last_and_a_reset_stack_is_one_frame():
    env = toy_env([0.0] * 10, frame_stack=4)
    obs, _ = env.reset()
    np.testing.assert_array_equal(obs, np.repeat(ToyGame.frame(0)[..., None], 4, axis=-1))
    for t in range(1, 6):
        next_obs, *_ = env.step(0)
        np.testing.assert_array_equal(next_obs[..., :-1], obs[..., 1:])
        np.testing.assert_array_equal(next_obs[..., -1], ToyGame.frame(t))
        obs = next_obs


# ---- options -----------------------------------------------------------------------------------


def test_split_kwargs_takes_the_options_out_and_turns_the_ale_skip_off():
    options, make_kwargs = split_kwargs({"frame_stack": 2, "clip_rewards": False, "repeat_action_probability": 0.0})
    assert options == AtariOptions(frame_stack=2, clip_rewards=False)
    assert make_kwargs == {"repeat_action_probability": 0.0, "frameskip": 1, "obs_type": "grayscale"}
    assert split_kwargs(None)[0] == ATARI_OPTIONS == AtariOptions(30, 4, 84, 4, True, True)


@pytest.mark.parametrize(
    "kwargs, says",
    [
        ({"frame_skp": 2}, "did you mean 'frame_skip'?"),
        ({"frame_skip": 0}, "frame_skip: expected an integer >= 1, got 0"),
        ({"noop_max": -1}, "noop_max: expected an integer >= 0, got -1"),
        ({"frame_stack": 2.5}, "frame_stack: expected an integer >= 1, got 2.5"),
        ({"screen_size": True}, "screen_size: expected an integer >= 1, got True"),
        ({"clip_rewards": 1}, "clip_rewards: expected true or false, got 1"),
        ({"frameskip": 4}, "use frame_skip"),
        ({"obs_type": "rgb"}, "obs_type"),
    ],
)
def test_a_bad_option_is_one_line(kwargs, says):
    with pytest.raises(ConfigError) as caught:
        split_kwargs(kwargs)
    assert says in str(caught.value) and "\n" not in str(caught.value)


def test_is_atari():
    assert is_atari("ale_py:ALE/Breakout-v5") and is_atari("ALE/Pong-v5")
    assert not is_atari("CartPole-v1") and not is_atari("minatar:MinAtar/Breakout-v1")


# ---- ALE/Breakout-v5 ---------------------------------------------------------------------------


def play(env: gym.Env, seed: int, steps: int):
    """Random play from reset(seed): every (obs, reward, terminated, truncated, info)."""
    rng = np.random.default_rng(seed)
    first = env.reset(seed=seed)
    return first, [env.step(int(rng.integers(env.action_space.n))) for _ in range(steps)]


def test_breakout_observations_and_the_ale_settings():
    env = make_atari(BREAKOUT)
    assert env.observation_space == gym.spaces.Box(0, 255, (84, 84, 4), np.uint8)
    ale_env = env.unwrapped
    assert ale_env._frameskip == 1 and ale_env.ale.getFloat("repeat_action_probability") == pytest.approx(0.25)
    (obs, info), _ = play(env, 0, 0)
    assert obs.shape == (84, 84, 4) and obs.dtype == np.uint8 and obs in env.observation_space
    assert all((obs[..., k] == obs[..., 0]).all() for k in range(4)) and 1 <= info["noops"] <= 30
    assert info["episode_frame_number"] == info["noops"]


def test_breakout_life_loss_ends_a_learning_episode_and_the_reset_continues_the_game():
    env = make_atari(BREAKOUT)
    obs, info = env.reset(seed=1)
    rng, lives = np.random.default_rng(1), info["lives"]
    for _ in range(2000):
        next_obs, _, terminated, truncated, info = env.step(int(rng.integers(4)))
        np.testing.assert_array_equal(next_obs[..., :-1], obs[..., 1:])
        obs = next_obs
        if terminated or truncated:
            break
    assert terminated and info["lives"] == lives - 1
    frame, frames_played = obs[..., -1], info["episode_frame_number"]
    obs, info = env.reset(seed=2)
    assert not info["new_game"] and info["lives"] == lives - 1
    assert env.unwrapped.ale.getEpisodeFrameNumber() == frames_played  # the same game, not restarted
    np.testing.assert_array_equal(obs, np.repeat(frame[..., None], 4, axis=-1))


@pytest.mark.slow
def test_breakout_plain_env_ends_only_at_game_over():
    env = make_atari(BREAKOUT, learning=False)
    env.reset(seed=3)
    rng, lives_seen = np.random.default_rng(3), set()
    for _ in range(3000):
        _, reward, terminated, truncated, info = env.step(int(rng.integers(4)))
        lives_seen.add(info["lives"])
        assert reward >= 0 and "plain_reward" not in info
        if terminated or truncated:
            break
    assert terminated and info["lives"] == 0 and lives_seen == {0, 1, 2, 3, 4, 5}


@pytest.mark.slow
def test_breakout_same_seed_same_observations():
    (obs_a, _), steps_a = play(make_atari(BREAKOUT), 4, 150)
    (obs_b, _), steps_b = play(make_atari(BREAKOUT), 4, 150)
    np.testing.assert_array_equal(obs_a, obs_b)
    for a, b in zip(steps_a, steps_b, strict=True):
        np.testing.assert_array_equal(a[0], b[0])
        assert a[1:4] == b[1:4]


def test_breakout_options_and_ale_kwargs_from_env_kwargs():
    env = make_atari(
        BREAKOUT,
        {
            "frame_stack": 2,
            "screen_size": 42,
            "noop_max": 0,
            "repeat_action_probability": 0.0,
            "full_action_space": True,
        },
    )
    obs, info = env.reset(seed=0)
    assert obs.shape == (42, 42, 2) and info["noops"] == 0 and info["episode_frame_number"] == 0
    assert env.unwrapped.ale.getFloat("repeat_action_probability") == 0.0 and env.action_space.n == 18
