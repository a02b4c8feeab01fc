"""`--env module:function`: a function that returns an env (a user's wrapper around one, as
rl-zoo3's `env_wrapper` adds) is a task, as `DQfD(env=factory)` takes one; config.json names it,
so `--resume` and `evaluate.py` in a new process make it again. A class given to `--env` is one line,
before TensorFlow loads, saying how to register it as an id."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import assert_refused, assert_without_tensorflow, call, command

from dqfd_bc_keras.envs.make import get_task, make_task

REPO = Path(__file__).resolve().parents[1]
FACTORY = "toy_envs:wrapped_chain"


def test_a_factory_is_a_task_with_the_limit_its_env_keeps():
    spec = get_task(FACTORY)
    assert spec.name == FACTORY and spec.max_steps is None
    env = make_task(FACTORY, env_kwargs={"size": 3})  # its own keyword arguments, as an env's constructor's
    env.reset(seed=0)
    assert [env.step(1)[1:3] for _ in range(2)] == [(0.0, False), (10.0, True)]  # the user's wrapper: 10× reward
    env.reset(seed=0)
    assert [env.step(0)[2:4] for _ in range(12)][-1] == (False, True)  # its TimeLimit of 12 is the limit


@pytest.mark.slow
def test_a_factory_trains_resumes_and_evaluates_in_a_new_process(tmp_path):
    run = tmp_path / "run"
    args = ["--env", FACTORY, "--env-kwargs", "size=4", "--expert", "toy_envs:go_right", "--quick", "--quiet"]
    done = call("train.py", *args, "--set", "total_steps=100", "--set", "eval_every=100", "--out", run)
    assert done.returncode == 0, done.stderr
    config = json.loads((run / "config.json").read_text())
    assert config["task"] == FACTORY and config["env_kwargs"] == {"size": 4} and config["max_steps"] is None
    assert call("train.py", "--out", run, "--resume", "--quiet").returncode == 0
    env = {**os.environ, "PYTHONPATH": str(REPO / "tests")}
    evaluated = subprocess.run(
        [sys.executable, "evaluate.py", run, "--episodes", "2", "--json"],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
    )
    assert evaluated.returncode == 0, evaluated.stderr
    played = json.loads(evaluated.stdout)
    assert all(r in (0.0, 10.0) for r in played["returns"]) and all(n <= 12 for n in played["lengths"])


def test_a_function_that_is_no_factory_is_one_line(tmp_path):
    (tmp_path / "user_envs.py").write_text("def broken():\n    return 3\n")
    done = call("train.py", "--env", "user_envs:broken", "--quick", "--out", tmp_path / "x", path=[tmp_path])
    assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert "--env user_envs:broken: int is not an env (no reset nor step method)" in done.stderr


@pytest.mark.parametrize(
    "registers, says",
    [
        (
            "",
            'register the class in myenv with gymnasium.register(id="MyEnvClass-v0", entry_point="myenv:MyEnvClass") '
            "and pass --env myenv:MyEnvClass-v0",
        ),
        (
            'gymnasium.register(id="MyEnv-v0", entry_point="myenv:MyEnvClass")\n',
            "myenv registers MyEnv-v0: pass --env myenv:MyEnv-v0",
        ),
    ],
)
def test_env_given_a_class_says_how_to_register_it_before_tensorflow_loads(tmp_path, registers, says):
    (tmp_path / "myenv.py").write_text(
        f"import gymnasium\n\n\nclass MyEnvClass(gymnasium.Env):\n    pass\n\n\n{registers}"
    )
    done = command("train.py", "--env", "myenv:MyEnvClass", "--quick", "--out", tmp_path / "a", path=[tmp_path])
    assert_refused(
        done,
        "train.py: error: argument --env: myenv:MyEnvClass is a class, not an env id: --env takes a "
        f"registered Gymnasium id; {says}",
    )
    assert_without_tensorflow(done)
    assert not (tmp_path / "a").exists()
