"""Env kwargs that must reach the env as they were written: a tuple stays a tuple from the command
line or the Python API to `gym.make`, through config.json, `--resume` and `evaluate.py`. Each
`--env-kwargs` value is read as JSON, then a Python literal, then a word, never passed on as a string
that would be silently truthy (`is_slippery=FALSE` is one line, before TensorFlow loads)."""

import json
from argparse import ArgumentTypeError

import gymnasium as gym
import pytest
from helpers import assert_refused, assert_without_tensorflow, call, command, left_in

from dqfd_bc_keras import DQfD
from dqfd_bc_keras.commands import cli
from dqfd_bc_keras.commands.cli import env_kwarg
from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.envs.kwargs import as_json, as_python
from dqfd_bc_keras.errors import ConfigError

GREY = {"type": "GrayscaleObservation", "stack_size": 4, "weights": [0.2989, 0.587, 0.114]}
"""highway-env's documented image observation, less its `observation_shape`."""
SHORT = ["--quick", "--quiet", "--max-steps", 8, "--set", "total_steps=40", "--set", "eval_every=40"]
SHORT += ["--set", "pretrain_steps=5", "--set", "demo_episodes=1", "--set", "eval_episodes=1"]
SHORT += ["--set", "final_eval_episodes=1"]
TINY = {"demo_episodes": 1, "pretrain_steps": 5, "bc_epochs": 1, "eval_every": 20, "eval_episodes": 1}
TINY |= {"final_eval_episodes": 1, "replay_capacity": 100, "demo_capacity": 500}


def test_a_tuple_on_the_command_line_is_recorded_as_one_and_made_as_one():
    assert cli.env_kwarg("observation_shape=84,84") == ("observation_shape", {"__tuple__": [84, 84]})
    assert cli.env_kwarg("observation_shape=(84, 84)") == ("observation_shape", {"__tuple__": [84, 84]})
    assert cli.env_kwarg("observation_shape=[84, 84]") == ("observation_shape", [84, 84])  # JSON: a list
    nested = cli.env_kwarg("config={'observation': {'observation_shape': (84, 84)}, 'lanes': [1, (2,)]}")[1]
    assert nested == {"observation": {"observation_shape": {"__tuple__": [84, 84]}}, "lanes": [1, {"__tuple__": [2]}]}
    assert as_python(nested) == {"observation": {"observation_shape": (84, 84)}, "lanes": [1, (2,)]}
    assert as_python(json.loads(json.dumps(nested))) == as_python(nested)  # what config.json gives back


def test_a_config_from_python_records_a_tuple_so_that_its_json_gives_it_back():
    config = Config.for_task("CartPole-v1", env_kwargs={"sutton_barto_reward": False, "shape": (3, 4)})
    assert config.env_kwargs == {"sutton_barto_reward": False, "shape": {"__tuple__": [3, 4]}}
    again = Config.from_dict(json.loads(json.dumps(config.to_dict())))
    assert as_python(again.env_kwargs)["shape"] == (3, 4) and again == config
    with pytest.raises(ConfigError, match="env_kwargs must be a JSON object of keyword arguments"):
        Config.for_task("CartPole-v1", env_kwargs={"shape": {1, 2}})
    assert as_json({"a": (1, [2, (3,)])}) == {"a": {"__tuple__": [1, [2, {"__tuple__": [3]}]]}}


@pytest.mark.slow
def test_highway_image_observation_from_the_command_line_trains_resumes_and_evaluates(tmp_path):
    """highway-env's `observation_shape` must be a tuple (`(stack,) + shape`): given as a Python
    literal it reaches the env as one in train.py, in --resume and in evaluate.py, which rebuild it
    from config.json; its (4, 84, 84) stack is read channels-first."""
    pytest.importorskip("highway_env")
    config = json.dumps({"observation": GREY, "duration": 4}).replace("}", ', "observation_shape": (84, 84)}', 1)
    rules = tmp_path / "hw_rules.py"
    rules.write_text("def idle(obs):\n    return 1\n")
    env = ["--env", "highway_env:highway-fast-v0", "--env-kwargs", f"config={config}", "--expert", "hw_rules:idle"]
    done = call("train.py", *env, *SHORT, "--set", "checkpoint_every=20", "--out", tmp_path / "run", path=[tmp_path])
    assert done.returncode == 0, done.stderr
    saved = json.loads((tmp_path / "run" / "config.json").read_text())
    assert saved["env_kwargs"]["config"]["observation"]["observation_shape"] == {"__tuple__": [84, 84]}
    assert saved["observation"]["shape"] == [4, 84, 84]
    assert saved["observation"]["frames"]["shape"] == [84, 84, 4] and saved["observation"]["frames"]["channels_first"]
    resumed = call("train.py", "--out", tmp_path / "run", "--resume", "--quiet", path=[tmp_path])
    assert resumed.returncode == 0, resumed.stderr
    assert json.loads((tmp_path / "run" / "config.json").read_text())["env_kwargs"] == saved["env_kwargs"]
    evaluated = call("evaluate.py", tmp_path / "run", "--episodes", 1, "--json", path=[tmp_path])
    assert evaluated.returncode == 0, evaluated.stderr
    assert json.loads(evaluated.stdout)["lengths"][0] <= 8

    listed = json.dumps({"observation": {**GREY, "observation_shape": [84, 84]}})
    as_list = call("train.py", *env[:3], f"config={listed}")
    assert as_list.returncode == 2 and len(as_list.stderr.strip().splitlines()) == 1, as_list.stderr
    assert "a tuple is written as a Python literal: (84, 84), not [84, 84]" in as_list.stderr


@pytest.mark.slow
def test_highway_image_observation_from_python_keeps_its_tuple():
    pytest.importorskip("highway_env")
    env = gym.make("highway_env:highway-fast-v0", config={"observation": {**GREY, "observation_shape": (84, 84)}})
    model = DQfD(env, lambda obs: 1, max_steps=8, **TINY)
    assert model.config.task == "highway_env:highway-fast-v0"
    assert model.config.env_kwargs["config"]["observation"]["observation_shape"] == {"__tuple__": [84, 84]}
    obs, _ = env.reset(seed=0)
    assert obs.shape == (4, 84, 84)
    action, _ = model.learn(20).predict(obs)  # the env's own (4, 84, 84), read as the networks read it
    assert action in range(5)


# --- each value as the command line reads it -------------------------------------------------------


@pytest.mark.parametrize(
    "text, value",
    [
        ("is_slippery=False", False),
        ("is_slippery=false", False),
        ("flag=True", True),
        ("flag=true", True),
        ("seed=None", None),
        ("seed=null", None),
        ("n=3", 3),
        ("x=-1.5", -1.5),
        ("x=1e5", 100000.0),
        ("obs_type='ram'", "ram"),
        ('obs_type="ram"', "ram"),
        ("shape=(3, 4)", {"__tuple__": [3, 4]}),  # a tuple, as config.json records it (JSON has none)
        ("shape=[3, 4]", [3, 4]),
        ('config={"lanes_count": 3}', {"lanes_count": 3}),
        ("config={'size': (2, 2)}", {"size": {"__tuple__": [2, 2]}}),
        ("render_mode=rgb_array", "rgb_array"),
        ("obs_type=ram", "ram"),
        ("map_name=8x8", "8x8"),
        ("mode=human-ish", "human-ish"),
        ("path=maps/a.txt", "maps/a.txt"),
        (" key =ram", "ram"),
    ],
)
def test_env_kwargs_values_are_json_then_python_literals_then_words(text, value):
    key, parsed = env_kwarg(text)
    assert key == text.partition("=")[0].strip() and parsed == value and type(parsed) is type(value)


@pytest.mark.parametrize(
    "text, message",
    [
        (
            "config={bad json",
            "config={bad json is not valid JSON (Expecting property name enclosed in double quotes: "
            "line 1 column 2 (char 1))",
        ),
        ("lanes=[1, 2", "lanes=[1, 2 is not valid JSON (Expecting ',' delimiter"),
        ("shape=(3, 4", "shape=(3, 4 is not a valid Python literal (SyntaxError: '(' was never closed"),
        ("name='ram", "name='ram is not a valid Python literal (SyntaxError: unterminated string literal"),
        (
            "is_slippery=FALSE",
            "is_slippery=FALSE is neither JSON nor Python: write is_slippery=false or "
            "is_slippery=False, or is_slippery='\"FALSE\"' for the string",
        ),
        ("seed=none", "seed=none is neither JSON nor Python: write seed=null or seed=None"),
        ("mission=go to the door", "mission=go to the door is neither JSON, a Python literal nor a word"),
        ("x=-fast", "x=-fast is neither JSON, a Python literal nor a word"),
        ("version=1.2.3", "version=1.2.3 is neither JSON, a Python literal nor a word"),
        ("x=", "x= is neither JSON, a Python literal nor a word"),
        ("ids={1, 2}", "ids={1, 2}: a Python set, which JSON cannot hold"),
        ("=3", "expected KEY=VALUE with KEY a Python identifier, got '=3'"),
    ],
)
def test_env_kwargs_refuses_a_value_it_would_otherwise_pass_on_as_a_string(text, message):
    with pytest.raises(ArgumentTypeError) as refused:
        env_kwarg(text)
    assert str(refused.value).startswith(message) and "\n" not in str(refused.value)


@pytest.mark.slow
def test_is_slippery_false_reaches_the_env_and_config_json_as_false(tmp_path):
    out = tmp_path / "run"
    done = call(
        "train.py",
        "--env",
        "FrozenLake-v1",
        "--env-kwargs",
        "is_slippery=False",
        "--expert-loss",
        "none",
        "--quick",
        "--quiet",
        "--set",
        "total_steps=100",
        "--set",
        "eval_every=100",
        "--set",
        "batch_size=16",
        "--out",
        out,
    )
    assert done.returncode == 0, done.stderr
    assert json.loads((out / "config.json").read_text())["env_kwargs"] == {"is_slippery": False}
    assert '"is_slippery": false' in (out / "config.json").read_text()


def test_malformed_env_kwargs_json_is_one_line_before_tensorflow(tmp_path):
    done = command("train.py", "--env", "FrozenLake-v1", "--env-kwargs", "config={bad json", "--out", tmp_path / "run")
    assert_refused(
        done,
        "train.py: error: argument --env-kwargs: config={bad json is not valid JSON (Expecting "
        "property name enclosed in double quotes: line 1 column 2 (char 1)); a string that is not a "
        "word is written as JSON: config='\"...\"'",
    )
    assert_without_tensorflow(done)
    assert left_in(tmp_path) == []
