"""Envs that do not speak the Gymnasium API exactly: a reward given as `np.array([r])`, and an env
written for gym 0.21 (`reset` without a seed returning the observation alone, a 4-tuple `step`)
are adapted where the env is made; a reward of several values is one line."""

import json
import re

import pytest
from helpers import call
from toy_envs import LegacyChain, OldApiChain

from dqfd_bc_keras import DQfD
from dqfd_bc_keras.envs.make import make_plain_env, make_task
from dqfd_bc_keras.errors import ConfigError

OLD = "toy_envs:ToyOldApiChain-v0"
QUICK = ["--quick", "--quiet", "--set", "total_steps=100", "--set", "eval_every=100"]


def test_an_old_api_env_steps_as_the_gymnasium_api_says():
    env = make_plain_env(OLD)
    obs, info = env.reset(seed=3)
    assert obs.tolist() == [1, 0, 0, 0, 0] and info == {} and env.unwrapped.seeded == [3]  # seed(3), reset()
    steps = [env.step(1) for _ in range(4)]
    assert [type(s[1]) for s in steps] == [float] * 4 and [s[1] for s in steps] == [0.0, 0.0, 0.0, 1.0]
    assert [(s[2], s[3]) for s in steps] == [(False, False)] * 3 + [(True, False)]  # done at the goal: terminated
    env.reset(seed=4)
    ends = [env.step(0)[2:4] for _ in range(8)]  # never moves: the env cuts it after 8 steps
    assert ends == [(False, False)] * 7 + [(False, True)]  # info["TimeLimit.truncated"]: truncated


@pytest.mark.slow
def test_an_old_api_env_trains_and_evaluates_from_the_command_line(tmp_path):
    done = call("train.py", "--env", OLD, "--expert", "toy_envs:go_right", *QUICK, "--out", tmp_path / "run")
    assert done.returncode == 0, done.stderr
    result = json.loads((tmp_path / "run" / "eval.json").read_text())
    assert all(n in range(4, 9) for n in result["lengths"])  # the goal in 4 steps, or cut at the env's 8
    evaluated = call("evaluate.py", tmp_path / "run", "--episodes", 2, "--json")
    assert evaluated.returncode == 0, evaluated.stderr
    assert all(n in range(4, 9) for n in json.loads(evaluated.stdout)["lengths"])


@pytest.mark.slow
def test_an_old_api_env_object_from_python_learns_and_predicts():
    tiny = {"total_steps": 100, "pretrain_steps": 5, "eval_every": 100, "bc_epochs": 1, "demo_episodes": 3}
    model = DQfD(OldApiChain(), lambda obs: 1, max_steps=10, **tiny)
    assert model.dataset.rewards.sum() == model.config.demo_episodes  # np.array([1.]) each goal, summed as floats
    played = model.learn().evaluate(2)
    assert set(played.returns) <= {0.0, 1.0} and all(n <= 8 for n in played.lengths)  # the goal, or cut at 8
    action, _ = model.predict(OldApiChain().reset())
    assert action in (0, 1)


@pytest.mark.slow
def test_an_old_api_env_that_is_no_gymnasium_env_learns_from_python_and_the_command_line(tmp_path):
    """A class of one's own (or of the old `gym` package) with reset, step and Gymnasium's spaces:
    its instance, the class itself as a factory, and `--env module:function` returning one."""
    tiny = {"total_steps": 100, "pretrain_steps": 5, "eval_every": 100, "bc_epochs": 1, "demo_episodes": 2}
    for env in (LegacyChain(), LegacyChain):
        model = DQfD(env, lambda obs: 1, max_steps=10, **tiny)
        assert model.dataset.rewards.sum() == 2.0  # the goal in each demonstrated episode, np.array([1.]) as 1.0
        played = model.learn().evaluate(2)
        assert set(played.returns) <= {0.0, 1.0} and all(n <= 10 for n in played.lengths)  # the goal, or cut at 10
    args = ["--env", "toy_envs:legacy_chain", "--max-steps", 10, "--expert", "toy_envs:go_right", *QUICK]
    done = call("train.py", *args, "--out", tmp_path / "run")
    assert done.returncode == 0, done.stderr
    with pytest.raises(ConfigError, match="env: Unsuitable is not an env .no gymnasium.spaces as its spaces."):
        DQfD(type("Unsuitable", (), {"reset": lambda self: 0, "step": lambda self, a: 0})(), lambda obs: 0)


def test_a_reward_of_several_values_is_one_line(tmp_path):
    env = make_task("toy_envs:ToyVectorReward-v0")
    env.reset(seed=0)
    with pytest.raises(ConfigError, match=re.escape("returned a reward of shape (2,) (float64): expected a number")):
        env.step(1)
    env_args = ["--env", "toy_envs:ToyVectorReward-v0", "--expert", "toy_envs:go_right"]
    done = call("train.py", *env_args, *QUICK, "--out", tmp_path / "run")
    assert done.returncode == 2 and done.stderr.strip().count("\n") == 0, done.stderr
    assert "reward of shape (2,)" in done.stderr
    with pytest.raises(ConfigError, match=re.escape("reward of shape (2,)")):
        DQfD("toy_envs:ToyVectorReward-v0", "toy_envs:go_right", total_steps=100, demo_episodes=1).learn()
