"""The Python API, `from dqfd_bc_keras import DQfD`, used as a user's script would use it: a preset,
env objects (a class of our own, a third party's made by gym.make), a callable expert, callbacks,
save → load → learn more, predict, and the same metrics as train.py."""

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from dqfd_bc_keras import DQfD
from dqfd_bc_keras.config import QUICK
from dqfd_bc_keras.errors import ConfigError, DqfdWarning
from dqfd_bc_keras.evaluation import EvalResult, evaluate, load_policy
from dqfd_bc_keras.records import EpisodeRow, EvalRow
from dqfd_bc_keras.seeds import EVAL_SEED
from toy_envs import Chain

REPO = Path(__file__).resolve().parents[1]
TINY = {"pretrain_steps": 10, "bc_epochs": 2, "bc_refit_epochs": 1, "demo_episodes": 2, "eval_every": 100,
        "eval_episodes": 2, "final_eval_episodes": 2, "replay_capacity": 2000, "demo_capacity": 5000}


def walk_right(obs):
    return 1


def test_the_same_metrics_as_train_py(tmp_path):
    """DQfD(preset, seed, QUICK's fields).learn(N) gives train.py --quick's metrics.csv, wall time aside."""
    fields = {key: value for key, value in QUICK.items() if key != "total_steps"}
    model = DQfD("cartpole", seed=0, **fields).learn(QUICK["total_steps"])
    done = subprocess.run([sys.executable, "train.py", "--quick", "--quiet", "--seed", "0", "--out", tmp_path / "run"],
                          cwd=REPO, capture_output=True, text=True, timeout=300,
                          env={**os.environ, "PYTHONPATH": str(REPO)})
    assert done.returncode == 0, done.stderr
    with open(tmp_path / "run" / "metrics.csv") as file:
        expected = [{k: v for k, v in row.items() if k != "wall_time"} for row in csv.DictReader(file)]
    ours = [{k: "" if v is None else str(v) for k, v in row.to_row().items() if k != "wall_time"}
            for row in model.state.metrics]
    assert ours == expected and len(ours) > 1
    assert json.loads((tmp_path / "run" / "config.json").read_text())["expert"] == model.config.expert == "imperfect"


def test_an_env_object_a_callable_expert_callbacks_save_load(tmp_path):
    """An env with no registered id, demonstrated by a Python function; a callback stops training;
    save warns once, evaluate.py's loader reads the run, load(env=...) learns more."""
    events = []

    def stop_at_second_episode(row):
        events.append(row)
        return sum(isinstance(r, EpisodeRow) for r in events) < 2

    model = DQfD(Chain(), walk_right, max_steps=20, seed=1, **TINY)
    model.learn(300, callback=stop_at_second_episode)
    assert [type(r) for r in events].count(EpisodeRow) == 2 and isinstance(events[0], EvalRow)
    assert model.learner.interactions < 300
    assert model.config.expert == "python callable walk_right"
    assert model.predict(np.eye(5, dtype=np.float32)[0]) in (0, 1)
    assert model.predict(np.eye(5, dtype=np.float32)).shape == (5,)

    with pytest.warns(DqfdWarning) as warned:
        model.save(tmp_path / "chain")
    ours = [w.message for w in warned if isinstance(w.message, DqfdWarning)]
    assert len(ours) == 1 and "python-Chain" in str(ours[0]) and "python callable walk_right" in str(ours[0])
    config = json.loads((tmp_path / "chain" / "config.json").read_text())
    summary = json.loads((tmp_path / "chain" / "demonstrations.json").read_text())
    assert config["expert"] == summary["expert"] == "python callable walk_right" and summary["source"] == "recorded"
    assert (tmp_path / "chain" / "complete.json").is_file()
    policy, settings = load_policy(tmp_path / "chain")  # what evaluate.py plays
    expected = evaluate(policy, settings.task, 3, EVAL_SEED, settings.timeout, settings.max_steps, settings.env_kwargs)
    assert model.evaluate(3) == expected

    again = DQfD.load(tmp_path / "chain", env=Chain())
    steps = int(again.learner.interaction.env_steps.numpy())
    again.learn(100)
    assert again.state.metrics[-1].env_step >= steps + 100 - 20
    assert isinstance(again.evaluate(2), EvalResult)


def test_a_third_party_env_instance_and_predict_on_what_it_gives():
    """gym.make's instance keeps its id and kwargs; predict takes its raw observations (Discrete states)."""
    env = gym.make("FrozenLake-v1", is_slippery=False)
    model = DQfD(env, lambda obs: 2, expert_loss="margin", **TINY).learn(200)
    assert model.config.task == "FrozenLake-v1" and model.config.env_kwargs == {"is_slippery": False}
    obs, _ = env.reset(seed=0)
    assert isinstance(model.predict(obs), int)
    assert model.predict(np.array([0, 5, 14])).shape == (3,)
    assert model.evaluate(2).task == "FrozenLake-v1"


def test_learn_goes_on_and_out_writes_a_run(tmp_path):
    """With out=, learn trains into a run directory as train.py does; a second learn goes on from it."""
    model = DQfD("cartpole", seed=0, out=tmp_path / "run", **TINY).learn(200)
    first = len(model.state.metrics)
    model.learn(200)
    assert model.config.total_steps == 400 and len(model.state.metrics) > first
    with open(tmp_path / "run" / "metrics.csv") as file:
        assert len(list(csv.DictReader(file))) == len(model.state.metrics)
    assert json.loads((tmp_path / "run" / "config.json").read_text())["total_steps"] == 400
    assert json.loads((tmp_path / "run" / "complete.json").read_text())["env_steps"] == 400


def test_nothing_is_written_unless_asked(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    DQfD("cartpole", **TINY).learn(100)
    assert list(tmp_path.iterdir()) == []


def test_a_bad_keyword_is_a_did_you_mean():
    with pytest.raises(ConfigError, match="unknown Config field 'sigma_sq'; did you mean sigma0_sq"):
        DQfD("cartpole", sigma_sq=1.0)
