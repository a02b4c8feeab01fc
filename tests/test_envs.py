"""The task wrappers' semantics, checked on hand-driven episodes."""

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import dqfd_bc_keras
from dqfd_bc_keras.choices import TIMEOUT_MODES
from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.envs.make import TASKS, checked_spaces, make_plain_env, make_task
from dqfd_bc_keras.errors import ConfigError

RIGHT, LEFT = 1, 0


def run_episode(env, policy, seed=0):
    """Drive one episode; return the list of (reward, terminated, truncated, info) per step."""
    obs, _ = env.reset(seed=seed)
    steps = []
    while True:
        obs, reward, terminated, truncated, info = env.step(policy(obs))
        steps.append((float(reward), terminated, truncated, info))
        if terminated or truncated:
            return steps


def balance(obs):
    """A rule that keeps CartPole up for the whole limit."""
    return int(obs[2] + 0.5 * obs[3] > 0)


@pytest.mark.parametrize("mode", TIMEOUT_MODES)
def test_fall_penalty_lands_on_the_falling_step_only(mode):
    steps = run_episode(make_task("cartpole", timeout=mode), lambda obs: RIGHT)
    rewards = [r for r, *_ in steps]
    assert 5 < len(steps) < 50  # always pushing right drops the pole quickly
    assert rewards[:-1] == [1.0] * (len(steps) - 1)
    assert rewards[-1] == -100.0
    assert steps[-1][1] is True and steps[-1][2] is False
    assert [info["plain_reward"] for *_, info in steps] == [1.0] * len(steps)


def test_fall_penalty_is_configurable_and_truncation_never_pays_it():
    env = dqfd_bc_keras.envs.wrappers.TimeLimitMode(
        dqfd_bc_keras.envs.wrappers.FallPenalty(gym.make("CartPole-v1", max_episode_steps=-1), penalty=-7.0), 30
    )
    assert run_episode(env, lambda obs: RIGHT)[-1][0] == -7.0
    steps = run_episode(env, balance)
    assert len(steps) == 30 and steps[-1][2] is True
    assert [r for r, *_ in steps] == [1.0] * 30


@pytest.mark.parametrize(
    "mode, terminated, truncated", [("bootstrap", False, True), ("naive", True, False), ("time-aware", True, False)]
)
def test_time_limit_flags(mode, terminated, truncated):
    steps = run_episode(make_task("cartpole-200", timeout=mode), balance)
    assert len(steps) == 200
    assert all(not t and not u for _, t, u, _ in steps[:-1])
    _, last_terminated, last_truncated, info = steps[-1]
    assert (last_terminated, last_truncated) == (terminated, truncated)
    assert info["time_limit"] is True
    assert steps[-1][0] == 1.0  # the time limit is not a fall: no penalty in any mode


def test_time_limit_is_configurable_and_defaults_to_the_task():
    assert len(run_episode(make_task("cartpole"), balance)) == 500
    assert len(run_episode(make_task("cartpole", max_steps=37), balance)) == 37
    assert len(run_episode(make_task("mountaincar"), lambda obs: 1)) == 200


def test_time_aware_observation_carries_the_remaining_fraction():
    env = make_task("cartpole-200", timeout="time-aware", max_steps=4)
    assert env.observation_space.shape == (5,)
    obs, _ = env.reset(seed=3)
    plain_obs, _ = make_plain_env("cartpole-200").reset(seed=3)
    np.testing.assert_array_equal(obs[:4], plain_obs)
    fractions = [obs[4]]
    for _ in range(4):
        obs, *_ = env.step(balance(obs))
        fractions.append(obs[4])
    np.testing.assert_allclose(fractions, [1.0, 0.75, 0.5, 0.25, 0.0])
    assert obs.dtype == np.float32 and env.observation_space.contains(obs)


def test_goal_count_counts_every_flag_and_restarts_the_car():
    """Pushing with the velocity reaches the flag in ~120 steps; 600 steps give several goals."""
    env = make_task("mountaincar-goals", max_steps=600)
    obs, info = env.reset(seed=1)
    assert info["goals"] == 0
    goals, rewards, plain, first_goal_step = 0, [], [], None
    for t in range(600):
        obs, reward, terminated, truncated, info = env.step(2 if obs[1] >= 0 else 0)
        rewards.append(reward)
        plain.append(info["plain_reward"])
        if info["goals"] > goals:  # the car was put back at a fresh start state, at rest
            goals = info["goals"]
            first_goal_step = first_goal_step or t
            assert reward == 100.0
            assert -0.6 <= obs[0] <= -0.4 and obs[1] == 0.0
        else:
            assert reward == -1.0
        assert not terminated
    assert truncated and goals >= 2
    assert rewards.count(100.0) == goals
    # The plain return is MountainCar-v0's: −1 per step up to and including the first goal.
    assert sum(plain) == -(first_goal_step + 1)


def test_mountaincar_without_goal_count_terminates_at_the_flag():
    steps = run_episode(make_task("mountaincar", max_steps=1000), lambda obs: 2 if obs[1] >= 0 else 0)
    assert steps[-1][1] is True and steps[-1][0] == -1.0 and "goals" not in steps[-1][3]


MINATAR = tuple(name for name, spec in TASKS.items() if spec.env_id.startswith("MinAtar/"))
"""MinAtar's own gym wrapper seeds its game, not `Env.np_random` (no `super().reset(seed=seed)`),
which `check_env` asserts; its presets are checked by the test after this one."""


@pytest.mark.parametrize("task", sorted(set(TASKS) - set(MINATAR)))
@pytest.mark.parametrize("mode", TIMEOUT_MODES)
def test_check_env_passes_on_every_preset(task, mode):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # CartPole's own infinite bounds, the wrapper notice
        check_env(make_task(task, timeout=mode), skip_render_check=True)
        check_env(gym.make(TASKS[task].gym_id, timeout=mode), skip_render_check=True)


@pytest.mark.parametrize("task", MINATAR)
def test_the_minatar_presets_are_seeded_frames_with_their_limit(task):
    env = make_task(task)
    assert env.observation_space == gym.spaces.Box(0, 1, env.observation_space.shape, np.uint8)

    def play(seed: int) -> list[np.ndarray]:
        obs, _ = env.reset(seed=seed)
        frames = [obs]
        for t in range(60):
            obs, _, terminated, truncated, _ = env.step(t % 3)
            frames.append(obs)
            if terminated or truncated:
                break
        return frames

    first, again, other = play(3), play(3), play(4)
    assert all(f.dtype == np.uint8 and env.observation_space.contains(f) for f in first)
    assert len(first) == len(again) and all(np.array_equal(a, b) for a, b in zip(first, again, strict=True))
    assert len(first) != len(other) or any(not np.array_equal(a, b) for a, b in zip(first, other, strict=False))
    limited = make_task(task, max_steps=5)
    limited.reset(seed=0)
    flags = [limited.step(0)[2:4] for _ in range(5)]
    assert flags[-1] == (False, True) or flags[-1][0]  # truncated at the limit, unless the game ended on it
    with pytest.raises(ConfigError, match="appends the time left to a vector observation"):
        make_task(task, timeout="time-aware")


def test_registered_ids_build_the_presets():
    env = gym.make("dqfd_bc_keras/cartpole-200-v0", timeout="naive")
    steps = run_episode(env, balance)
    assert len(steps) == 200 and steps[-1][1] is True
    assert gym.make("dqfd_bc_keras/mountaincar-goals-v0").reset(seed=0)[1]["goals"] == 0


def test_plain_env_is_unmodified():
    env = make_plain_env("cartpole-200")
    assert env.spec.id == "CartPole-v1" and env.spec.max_episode_steps == 500
    steps = run_episode(env, lambda obs: RIGHT)
    assert steps[-1][0] == 1.0  # no fall penalty


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"name": "pong"}, "unknown task 'pong'"),
        (
            {"name": "no_such_pkg:Pong-v0"},
            r"^unknown task 'no_such_pkg:Pong-v0': no module named 'no_such_pkg' \(is its directory on PYTHONPATH\?\)$",
        ),
        ({"name": "json:NoSuch-v0"}, r"^unknown task 'json:NoSuch-v0': neither a preset \(.*\) nor a Gymnasium env id"),
        ({"name": "cartpole", "timeout": "lazy"}, "unknown timeout mode 'lazy'"),
        ({"name": "cartpole", "max_steps": 0}, "max_steps must be ≥ 1, got 0"),
    ],
)
def test_bad_task_settings_are_rejected_by_name(kwargs, match):
    with pytest.raises(ConfigError, match=match):
        make_task(**kwargs)


@pytest.mark.parametrize(
    "task, fields, match",
    [
        ("cartpole", {"torso": "minatar"}, "torso='minatar' needs frames"),
        ("cartpole", {"torso": "nature"}, "torso='nature' needs frames"),
        ("CartPole-v1", {"env_kwargs": {"bad": 1}}, "CartPole-v1 takes no keyword argument 'bad'"),
    ],
)
def test_the_env_is_checked_against_a_config_where_envs_are_made(task, fields, match):
    """`Config.validate` checks values alone; whether the env takes them is `checked_spaces`'s to say."""
    config = Config.for_task(task, **fields)
    with pytest.raises(ConfigError, match=match):
        checked_spaces(config)
    assert checked_spaces(Config.for_task(task)).n_actions == 2
