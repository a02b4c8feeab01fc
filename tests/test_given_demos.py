"""A run given its demonstrations (`train.py --demos FILE`, `DQfD(env, demos=...)`) records what it
trained on: `config.json`'s `demo_episodes` is the number of episodes the file holds, not the count
an expert would have recorded (the default's, or `--quick`'s 2), and a count that disagrees with
the file is refused in one line."""

from __future__ import annotations

import json

import pytest
from helpers import call

from dqfd_bc_keras import DQfD, demos
from dqfd_bc_keras.errors import ConfigError


@pytest.fixture
def three_episodes(tmp_path):
    """A file of 3 episodes (what a person's 3 played episodes are to training: a dataset of 3)."""
    path = tmp_path / "mine.npz"
    demos.save(demos.record("cartpole", "imperfect", episodes=3, seed=5, max_steps=60), path)
    return path


@pytest.mark.slow
def test_train_records_the_files_episode_count_and_resumes_quick(three_episodes, tmp_path):
    run = tmp_path / "run"
    trained = call("train.py", "--task", "cartpole", "--demos", three_episodes, "--quick", "--quiet", "--out", run)
    assert trained.returncode == 0, trained.stderr
    config = json.loads((run / "config.json").read_text())
    assert config["demo_episodes"] == 3  # --quick's count of episodes to record is 2
    assert config["expert"] == f"demonstrations from {three_episodes} (imperfect)"
    resumed = call("train.py", "--task", "cartpole", "--quick", "--quiet", "--out", run, "--resume")
    assert resumed.returncode == 0, resumed.stderr  # --quick's 2 is no change to a run given its episodes


@pytest.mark.parametrize("flag", [["--demo-episodes", "5"], ["--set", "demo_episodes=2"]])
def test_a_count_the_file_does_not_hold_is_refused(flag, three_episodes, tmp_path):
    answer = call("train.py", "--task", "cartpole", "--demos", three_episodes, *flag, "--out", tmp_path / "run")
    assert answer.returncode == 2 and answer.stderr.count("\n") == 1, answer.stderr
    assert f"--demos {three_episodes} holds 3 episodes, not demo_episodes={flag[1][-1]}" in answer.stderr
    assert not (tmp_path / "run").exists()


def test_the_python_api_records_the_datasets_episode_count(three_episodes):
    assert DQfD("cartpole", demos=three_episodes, total_steps=100).config.demo_episodes == 3
    dataset = demos.load(three_episodes)
    assert DQfD("cartpole", demos=dataset, demo_episodes=3).config.demo_episodes == 3
    with pytest.raises(ConfigError, match="demos holds 3 episodes, not demo_episodes=10"):
        DQfD("cartpole", demos=dataset, demo_episodes=10)
