"""Frames: uint8 observations through the replay's frame pool, the convolutional networks and the
estimators, the torso's choice, and MinAtar and Atari runs through train.py and evaluate.py (answered
in this process)."""

import json

import keras
import numpy as np
import pytest
import tensorflow as tf
from helpers import python as run

from dqfd_bc_keras.core.bc import BCModel, BCNetwork
from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.core.networks import NetworkInput, build_q_network, resolve_torso
from dqfd_bc_keras.core.replay import PrioritizedReplay, ReplaySettings
from dqfd_bc_keras.core.uncertainty import VarianceEstimator
from dqfd_bc_keras.envs.make import checked_spaces
from dqfd_bc_keras.envs.observations import Frames
from dqfd_bc_keras.errors import ConfigError

BREAKOUT = "ale_py:ALE/Breakout-v5"


# --- the frame pool -----------------------------------------------------------------------------


def episodes_of_frames(rng, lengths, shape, stack):
    """Transitions (obs, next_obs, terminated) of episodes of these lengths: random frames, a
    stack shifting one frame a step and starting as copies of its first frame (as Atari's)."""
    out = []
    for length in lengths:
        frame = lambda: rng.integers(0, 256, shape, dtype=np.uint8)
        obs = np.repeat(frame()[..., None], stack, axis=-1) if stack > 1 else frame()
        for t in range(length):
            nxt = np.concatenate([obs[..., 1:], frame()[..., None]], axis=-1) if stack > 1 else frame()
            out.append((obs, nxt, t == length - 1))
            obs = nxt
    return out


def store(replay, transitions):
    for obs, nxt, terminated in transitions:
        obs_index, next_index = replay.frame_pool.store(tf.constant(obs), tf.constant(nxt))
        replay.store(
            replay.rows(
                obs_index[None],
                0,
                1.0,
                next_index[None],
                terminated,
                False,
                tf.fill([1, replay.n_actions], 1.0 / replay.n_actions),
                0.5,
            )[0]
        )


def set_demos(replay, transitions):
    obs = np.stack([t[0] for t in transitions])
    nxt = np.stack([t[1] for t in transitions])
    ends = np.array([t[2] for t in transitions])
    obs_index, next_index = replay.frame_pool.store_demos(obs, nxt, ends)
    n = len(transitions)
    replay.set_demos(
        replay.rows(
            obs_index,
            np.zeros(n),
            np.ones(n),
            next_index,
            ends,
            np.zeros(n),
            np.full((n, replay.n_actions), 1.0 / replay.n_actions),
            np.full(n, 0.5),
        )
    )


@pytest.mark.parametrize("shape, stack", [((5, 5, 2), 1), ((6, 7), 4)])
def test_frames_read_back_exactly_from_the_pool_after_the_buffer_wraps(shape, stack):
    frames = Frames((*shape, stack) if stack > 1 else shape, 1 / 255, stack)
    replay = PrioritizedReplay(
        NetworkInput(int(np.prod(frames.shape)), frames), 3, ReplaySettings(capacity=8, demo_capacity=20, n_step=3)
    )
    rng = np.random.default_rng(0)
    demos = episodes_of_frames(rng, [4, 3], shape, stack)
    set_demos(replay, demos)
    stream = episodes_of_frames(rng, [5, 1, 6, 2, 3], shape, stack)  # 17 transitions into 8 rows
    store(replay, stream)
    # The table holds D_demo's 7 rows, then the last 8 self-generated ones (the head is at 17 % 8 = 1).
    expected = demos + [stream[17 - 8 + (p - 1) % 8] for p in range(8)]
    replay.settle()  # as `sample` does before reading
    rows = replay.stored_indices()
    batch = replay._batch(rows, tf.ones([len(expected)]))
    assert batch.obs.dtype == tf.uint8 and tuple(batch.obs.shape[1:]) == frames.shape
    for i, (obs, nxt, _) in enumerate(expected):
        np.testing.assert_array_equal(batch.obs[i].numpy(), obs)
        np.testing.assert_array_equal(batch.next_obs[i].numpy(), nxt)
    # s_{t+m} of the n-step return: the s' where the window (n = 3) stops, at its episode's end or
    # at the newest stored transition, in time order within each region.
    newest = stream[9:]
    for i in range(len(expected)):
        sequence, q = (demos, i) if i < 7 else (newest, (i - 7 - 1) % 8)
        j = q
        while j - q < 2 and not sequence[j][2] and j + 1 < len(sequence):
            j += 1
        np.testing.assert_array_equal(batch.n_next_obs[i].numpy(), sequence[j][1])
    assert replay.pool_bytes == 2 * (20 + 8 + stack) * int(np.prod(frames.frame_shape))


def test_a_stack_that_does_not_shift_is_refused():
    frames = Frames((4, 4, 4), 1 / 255, 4)
    replay = PrioritizedReplay(NetworkInput(64, frames), 2, ReplaySettings(capacity=8, demo_capacity=8, n_step=2))
    obs = np.zeros((4, 4, 4), np.uint8)
    with pytest.raises(tf.errors.InvalidArgumentError, match="shifted by one frame"):
        replay.frame_pool.store(tf.constant(obs), tf.constant(np.full((4, 4, 4), 7, np.uint8)))
    with pytest.raises(ConfigError, match="must shift by one frame per step and start as copies"):
        replay.frame_pool.store_demos(np.arange(64, dtype=np.uint8).reshape(1, 4, 4, 4), obs[None], np.array([True]))


def test_a_frame_is_stored_once_not_once_per_stack():
    # An Atari replay of 100k transitions: 2 slots of 84×84 bytes per row, not 2 stacks of 4 floats.
    frames = Frames((84, 84, 4), 1 / 255, 4)
    replay = PrioritizedReplay(
        NetworkInput(84 * 84 * 4, frames), 4, ReplaySettings(capacity=1000, demo_capacity=10, n_step=3)
    )
    assert replay.table.shape[1] == 2 * 4 + 5 + 4  # s and s' are 4 pool indices each
    assert replay.pool_bytes == 2 * (10 + 1000 + 4) * 84 * 84


# --- networks and estimators on frames -------------------------------------------------------------

MINATAR = NetworkInput(400, Frames((10, 10, 4), 1.0), "minatar")


@pytest.mark.parametrize(
    "spec, sizes",
    [
        (MINATAR, [(3, 3, 4, 16), (16,), (1024, 128), (128,), (128, 3), (3,)]),
        (
            NetworkInput(84 * 84 * 4, Frames((84, 84, 4), 1 / 255, 4), "nature"),
            [(8, 8, 4, 32), (32,), (4, 4, 32, 64), (64,), (3, 3, 64, 64), (64,), (3136, 128), (128,), (128, 3), (3,)],
        ),
    ],
)
def test_conv_q_networks_round_trip_through_keras_in_safe_mode(tmp_path, spec, sizes):
    model = build_q_network(spec, 3, (128,))
    assert [tuple(w.shape) for w in model.weights] == sizes  # MinAtar's 3×3×16; Nature's 8/4, 4/2, 3/1
    model.save(tmp_path / "q.keras")
    loaded = keras.saving.load_model(tmp_path / "q.keras", safe_mode=True)
    obs = np.random.default_rng(0).integers(0, 2 if spec.torso == "minatar" else 256, (5, *spec.shape), np.uint8)
    np.testing.assert_array_equal(model(obs).numpy(), loaded(obs).numpy())
    scaled = keras.Model(model.inputs, model.get_layer("to_unit").output)(obs).numpy()
    np.testing.assert_allclose(scaled, obs * spec.frames.scale, rtol=1e-6)  # uint8 in, [0, 1] inside


@pytest.mark.parametrize("uncertainty", ["mc_dropout", "ensemble", "distance"])
def test_bc_models_on_frames_fit_predict_and_round_trip(tmp_path, uncertainty):
    rng = np.random.default_rng(1)
    obs = rng.integers(0, 2, (40, 10, 10, 4), np.uint8)
    actions = (obs[:, 0, 0, 0] + obs[:, 1, 1, 1]).astype(np.int64) % 3
    model = BCModel(
        MINATAR,
        3,
        BCNetwork(hidden=(32,), dropout=0.0 if uncertainty == "ensemble" else 0.2, prior_scale=1.0),
        VarianceEstimator(uncertainty, members=3 if uncertainty == "ensemble" else 1),
    )
    model.compile(optimizer=keras.optimizers.Adam(1e-3))
    model.fit_demos(obs, actions, epochs=2, batch_size=8)
    pi, sigma_sq = model.predictive(tf.constant(obs[:6]))
    assert pi.shape == (6, 3) and np.allclose(pi.numpy().sum(1), 1, atol=1e-5)
    assert np.all(sigma_sq.numpy() >= 0.5 - 1e-6) and np.all(sigma_sq.numpy() <= 0.5 + 2 / 9 + 1e-6)
    if uncertainty == "distance":
        np.testing.assert_allclose(sigma_sq.numpy(), 0.5, atol=1e-6)  # demonstrated states: distance 0
        far = 1 - obs[:1]
        assert float(model.predictive(tf.constant(far))[1][0]) > 0.5
    model.save(tmp_path / "bc.keras")
    loaded = keras.saving.load_model(tmp_path / "bc.keras", safe_mode=True)
    np.testing.assert_allclose(model(obs[:6]).numpy(), loaded(obs[:6]).numpy(), rtol=1e-6)
    assert loaded.net_input == model.net_input and loaded.net_input.torso == "minatar"


def test_the_torso_is_chosen_by_the_observation_and_refused_where_it_cannot_read_it():
    assert resolve_torso("auto", None) == "mlp"
    assert resolve_torso("auto", Frames((10, 10, 4), 1.0)) == "minatar"
    assert resolve_torso("auto", Frames((84, 84, 4), 1 / 255, 4)) == "nature"
    assert resolve_torso("mlp", Frames((10, 10, 4), 1.0)) == "mlp"  # frames flattened in the network
    with pytest.raises(ConfigError, match="torso='minatar' needs frames"):
        checked_spaces(Config.for_task("cartpole", torso="minatar"))
    with pytest.raises(ConfigError, match="torso=nature needs frames of at least 36×36"):
        checked_spaces(Config.for_task("minatar-breakout", torso="nature"))
    with pytest.raises(ConfigError, match="timeout='time-aware' appends the time left to a vector"):
        checked_spaces(Config.for_task("minatar-breakout", timeout="time-aware"))
    with pytest.raises(ConfigError, match="torso='conv' is not one of"):
        Config.for_task("cartpole", torso="conv")
    breakout = Config.for_task("minatar-breakout")
    assert checked_spaces(breakout).network_input(breakout.torso, breakout.timeout).torso == "minatar"


# --- end to end -----------------------------------------------------------------------------------


@pytest.mark.slow
def test_a_minatar_run_trains_and_evaluates_end_to_end(tmp_path):
    out = tmp_path / "run"
    done = run(
        "train.py",
        "--task",
        "minatar-breakout",
        "--quick",
        "--set",
        "total_steps=300",
        "--set",
        "eval_every=150",
        "--out",
        out,
    )
    assert done.returncode == 0, done.stderr
    config = json.loads((out / "config.json").read_text())
    assert config["observation"]["frames"] == {"shape": [10, 10, 4], "scale": 1.0, "stack": 1}
    q = keras.saving.load_model(out / "q_network.keras", safe_mode=True)
    assert q.inputs[0].dtype == "uint8" and tuple(q.inputs[0].shape[1:]) == (10, 10, 4)
    assert any(isinstance(layer, keras.layers.Conv2D) for layer in q.layers)
    with np.load(out / "demos.npz") as demos:
        assert demos["obs"].dtype == np.uint8 and demos["obs"].shape[1:] == (10, 10, 4)
    for policy in ("q", "bc"):
        done = run("evaluate.py", out, "--policy", policy, "--episodes", "2")
        assert done.returncode == 0, done.stderr
        assert f"minatar-breakout (MinAtar/Breakout-v1), {policy} policy, 2 greedy episodes" in done.stdout


@pytest.mark.slow
def test_an_atari_run_trains_from_a_rule_and_a_saved_model_demonstrates(tmp_path):
    tiny = [
        "--quick",
        "--max-steps",
        "40",
        "--set",
        "total_steps=80",
        "--set",
        "pretrain_steps=4",
        "--set",
        "batch_size=4",
        "--set",
        "bc_epochs=1",
        "--set",
        "demo_episodes=1",
        "--set",
        "eval_every=40",
    ]
    done = run("train.py", "--env", BREAKOUT, "--expert", "toy_envs:breakout_rule", *tiny, "--out", tmp_path / "a")
    assert done.returncode == 0, done.stderr
    config = json.loads((tmp_path / "a" / "config.json").read_text())
    assert config["observation"]["frames"]["stack"] == 4 and config["hidden"] == [512]
    done = run("evaluate.py", tmp_path / "a", "--episodes", "1")
    assert done.returncode == 0 and "1 greedy episodes" in done.stdout, done.stderr
    # The saved Q-network demonstrates: demonstrations recorded from the model file.
    done = run(
        "-m",
        "dqfd_bc_keras.demos",
        "record",
        "--env",
        BREAKOUT,
        "--expert",
        tmp_path / "a" / "q_network.keras",
        "--episodes",
        "1",
        "--max-steps",
        "40",
        "--out",
        tmp_path / "d.npz",
    )
    assert done.returncode == 0, done.stderr
    with np.load(tmp_path / "d.npz") as demos:
        assert demos["obs"].shape[1:] == (84, 84, 4) and demos["obs"].dtype == np.uint8
        assert len(demos["actions"]) == 40 or demos["terminated"][-1]


@pytest.mark.slow
def test_quick_caps_an_atari_games_episodes_so_a_policy_that_never_fires_ends(tmp_path):
    """Breakout waits for FIRE: a greedy agent that never presses it plays every step of the limit
    (27,000 steps). `--quick` caps an Atari game's limit at 200; `--max-steps` still wins."""
    (tmp_path / "still.py").write_text("def noop(obs):\n    return 0\n")
    tiny = ["--set", "total_steps=40", "--set", "eval_every=40", "--set", "pretrain_steps=4", "--set", "batch_size=4"]
    tiny += ["--set", "bc_epochs=1", "--set", "demo_episodes=1", "--set", "eval_episodes=1"]
    tiny += ["--set", "final_eval_episodes=1", "--quiet"]
    args = ["train.py", "--env", BREAKOUT, "--expert", "still:noop", "--quick", *tiny]
    done = run(*args, "--out", tmp_path / "a", path=[tmp_path])
    assert done.returncode == 0, done.stderr
    assert json.loads((tmp_path / "a" / "config.json").read_text())["max_steps"] == 200
    assert json.loads((tmp_path / "a" / "eval.json").read_text())["lengths"][0] <= 200
    with np.load(tmp_path / "a" / "demos.npz") as demos:
        assert len(demos["actions"]) == 200  # never fired: cut at the limit, not at 27,000
    refused = run(*args, "--max-steps", "30000", "--out", tmp_path / "b", path=[tmp_path])
    assert refused.returncode == 2 and "the episode limit 30000" in refused.stderr  # the given limit, not --quick's


def test_an_unknown_atari_option_is_one_line(tmp_path):
    done = run(
        "train.py",
        "--env",
        BREAKOUT,
        "--expert",
        "toy_envs:breakout_rule",
        "--quick",
        "--env-kwargs",
        "frame_skp=2",
        "--out",
        tmp_path / "x",
    )
    assert done.returncode == 2 and "did you mean 'frame_skip'?" in done.stderr
    assert len([line for line in done.stderr.strip().splitlines() if "A.L.E" not in line and "Stella" not in line]) == 1
    assert not (tmp_path / "x").exists()


def test_what_frames_do_not_support_yet_is_refused_in_one_line(tmp_path):
    demos_file = tmp_path / "d.npz"
    done = run(
        "-m",
        "dqfd_bc_keras.demos",
        "record",
        "--task",
        "minatar-breakout",
        "--expert",
        "imperfect",
        "--episodes",
        "1",
        "--out",
        demos_file,
    )
    assert done.returncode == 0, done.stderr
    done = run("-m", "dqfd_bc_keras.demos", "export", demos_file, "--minari", "breakout/frames-v0")
    assert done.returncode == 2 and "writing Minari datasets of frames is not supported yet" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr
    done = run("train.py", "--task", "minatar-breakout", "--timeout", "time-aware", "--quick", "--out", tmp_path / "t")
    assert done.returncode == 2 and "appends the time left to a vector observation" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert not (tmp_path / "t").exists()


@pytest.mark.slow
def test_the_pixels_study_runs_both_sides_and_reports_from_its_archive(tmp_path):
    out = tmp_path / "pixels"
    done = run("-m", "studies.pixels", "--out", out, "--quick")
    assert done.returncode == 0, done.stderr
    assert (out / "sb3-dqn" / "seed0-quick.json").is_file() and (out / "pixels.json").is_file()
    archive = tmp_path / "pixels.tar.xz"
    assert run("-m", "dqfd_bc_keras.experiments", "export", out, "--out", archive).returncode == 0
    report = tmp_path / "PIXELS.md"
    done = run("-m", "studies.pixels", "--out", archive, "--quick", "--no-run", "--report", report)
    assert done.returncode == 0, done.stderr
    text = report.read_text()
    assert "| minatar-breakout bayes |" in text and "| minatar-breakout SB3 DQN (rl-zoo3) |" in text
    assert "threshold 10" in text and "5,000,000 frames ≈ 10" in text
    done = run("-m", "studies.pixels", "--out", archive)
    assert done.returncode == 2 and "an archive is read, never run into: add --no-run" in done.stderr
