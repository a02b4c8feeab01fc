"""Atari through train.py and evaluate.py (answered in this process): evaluation's step limit counts
the agent's steps as training's does; plain DQN needs no D_demo, a method with demonstrations does;
the console's RAM trains as a 128-byte vector with the no-op starts and the frame skip kept; an
observation that is not taken is one line. (The wrappers themselves: tests/test_atari.py.)"""

import json

import pytest
from helpers import assert_refused, call, command

from dqfd_bc_keras.envs.make import make_task

PONG = "ale_py:ALE/Pong-v5"


TINY_PONG = [
    "--quick",
    "--max-steps",
    "50",
    "--set",
    "total_steps=60",
    "--set",
    "eval_every=60",
    "--set",
    "eval_episodes=1",
    "--set",
    "final_eval_episodes=1",
    "--set",
    "pretrain_steps=4",
    "--set",
    "batch_size=4",
    "--set",
    "bc_epochs=1",
    "--set",
    "demo_episodes=1",
]
"""A run of a few seconds whose greedy episodes end at 50 agent steps: Pong cannot end a game in 50."""


@pytest.mark.slow
def test_atari_evaluation_plays_max_steps_agent_steps_and_plain_dqn_needs_no_demo_capacity(tmp_path):
    # demo_capacity=10 is below the limit 50: sized D_demo only for a method with demonstrations.
    done = call(
        "train.py",
        "--env",
        PONG,
        "--expert-loss",
        "none",
        *TINY_PONG,
        "--set",
        "demo_capacity=10",
        "--out",
        tmp_path / "a",
    )
    assert done.returncode == 0, done.stderr
    result = json.loads((tmp_path / "a" / "eval.json").read_text())
    assert result["lengths"] == [50]  # not 50 emulator frames (about 12 agent steps)
    done = call("evaluate.py", tmp_path / "a", "--episodes", "2", "--max-steps", "30")
    assert done.returncode == 0, done.stderr
    assert "length 30.0 steps on average" in done.stdout


@pytest.mark.slow
def test_a_method_with_demonstrations_still_needs_demo_capacity_for_an_episode(tmp_path):
    done = command("train.py", "--env", PONG, *TINY_PONG, "--set", "demo_capacity=10", "--out", tmp_path / "a")
    assert_refused(done, "error: demo_capacity must be ≥ the episode limit 50, got 10")
    assert not (tmp_path / "a").exists()


@pytest.mark.slow
def test_atari_ram_trains_on_a_128_byte_vector_with_the_step_limit_in_agent_steps(tmp_path):
    (tmp_path / "ram_rules.py").write_text("def fire(obs):\n    return 1\n")
    done = call(
        "train.py",
        "--env",
        PONG,
        "--env-kwargs",
        'obs_type="ram"',
        "--expert",
        "ram_rules:fire",
        *TINY_PONG,
        "--out",
        tmp_path / "a",
        path=[tmp_path],
    )
    assert done.returncode == 0, done.stderr
    config = json.loads((tmp_path / "a" / "config.json").read_text())
    assert config["env_kwargs"] == {"obs_type": "ram"}
    assert config["observation"] == {
        "space": "Box(128,) uint8",
        "shape": [128],
        "features": 128,
        "flattened": False,
        "dropped": [],
        "frames": None,
    }
    assert json.loads((tmp_path / "a" / "eval.json").read_text())["lengths"] == [50]


def test_atari_ram_keeps_the_no_op_starts_and_the_frame_skip():
    env = make_task(PONG, max_steps=10, env_kwargs={"obs_type": "ram"})
    obs, info = env.reset(seed=0)
    assert obs.shape == (128,) and 1 <= info["noops"] <= 30
    for _ in range(10):
        obs, _, terminated, truncated, step_info = env.step(0)
    assert truncated and not terminated and obs.shape == (128,)
    assert step_info["episode_frame_number"] == info["noops"] + 4 * 10


@pytest.mark.parametrize(
    "kwargs, says",
    [
        (
            ['obs_type="ram"', "frame_stack=2"],
            "error: --env-kwargs frame_stack: not with obs_type='ram', which observes the console's 128 bytes, "
            "not frames",
        ),
        (
            ['obs_type="rgb"'],
            "error: --env-kwargs obs_type: expected 'grayscale' (the screen as frames) or 'ram' (the console's "
            "128 bytes), got 'rgb'",
        ),
    ],
)
def test_an_atari_observation_that_is_not_taken_is_one_line(tmp_path, kwargs, says):
    assert_refused(
        command("train.py", "--env", PONG, "--env-kwargs", *kwargs, "--quick", "--out", tmp_path / "a"), says
    )
    assert not (tmp_path / "a").exists()
