"""The SB3 MinAtar baseline: MinAtar's network inside SB3's DQN policy (shapes, 0/1 frames fed
unscaled), the schedule taken from rl-zoo3, and the command's evaluation grid and errors."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("stable_baselines3")
pytest.importorskip("minatar")

import gymnasium as gym  # noqa: E402  (after the importorskip guards)
from gymnasium import spaces  # noqa: E402  (after the importorskip guards)
from stable_baselines3.dqn.policies import CnnPolicy  # noqa: E402  (after the importorskip guards)
from torch.nn import functional as F  # noqa: E402  (after the importorskip guards)

from dqfd_bc_keras.errors import ConfigError  # noqa: E402  (after the importorskip guards)
from dqfd_bc_keras.seeds import eval_seed  # noqa: E402  (after the importorskip guards)
from studies.sb3_pixels import MinAtarCNN, hyperparameters, minatar_env_id, policy_kwargs  # noqa: E402  (after the importorskip guards)

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]
MODULE = "studies.sb3_pixels"


def minatar_space(env_id: str = "MinAtar/Breakout-v1") -> spaces.Box:
    env = gym.make(minatar_env_id(env_id))
    space = env.observation_space
    env.close()
    return space


def policy_for(space: spaces.Box, actions: int = 3) -> CnnPolicy:
    return CnnPolicy(space, spaces.Discrete(actions), lambda _: 1e-4, **policy_kwargs())


@pytest.mark.parametrize("env_id, channels", [("MinAtar/Breakout-v1", 4), ("MinAtar/Seaquest-v1", 10)])
def test_features_are_128_and_the_head_gives_one_value_per_action(env_id, channels):
    space = minatar_space(env_id)
    assert space.shape == (10, 10, channels)
    frames = torch.as_tensor(np.stack([space.sample() for _ in range(5)]))
    assert MinAtarCNN(space)(frames).shape == (5, 128)
    policy = policy_for(space, actions=4)
    assert [type(layer).__name__ for layer in policy.q_net.q_net] == ["Linear"]  # net_arch=[]: a linear head
    assert policy.q_net(frames).shape == (5, 4)


@pytest.mark.parametrize("dtype", [bool, np.uint8])
def test_a_0_1_frame_goes_through_the_policy_unscaled(dtype):
    """Q(s) from SB3's own path (preprocess_obs, then the extractor, then the head) equals the
    network computed by hand on the frame as 0/1 floats, not divided by 255."""
    space = spaces.Box(0, 1, (10, 10, 4), dtype=dtype)
    policy = policy_for(space)
    rng = np.random.default_rng(0)
    frame = (rng.random((10, 10, 4)) < 0.3).astype(dtype)
    net = policy.q_net
    conv, hidden, head = net.features_extractor.conv, net.features_extractor.hidden, net.q_net[0]

    def by_hand(x: torch.Tensor) -> torch.Tensor:
        h = F.relu(F.conv2d(x, conv.weight, conv.bias, stride=1))  # (1, 16, 8, 8)
        h = F.relu(h.reshape(1, 16 * 8 * 8) @ hidden.weight.T + hidden.bias)
        return h @ head.weight.T + head.bias

    x = torch.tensor(frame.astype(np.float32)).permute(2, 0, 1)[None]  # (1, C, H, W), values 0 and 1
    with torch.no_grad():
        q = net(torch.as_tensor(frame[None]))
        expected, scaled = by_hand(x), by_hand(x / 255)
    torch.testing.assert_close(q, expected)
    assert not torch.allclose(q, scaled, atol=1e-4)  # the check can tell the two apart


def test_an_8_bit_image_space_is_refused():
    """SB3 would transpose such a space to channel-first and divide it by 255."""
    with pytest.raises(ConfigError, match="image space"):
        MinAtarCNN(spaces.Box(0, 255, (10, 10, 4), dtype=np.uint8))


def test_the_schedule_is_the_zoo_atari_entry_with_learning_starts_at_1_percent():
    assert hyperparameters(1_000_000) == dict(
        buffer_size=100_000,
        learning_rate=1e-4,
        batch_size=32,
        learning_starts=10_000,
        target_update_interval=1000,
        train_freq=4,
        gradient_steps=1,
        exploration_fraction=0.1,
        exploration_final_eps=0.01,
        optimize_memory_usage=False,
    )
    assert hyperparameters(250_000)["learning_starts"] == 2500


def command(*args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    return subprocess.run(
        [sys.executable, "-m", MODULE, *args], cwd=ROOT, capture_output=True, text=True, env=env, timeout=300
    )


def test_quick_run_writes_the_evaluation_grid_within_the_budget(tmp_path):
    done = command(
        "--env",
        "MinAtar/Breakout-v1",
        "--out",
        str(tmp_path),
        "--quick",
        "--budget",
        "1000",
        "--every",
        "300",
        "--eval-episodes",
        "3",
    )
    assert done.returncode == 0, done.stderr
    path = tmp_path / "MinAtar-Breakout-v1" / "seed0-quick.json"
    run = json.loads(path.read_text())
    assert [e["interactions"] for e in run["evaluations"]] == [0, 300, 600, 900]
    for e in run["evaluations"]:
        assert len(e["returns"]) == 3 and e["mean_return"] == pytest.approx(np.mean(e["returns"]))
    assert (run["budget"], run["eval_every"], run["eval_seed"]) == (1000, 300, eval_seed(0))
    assert run["hyperparameters"]["learning_starts"] == 10
    assert run["hyperparameters"]["policy_kwargs"] == {
        "features_extractor_class": "MinAtarCNN",
        "net_arch": [],
        "normalize_images": False,
    }
    assert set(run["versions"]) == {"stable-baselines3", "torch", "gymnasium", "minatar"}
    again = command(
        "--env",
        "MinAtar/Breakout-v1",
        "--out",
        str(tmp_path),
        "--quick",
        "--budget",
        "1000",
        "--every",
        "300",
        "--eval-episodes",
        "3",
    )
    assert again.returncode == 0 and "kept" in again.stdout
    assert json.loads(path.read_text()) == run


@pytest.mark.parametrize(
    "args, says",
    [
        (["--env", "MinAtar/Breakot-v1", "--quick"], "unknown MinAtar env id 'MinAtar/Breakot-v1'"),
        (["--env", "CartPole-v1", "--quick"], "unknown MinAtar env id 'CartPole-v1'"),
        (["--env", "MinAtar/Breakout-v1"], "--budget is required"),
    ],
)
def test_a_bad_command_exits_non_zero_with_one_line(tmp_path, args, says):
    done = command(*args, "--out", str(tmp_path))
    assert done.returncode != 0
    assert len(done.stderr.strip().splitlines()) == 1 and says in done.stderr
    assert not any(tmp_path.iterdir())
