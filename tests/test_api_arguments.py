"""What the Python API takes, as a user gives it: `expert=` (the command line's word) for every kind
of demonstrator `demos=` takes; each method's own arguments checked by type and range in one line
naming the argument (Config fields go to Config's own checks); and `predict`'s observations checked
against the env's space, refused in one line that says what was expected."""

import re

import gymnasium as gym
import numpy as np
import pytest
from test_python_api import TINY
from toy_envs import Chain, pole_rule

from dqfd_bc_keras import DQfD, demos
from dqfd_bc_keras.errors import ConfigError


def my_rule(obs):
    return int(obs[3] > 0)


@pytest.fixture(scope="module")
def cartpole():
    return DQfD("cartpole", seed=0, **TINY).learn(100)


@pytest.fixture(scope="module")
def lake():
    """FrozenLake: a Discrete(16) observation, the state's index."""
    return DQfD(gym.make("FrozenLake-v1", is_slippery=False), lambda obs: 2, expert_loss="margin", **TINY).learn(100)


# --- expert= ----------------------------------------------------------------------------------------


@pytest.mark.slow
def test_expert_takes_every_demonstrator_that_demos_takes():
    """A function, a preset expert's name and module:function, as --expert takes them: the same
    demonstrations as given as demos=."""
    for demonstrator, expert in (
        (my_rule, "python callable my_rule"),
        ("strong", "strong"),
        ("toy_envs:pole_rule", "toy_envs:pole_rule"),
    ):
        by_expert = DQfD("cartpole", expert=demonstrator, **TINY)
        by_demos = DQfD("cartpole", demonstrator, **TINY)
        assert by_expert.config.expert == by_demos.config.expert == expert
        assert (by_expert.dataset is None) == (by_demos.dataset is None)  # a callable is recorded at once
    recorded = DQfD("cartpole", expert=my_rule, **TINY).dataset
    assert np.array_equal(recorded.actions, (recorded.obs[:, 3] > 0).astype(recorded.actions.dtype))
    model = DQfD("cartpole", expert="strong", **{**TINY, "demo_episodes": 1}).learn(50)
    assert int(model.learner.agent.replay.demo_size.numpy()) > 0


def test_expert_refuses_demonstrations_and_a_second_demonstrator(tmp_path):
    data = demos.record("CartPole-v1", pole_rule, episodes=1, seed=0)
    for given, message in (
        ({"demos": "strong", "expert": my_rule}, "DQfD(demos='strong', expert=<function my_rule"),
        ({"expert": "d.npz"}, "DQfD(expert='d.npz'): expert is who demonstrates"),
        ({"expert": "minari:cartpole/push-v0"}, "demonstrations themselves are given as demos="),
        ({"expert": data}, "DQfD(expert=DemoDataset("),
        (
            {"expert": 5},
            "DQfD(expert=5): expected a preset expert's name, module:function, a .keras model or a "
            "function obs → action, not an int",
        ),
    ):
        with pytest.raises(ConfigError, match=re.escape(message)):
            DQfD("cartpole", **given, **TINY)
    with pytest.raises(ConfigError, match="give one$"):
        DQfD("cartpole", "strong", expert="imperfect", **TINY)


# --- each method's own arguments ------------------------------------------------------------------


@pytest.mark.slow
def test_the_methods_check_their_arguments(cartpole, tmp_path):
    """Wrong types and ranges are one line naming the argument, and change nothing: the model
    keeps its step count, and no file is written."""
    obs = np.zeros(4, np.float32)
    steps = cartpole.num_timesteps
    refused = [
        (lambda: cartpole.learn("100"), "learn(total_timesteps='100'): expected an int ≥ 1, not a str"),
        (lambda: cartpole.learn(100.0), "learn(total_timesteps=100.0): expected an int ≥ 1, not a float"),
        (lambda: cartpole.learn(True), "learn(total_timesteps=True): expected an int ≥ 1, not a bool"),
        (lambda: cartpole.learn(-5), "learn(total_timesteps=-5): expected an int ≥ 1"),
        (lambda: cartpole.learn(10, callback=5), "learn(callback=5): expected a function of each row or a list"),
        (lambda: cartpole.learn(10, callback=[print, "x"]), "learn(callback='x'): expected a function"),
        (lambda: cartpole.learn(10, progress_bar="yes"), "learn(progress_bar='yes'): expected True or False"),
        (lambda: cartpole.predict(obs, deterministic="no"), "predict(deterministic='no'): expected True or False"),
        (lambda: cartpole.predict(obs, deterministic=False), "predict(deterministic=False): DQfD's policy is"),
        (lambda: cartpole.evaluate("3"), "evaluate(episodes='3'): expected an int ≥ 1, not a str"),
        (lambda: cartpole.evaluate(0), "evaluate(episodes=0): expected an int ≥ 1"),
        (lambda: cartpole.evaluate(2, seed=-1), "evaluate(seed=-1): expected an int in [0, 2147483647]"),
        (lambda: cartpole.evaluate(2, seed=1.5), "evaluate(seed=1.5): expected an int in [0, 2147483647], not a float"),
        (lambda: cartpole.save(5), "save(path=5): expected a path (str or pathlib.Path), not an int"),
        (lambda: cartpole.save(""), "save(path=''): expected a path (str or pathlib.Path), not an empty path"),
        (lambda: DQfD.load(None), "DQfD.load(path=None): expected a path (str or pathlib.Path), not a NoneType"),
        (lambda: DQfD.load(tmp_path, resume="yes"), "DQfD.load(resume='yes'): expected True or False, not a str"),
        (lambda: DQfD("cartpole", out=3, **TINY), "DQfD(out=3): expected a path (str or pathlib.Path), not an int"),
    ]
    for call, message in refused:
        with pytest.raises(ConfigError, match="^" + re.escape(message)):
            call()
    assert cartpole.num_timesteps == steps and list(tmp_path.iterdir()) == []
    assert cartpole.learn(np.int64(20)).num_timesteps == steps + 20  # a NumPy integer is an int
    assert len(cartpole.evaluate(np.int64(1), seed=np.int32(3)).lengths) == 1


def test_config_fields_given_as_keywords_reach_configs_checks():
    """DQfD's keywords are Config's fields, checked by Config where it is made (its ranges here)."""
    with pytest.raises(ConfigError, match="batch_size"):
        DQfD("cartpole", batch_size=0)
    with pytest.raises(ConfigError, match="gamma"):
        DQfD("cartpole", gamma=1.5)


# --- predict's observations ---------------------------------------------------------------------


@pytest.mark.slow
def test_predict_refuses_what_is_not_an_observation_of_the_env(cartpole):
    env = gym.make("CartPole-v1")
    expected = "predict: expected an observation of Box(4,) float32 or a batch of them, got "
    for given, got in (
        (np.zeros(3), "an array of float64 of shape (3,)"),
        (np.zeros((2, 5)), "an array of float64 of shape (2, 5)"),
        (env.reset(seed=0), "a pair (obs, info) as reset() returns it: pass obs alone (obs, info = env.reset())"),
        (None, "None"),
        ("left", "the str 'left'"),
        (np.zeros((0, 4)), "an empty batch"),
        ([np.zeros(4), np.zeros(3)], "a ragged list"),
        (np.array([0.0, np.nan, 0.0, 0.0]), "float64 values that are not finite (NaN or inf)"),
        ({"obs": np.zeros(4)}, "a dict"),
    ):
        with pytest.raises(ConfigError, match="^" + re.escape(expected + got) + "$"):
            cartpole.predict(given)
    obs, _ = env.reset(seed=0)
    action, state = cartpole.predict(obs)
    assert isinstance(action, int) and state is None
    assert cartpole.predict(list(obs))[0] == action  # a list is taken as the array it holds
    batch, _ = cartpole.predict(np.stack([obs, -obs, obs]))
    assert batch.dtype == np.int64 and batch.tolist() == [action, cartpole.predict(-obs)[0], action]


@pytest.mark.slow
def test_predict_takes_a_discrete_state_as_an_integer_in_range(lake):
    expected = "predict: expected an observation of Discrete(16) or a batch of them, got "
    for given, got in (
        (-1, "the state(s) [-1], outside [0, 16)"),
        (16, "the state(s) [16], outside [0, 16)"),
        (np.array([3, 16]), "the state(s) [ 3, 16], outside [0, 16)"),
        (2.7, "float64 values [2.7]; its states are integers"),
        (
            np.eye(16)[3],
            "float64 values [0., 0., 0., 1., 0., 0.]… (a one-hot vector? give the state's index); "
            "its states are integers",
        ),
        (True, "bool values [ True]; its states are integers"),
        (np.zeros((2, 2), np.int64), "an array of int64 of shape (2, 2)"),
    ):
        with pytest.raises(ConfigError, match="^" + re.escape(expected + got) + "$"):
            lake.predict(given)
    states = [0, 5, 14]
    actions, _ = lake.predict(np.array(states))
    assert actions.tolist() == [lake.predict(s)[0] for s in states] and isinstance(lake.predict(np.int64(5))[0], int)
    obs, _ = gym.make("FrozenLake-v1", is_slippery=False).reset(seed=0)
    assert isinstance(lake.predict(obs)[0], int)


@pytest.mark.slow
def test_predict_takes_a_dict_observation_with_its_keys():
    """Chain's {"cell": Discrete(5), "mission": Text, "visits": MultiBinary(5)}: the text is dropped
    in training, and predict takes the dict as the env gives it, or a batch of them."""
    model = DQfD(Chain(observe="dict"), lambda obs: 1, max_steps=20, **TINY).learn(100)
    obs, _ = Chain(observe="dict").reset(seed=0)
    assert isinstance(model.predict(obs)[0], int)
    batch = {"cell": np.array([0, 1]), "mission": ["walk right"] * 2, "visits": np.zeros((2, 5), np.int8)}
    assert model.predict(batch)[0].shape == (2,)
    space = "Dict(cell: Discrete(5), mission: Text, visits: MultiBinary(5))"
    expected = f"predict: expected an observation of {space} or a "
    for given, got in (
        ({"cell": 0}, "batch of them, got a mapping without the key(s) 'visits'"),
        ({**obs, "visits": np.full(5, 2)}, "batch of them, got values [2, 2, 2, 2, 2] that are not bits (0 or 1)"),
        ({**batch, "cell": 0}, "batch of them, got parts of different batch lengths (one, 2)"),
        (np.zeros(6), "batch of them, got an array of float64 of shape (6,)"),
    ):
        with pytest.raises(ConfigError, match="^" + re.escape(expected + got) + "$"):
            model.predict(given)
