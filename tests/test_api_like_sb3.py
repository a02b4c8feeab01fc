"""The Python API in Stable-Baselines3's shape, used as an SB3 user would: `action, _ =
model.predict(obs)`, SB3's own `evaluate_policy` on a model, the attributes SB3 users reach for, and
a list of callbacks (SB3's `BaseCallback` objects are refused in one line, saying why)."""

import re

import gymnasium as gym
import numpy as np
import pytest
from test_python_api import TINY

from dqfd_bc_keras import DQfD
from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.seeds import EVAL_SEED
from dqfd_bc_keras.training.records import EpisodeRow, EvalRow

sb3 = pytest.importorskip("stable_baselines3")
from stable_baselines3.common.callbacks import BaseCallback  # noqa: E402
from stable_baselines3.common.evaluation import evaluate_policy  # noqa: E402
from stable_baselines3.common.vec_env import DummyVecEnv  # noqa: E402

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def model():
    return DQfD("cartpole", seed=0, **TINY).learn(300)


def test_predict_answers_as_sb3s(model):
    """(action, state): an int for one observation, an int64 array for a batch, None as the state;
    SB3's `state` and `episode_start` are taken."""
    obs, _ = gym.make("CartPole-v1").reset(seed=0)
    action, state = model.predict(obs)
    assert isinstance(action, int) and action in (0, 1) and state is None
    actions, state = model.predict(np.stack([obs, obs]), state=None, episode_start=np.ones(2, bool))
    assert actions.shape == (2,) and actions.dtype == np.int64 and actions.tolist() == [action, action]
    assert state is None


def test_sb3s_evaluate_policy_plays_the_model_as_evaluate_does(model):
    """Two envs in SB3's DummyVecEnv, seeded EVAL_SEED and EVAL_SEED + 1 (SB3 seeds env i with seed + i),
    each playing one episode: the episodes of `model.evaluate(2)`, which resets episode i with
    EVAL_SEED + i, in the order they end."""
    vec = DummyVecEnv([lambda: gym.make("CartPole-v1")] * 2)
    vec.seed(EVAL_SEED)
    returns, lengths = evaluate_policy(model, vec, n_eval_episodes=2, return_episode_rewards=True, warn=False)
    ours = model.evaluate(2)
    assert sorted(lengths) == sorted(ours.lengths) and sorted(returns) == sorted(ours.returns)
    mean, std = evaluate_policy(model, model.get_env(), n_eval_episodes=2, warn=False)
    assert 1 <= mean <= 500 and std >= 0


def test_evaluate_policy_on_a_discrete_observation_env():
    """FrozenLake's states through a VecEnv (an int array per step) are a batch of states."""
    lake = DQfD(gym.make("FrozenLake-v1", is_slippery=False), lambda obs: 2, expert_loss="margin", **TINY).learn(100)
    returns, lengths = evaluate_policy(lake, lake.get_env(), n_eval_episodes=2, return_episode_rewards=True, warn=False)
    assert len(returns) == 2 and all(r in (0.0, 1.0) for r in returns) and all(1 <= n <= 100 for n in lengths)


def test_the_attributes_sb3_users_reach_for(model):
    fresh = DQfD("cartpole", seed=0, **TINY)
    assert fresh.num_timesteps == 0 and model.num_timesteps == 300
    plain = gym.make("CartPole-v1")
    assert model.observation_space == plain.observation_space and model.action_space == gym.spaces.Discrete(2)
    env = model.get_env()  # a new env of the task, as evaluate plays it (the README's loop, in Gymnasium's terms)
    obs, _ = env.reset(seed=EVAL_SEED)
    length, done = 0, False
    while not done:
        action, _ = model.predict(obs)
        obs, _, terminated, truncated, _ = env.step(action)
        length, done = length + 1, terminated or truncated
    assert length == model.evaluate(1).lengths[0]
    assert model.num_timesteps == 300  # stepping get_env's env is not training
    lake = DQfD(gym.make("FrozenLake-v1", is_slippery=False), lambda obs: 2, expert_loss="margin", **TINY)
    assert lake.get_env().observation_space == lake.observation_space == gym.spaces.Discrete(16)  # not one-hot


def test_a_list_of_callbacks_each_sees_every_row_and_any_false_stops():
    seen_first, seen_second = [], []

    def first(row):
        seen_first.append(row)

    def second(row):
        seen_second.append(row)
        return sum(isinstance(r, EpisodeRow) for r in seen_second) < 2  # False at the second episode

    model = DQfD("cartpole", seed=0, **TINY).learn(2_000, callback=[first, second])
    assert seen_first == seen_second and isinstance(seen_first[0], EvalRow)
    assert [type(r) for r in seen_first].count(EpisodeRow) == 2 and len(model.state.metrics) == 2
    assert model.num_timesteps == seen_first[-1].env_step < 2_000


def test_sb3s_callback_objects_are_refused_saying_why():
    class Mine(BaseCallback):
        def _on_step(self) -> bool:
            return True

    model = DQfD("cartpole", seed=0, **TINY)
    message = "learn(callback=Mine(...)): Stable-Baselines3's callbacks are called at every env step"
    for callback in (Mine(), [print, Mine()]):
        with pytest.raises(ConfigError, match="^" + re.escape(message)):
            model.learn(100, callback=callback)
    assert model.num_timesteps == 0 and model.learner is None
