"""A run trained on a Python env object (`DQfD(env=<object>)`, saved with `DQfD.save`) read again by
the command line in another process: `evaluate.py` and `train.py --resume` say that the env was a
Python object and how to give it again, as `DQfD.save` warned, not that the task is unknown; and
`evaluate.py --env ID` plays it on a registered id of the same env (and films it there: `--video`),
and `train.py --resume --env ID` and `DQfD.load(path, env="ID")` continue it there, in its own config."""

import json
import shutil
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from helpers import call
from test_python_api import TINY, walk_right
from toy_envs import Chain

from dqfd_bc_keras import DQfD
from dqfd_bc_keras.errors import DqfdWarning
from dqfd_bc_keras.seeds import EVAL_SEED

pytestmark = pytest.mark.slow

TESTS = Path(__file__).resolve().parent


@pytest.fixture(scope="module")
def saved(tmp_path_factory) -> tuple[Path, str, list[float]]:
    """A run of Chain() given as an object, saved; its env id; its greedy returns on 3 episodes."""
    run = tmp_path_factory.mktemp("env-object") / "chain"
    model = DQfD(Chain(), walk_right, max_steps=20, seed=1, **TINY).learn(150)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DqfdWarning)  # what a later process cannot make: said by save
        model.save(run)
    return run, model.config.task, model.evaluate(3).returns


@pytest.fixture
def elsewhere(saved, monkeypatch) -> tuple[Path, str, list[float]]:
    """As another process finds the run: the id registered for the object is not registered there."""
    monkeypatch.delitem(gym.registry, saved[1])
    return saved


def files(run: Path) -> dict[str, bytes]:
    return {str(p.relative_to(run)): p.read_bytes() for p in sorted(run.rglob("*")) if p.is_file()}


def test_evaluate_says_the_env_was_a_python_object_and_how_to_give_it_again(elsewhere):
    run, task, _ = elsewhere
    done = call("evaluate.py", run)
    assert (done.returncode, done.stdout) == (2, "")
    assert done.stderr == (
        f"error: {run / 'config.json'}: trained on a Python env object ({task}), which no other process can "
        "make: evaluate it from Python, DQfD.load(path, env=...).evaluate(), or here with --env ID, a "
        "registered id of the same env\n"
    )


def test_evaluate_plays_it_on_a_registered_id_of_the_same_env(elsewhere):
    run, _, returns = elsewhere
    done = call("evaluate.py", run, "--env", "toy_envs:ToyChainNoLimit-v0", "--episodes", "3", "--json", path=[TESTS])
    assert (done.returncode, done.stderr) == (0, "")
    result = json.loads(done.stdout)
    assert (result["task"], result["returns"]) == ("toy_envs:ToyChainNoLimit-v0", returns)


def test_resume_says_the_env_was_a_python_object_and_changes_nothing(elsewhere):
    run, task, _ = elsewhere
    before = files(run)
    done = call("train.py", "--out", run, "--resume", "--quiet")
    assert done.returncode == 2
    assert done.stderr == (
        f"error: {run / 'config.json'}: trained on a Python env object ({task}), which no other process can "
        "make; give it again: --env ID, a registered id of the same env, or from Python DQfD.load(path, env=...)\n"
    )
    assert files(run) == before


SAME_ENV = "toy_envs:ToyChainNoLimit-v0"
"""A registered id that makes the env the run was trained on (Chain(), its limit the run's own)."""


def test_load_plays_it_on_a_registered_id_of_the_same_env(elsewhere):
    run, task, returns = elsewhere
    model = DQfD.load(run, env=SAME_ENV)
    assert model.config.task == task  # its own config: the id only makes the env
    assert model.evaluate(3).returns == returns


def test_resume_continues_it_on_a_registered_id_of_the_same_env(elsewhere, tmp_path):
    run, task, _ = elsewhere
    copy = tmp_path / "chain"
    shutil.copytree(run, copy)
    config = json.loads((copy / "config.json").read_text())
    done = call("train.py", "--out", copy, "--resume", "--env", SAME_ENV, "--quiet", path=[TESTS])
    assert (done.returncode, done.stderr) == (0, "")
    assert json.loads((copy / "config.json").read_text()) == config  # the same run, in its own config
    assert json.loads((copy / "complete.json").read_text())["env_steps"] >= 150


def test_a_preset_or_an_unknown_id_does_not_stand_in_for_the_object(elsewhere):
    run, task, _ = elsewhere
    before = files(run)
    for env, said in (
        (
            "cartpole",
            f"error: cartpole: a run trained on a Python env object ({task}) is given its env again as a "
            "Gymnasium id that makes the same env (e.g. CartPole-v1, my_package:MyEnv-v0)\n",
        ),
        ("NoSuchEnv-v0", "train.py: error: argument --env: unknown task 'NoSuchEnv-v0'"),
    ):
        done = call("train.py", "--out", run, "--resume", "--env", env, "--quiet")
        assert done.returncode == 2 and done.stderr.startswith(said), done.stderr
    assert files(run) == before


def test_evaluate_films_it_on_a_registered_id_of_the_same_env(tmp_path, monkeypatch):
    """The id given again renders the video; the factory the run was trained on made no frames."""
    iio = pytest.importorskip("imageio.v3")  # moviepy's, as RecordVideo writes with it
    run = tmp_path / "cartpole"
    model = DQfD(lambda: gym.make("CartPole-v1"), walk_right, max_steps=30, seed=1, **TINY).learn(150)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DqfdWarning)
        model.save(run)
    monkeypatch.delitem(gym.registry, model.config.task)  # as another process finds the run
    done = call("evaluate.py", run, "--env", "CartPole-v1", "--episodes", "1", "--video", tmp_path / "videos")
    assert (done.returncode, done.stderr) == (0, f"recorded 1 episode(s) in {tmp_path / 'videos'}\n")
    (video,) = (tmp_path / "videos").glob("*.mp4")
    env = gym.make("CartPole-v1", render_mode="rgb_array")
    env.reset(seed=EVAL_SEED)  # the first episode's reset
    first = env.render()
    frames = iio.imread(video)
    assert frames.shape[1:] == first.shape and len(frames) > 1
    assert np.abs(frames[0].astype(int) - first.astype(int)).mean() < 3  # up to the codec's loss
