"""An env object given to the Python API is what the run trains on: its id is used only when the env
made again from it is the same (its spaces, highway-env's config), else a copy of the object; the
limit an object keeps (MiniGrid's `max_steps`) is its limit; frames that are not pixels say so."""

import json

import gymnasium as gym
import pytest
from helpers import call

from dqfd_bc_keras import DQfD
from dqfd_bc_keras.envs.make import task_spaces
from dqfd_bc_keras.envs.objects import PYTHON_ENV_PREFIX
from dqfd_bc_keras.errors import DqfdWarning

TINY = {"demo_episodes": 1, "pretrain_steps": 5, "bc_epochs": 1, "eval_every": 20, "eval_episodes": 1}
TINY |= {"final_eval_episodes": 1, "replay_capacity": 100, "demo_capacity": 500}
GREY = {"type": "GrayscaleObservation", "observation_shape": (84, 84), "stack_size": 4, "weights": [0.3, 0.6, 0.1]}


def test_a_highway_env_configured_after_gym_make_is_trained_on_as_configured():
    """highway-env's own way: `env.unwrapped.configure({...})` then `reset`. Its id makes the
    default (5, 5) kinematics env, so the run trains on copies of the object, and says so."""
    pytest.importorskip("highway_env")
    env = gym.make("highway_env:highway-fast-v0")
    env.unwrapped.configure({"observation": GREY})
    env.reset(seed=0)
    with pytest.warns(DqfdWarning, match=r"highway-fast-v0 made again from its id is not the env given \(observation"):
        model = DQfD(env, lambda obs: 1, max_steps=5, **TINY)
    assert model.config.task.startswith(PYTHON_ENV_PREFIX)
    layout = task_spaces(model.config.task).layout
    assert layout.space == env.observation_space and layout.frames.shape == (84, 84, 4)

    configured = gym.make("highway_env:highway-fast-v0")
    configured.unwrapped.configure({"duration": 3})  # the spaces alike, the config not: still the object
    with pytest.warns(DqfdWarning, match="its config was changed after gym.make"):
        assert DQfD(configured, lambda obs: 1, max_steps=5, **TINY).config.task.startswith(PYTHON_ENV_PREFIX)

    same = gym.make("highway_env:highway-fast-v0")  # untouched: its id, which a later process can make
    assert DQfD(same, lambda obs: 1, max_steps=5, **TINY).config.task == "highway_env:highway-fast-v0"


def test_an_env_whose_spaces_were_changed_after_gym_make_is_trained_on_itself(tmp_path):
    env = gym.make("CartPole-v1")
    env.unwrapped.action_space = gym.spaces.Discrete(3)  # the user's change; its id makes Discrete(2)
    with pytest.warns(DqfdWarning, match=r"action_space Discrete\(3\) given, Discrete\(2\) made"):
        model = DQfD(env, lambda obs: 2, **TINY)
    assert task_spaces(model.config.task).n_actions == 3
    assert model.dataset.actions.max() == 2  # the demonstrations were played on the object's actions


def test_minigrid_made_with_its_own_max_steps_is_its_limit():
    """MiniGrid registers no limit but truncates its episodes itself after `max_steps`: that is the
    run's limit, for the API's object and for `--env-kwargs max_steps=...` alike."""
    pytest.importorskip("minigrid")
    model = DQfD(gym.make("minigrid:MiniGrid-Empty-5x5-v0", max_steps=50), lambda obs: 2, **TINY)
    assert model.config.env_kwargs == {"max_steps": 50} and model.config.limit == 50
    assert DQfD("minigrid:MiniGrid-Empty-5x5-v0", lambda obs: 2, **TINY).config.limit == 100  # its default: 4·5²


@pytest.mark.slow
def test_minigrid_from_the_command_line_takes_its_own_max_steps_as_the_limit(tmp_path):
    pytest.importorskip("minigrid")
    (tmp_path / "turn.py").write_text("def left(obs):\n    return 0\n")  # never reaches the goal
    env = ["--env", "minigrid:MiniGrid-Empty-5x5-v0", "--env-kwargs", "max_steps=6", "--expert", "turn:left"]
    budget = ["--quick", "--quiet", "--set", "total_steps=60", "--set", "eval_every=60"]
    done = call("train.py", *env, *budget, "--out", tmp_path / "run", path=[tmp_path])
    assert done.returncode == 0, done.stderr
    assert json.loads((tmp_path / "run" / "eval.json").read_text())["lengths"] == [6, 6]


def test_minigrid_object_ids_are_not_pixels_when_the_user_says_so():
    """MiniGrid's `ImgObsWrapper` view holds object ids 0–10 but declares a high of 255, so by its
    bounds it is scaled by 1/255; `frame_scale=none` keeps the ids, a Box whose high is 10 is 1/10."""
    pytest.importorskip("minigrid")
    from minigrid.wrappers import ImgObsWrapper

    view = ImgObsWrapper(gym.make("minigrid:MiniGrid-Empty-5x5-v0"))
    assert DQfD(view, lambda obs: 2, **TINY).config.limit == 100  # the wrapped env's own max_steps
    ids = DQfD(view, lambda obs: 2, env_kwargs={"frame_scale": "none"}, **TINY)
    frames = task_spaces(ids.config.task, ids.config.env_kwargs).layout.frames
    assert frames.scale == 1.0 and frames.shape == (7, 7, 3)
    assert task_spaces(ids.config.task).layout.frames.scale == 1 / 255
    obs, _ = view.reset(seed=0)
    assert obs.max() == 8  # the goal's object id (an id, not a brightness)
