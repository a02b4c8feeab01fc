"""Any Gymnasium env through `--env ID`: a user's own env trains end to end, unsupported spaces
are refused in one line, demonstrators come from a rule or a saved model."""

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from dqfd_bc_keras import demos
from dqfd_bc_keras.config import Config, EnvConfig
from dqfd_bc_keras.envs import env_task, get_task, make_plain_env, make_task, task_slug
from dqfd_bc_keras.errors import ConfigError, DqfdError
from dqfd_bc_keras.evaluation import evaluate, load_policy
from dqfd_bc_keras.experiments.suites import SUITES, arm, on_task

REPO = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), str(REPO / "tests")])}
CHAIN = "toy_envs:ToyChain-v0"
SUPPORTED = "supported: a flat Box observation (one dimension) and a Discrete action space"


def run(*args, timeout=300):
    return subprocess.run([sys.executable, *map(str, args)], capture_output=True, text=True, timeout=timeout,
                          cwd=REPO, env=ENV)


def one_line_error(done, message):
    assert done.returncode == 2, done.stdout + done.stderr
    assert message in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr


def test_a_user_env_is_a_task_with_its_own_limit_threshold_and_no_shaping():
    spec = get_task(CHAIN)
    assert (spec.env_id, spec.family, spec.max_steps, spec.solved_return) == (CHAIN, None, 20, 1.0)
    assert spec.fall_penalty is None and spec.goal_reward is None
    env = make_task(CHAIN, timeout="naive")
    env.reset(seed=0)
    flags = [env.step(0)[2:4] for _ in range(20)]  # never reaches the end: the limit ends it
    assert flags[-1] == (True, False) and all(f == (False, False) for f in flags[:-1])
    env = make_task(CHAIN, timeout="bootstrap", max_steps=3)
    env.reset(seed=0)
    assert [env.step(1)[1:4] for _ in range(3)] == [(0.0, False, False), (0.0, False, False), (0.0, False, True)]
    assert make_plain_env(CHAIN).spec.max_episode_steps == 20


def test_the_generic_preset_is_written_to_config_json_and_overridable():
    config = Config.for_task(CHAIN, total_steps=123)
    assert isinstance(config, EnvConfig)
    assert (config.task, config.total_steps, config.demo_episodes, config.early_stop_window) == (CHAIN, 123, 10, 0)
    assert Config.from_dict(json.loads(json.dumps(config.to_dict()))) == config
    assert config.with_overrides(["eval_every=7"]).eval_every == 7


@pytest.mark.parametrize("env_id", ["toy_envs:ToyImage-v0", "toy_envs:ToyDict-v0", "Pendulum-v1"])
def test_unsupported_spaces_are_refused_by_name(env_id):
    with pytest.raises(ConfigError, match=re.escape(SUPPORTED)):
        env_task(env_id)


def test_an_env_without_a_time_limit_needs_max_steps():
    with pytest.raises(ConfigError, match="has no time limit of its own: set one with --set max_steps=N"):
        Config.for_task("toy_envs:ToyChainNoLimit-v0")
    config = Config.for_task("toy_envs:ToyChainNoLimit-v0", max_steps=9)
    assert config.limit == 9
    assert make_plain_env(config.task, max_steps=9).spec.max_episode_steps == 9


def test_rule_demonstrator_records_on_any_env():
    data = demos.record(CHAIN, "toy_envs:go_right", episodes=2)
    assert (data.actions == 1).all() and len(data) == 8 and data.meta.episode_returns == [1.0, 1.0]
    assert data.meta.task == data.meta.env_id == CHAIN
    noisy = demos.record(CHAIN, "toy_envs:go_right", episodes=3, epsilon=1.0, seed=0)
    assert set(noisy.actions) == {0, 1}


@pytest.mark.parametrize("spec, message", [
    ("imperfect", "has no scripted imperfect expert"),
    ("toy_envs:nothing", "cannot import it (AttributeError"),
    ("no_such_module:rule", "cannot import it (ModuleNotFoundError"),
    ("toy_envs:NOT_CALLABLE", "NOT_CALLABLE is not callable"),
    ("toy_envs:out_of_range", "returned 7, not an action in [0, 2)"),
    ("best", "expert='best' is none of strong, imperfect, module:function or a .keras model file"),
])
def test_bad_demonstrators_are_named(spec, message):
    with pytest.raises(ConfigError) as error:
        demos.record(CHAIN, spec, episodes=1)
    assert message in str(error.value)


def test_a_saved_model_demonstrates_its_greedy_policy():
    model = REPO / "models" / "cartpole" / "q_network.keras"
    data = demos.record("cartpole", str(model), episodes=3, seed=50)
    greedy = evaluate(load_policy(model)[0], "cartpole", 3, seed=50)
    assert data.meta.plain_returns == greedy.returns and data.meta.expert == str(model)
    with pytest.raises(DqfdError, match="model expects 4 observation features, task mountaincar gives 2"):
        demos.record("mountaincar", str(model), episodes=1)


def test_suites_move_to_any_env_with_their_settings():
    moved = on_task(SUITES["quick"], CHAIN, ["expert=toy_envs:go_right"])
    assert [a.task for a in moved] == [CHAIN, CHAIN]
    config = moved[0].config(0)
    assert config.total_steps == 600 and config.expert == "toy_envs:go_right"
    assert moved[0].name == "toy_envs-ToyChain-v0-bootstrap-bayes-" + moved[0].label
    assert moved[0].name.endswith("-toy_envs-go_right")  # one path component, whatever the values
    assert "/" not in on_task(SUITES["quick"], None, ["expert=models/cartpole/q_network.keras"])[0].name
    assert "/" not in task_slug("ALE/Pong-v5") and ":" not in task_slug(CHAIN)
    with pytest.raises(ConfigError, match="expert_loss is an arm's own"):
        on_task(SUITES["quick"], CHAIN, ["expert_loss=ce"])
    assert on_task([arm("cartpole", "bootstrap", "ce"), arm("cartpole-200", "bootstrap", "ce")], "acrobot") == \
        [arm("acrobot", "bootstrap", "ce")]


def test_train_and_evaluate_a_user_env_end_to_end(tmp_path):
    out = tmp_path / "chain"
    done = run("train.py", "--env", CHAIN, "--expert", "toy_envs:go_right", "--demo-episodes", 20, "--quick", "--quiet", "--out", out)
    assert done.returncode == 0, done.stderr
    config = json.loads((out / "config.json").read_text())
    assert config["task"] == CHAIN and config["expert"] == "toy_envs:go_right"
    result = json.loads((out / "eval.json").read_text())
    assert result["env_id"] == CHAIN and result["mean_return"] == 1.0  # learned to walk right
    done = run("evaluate.py", out, "--episodes", "3", "--json")
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["returns"] == [1.0, 1.0, 1.0]


@pytest.mark.parametrize("args, message", [
    (["train.py", "--env", "toy_envs:ToyImage-v0"], SUPPORTED),
    (["train.py", "--env", "Pendulum-v1"], SUPPORTED),
    (["train.py", "--env", "toy_envs:ToyDict-v0"], SUPPORTED),
    (["train.py", "--env", "NoSuchEnv-v0"], "unknown task 'NoSuchEnv-v0'"),
    (["train.py", "--env", CHAIN, "--task", "cartpole"], "not allowed with argument"),
    (["train.py", "--env", CHAIN], "has no scripted imperfect expert"),
    (["-m", "dqfd_bc_keras.demos", "record", "--env", "Pendulum-v1", "--expert", "strong", "--out", "x.npz"],
     SUPPORTED),
    (["evaluate.py", "models/cartpole", "--env", "Pendulum-v1"], SUPPORTED),
    (["-m", "dqfd_bc_keras.experiments", "run", "quick", "--env", "Pendulum-v1", "--out", "x"], SUPPORTED),
])
def test_unsupported_envs_are_refused_in_one_line_with_exit_2(args, message, tmp_path):
    one_line_error(run(*args[:1], *args[1:], *(["--quick", "--out", tmp_path / "r"] if args[0] == "train.py" else [])),
                   message)
