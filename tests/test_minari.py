"""Minari datasets: our demos → Minari → our demos round trip, naive conversion, every refusal.

Everything happens in a temporary local Minari cache (MINARI_DATASETS_PATH); downloading is
made to fail, so a test that tried the network would fail too.
"""

import dataclasses
import re
import sys

import gymnasium as gym
import numpy as np
import pytest
from helpers import python as run

minari = pytest.importorskip("minari")

from dqfd_bc_keras.demos import ARRAYS, DemoDataset, concatenate, record, rollout  # noqa: E402  (after the importorskip guards)
from dqfd_bc_keras.demos.minari import _check_spaces, from_minari  # noqa: E402  (after the importorskip guards)
from dqfd_bc_keras.demos.minari_export import check_exportable, to_minari  # noqa: E402  (after the importorskip guards)
from dqfd_bc_keras.envs import make as envs  # noqa: E402  (after the importorskip guards)
from dqfd_bc_keras.errors import ConfigError, DemoFileError  # noqa: E402  (after the importorskip guards)


@pytest.fixture(autouse=True)
def cache(tmp_path, monkeypatch):
    """A fresh, empty local Minari cache per test, and no way to download."""
    root = tmp_path / "minari"
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(root))

    def no_network(*args, **kwargs):
        raise AssertionError("minari tried to download")

    monkeypatch.setattr(minari.storage.hosting, "download_dataset", no_network)
    monkeypatch.setattr(minari, "download_dataset", no_network)
    return root


@pytest.fixture(scope="module")
def mountaincar() -> DemoDataset:
    return record("mountaincar", "imperfect", 3, seed=0)


@pytest.fixture(scope="module")
def cartpole_v1() -> DemoDataset:
    """A generic env id task, recorded with a rule (the pole's angular velocity)."""
    env = envs.make_task("CartPole-v1")
    dataset = rollout(env, lambda obs: int(obs[3] > 0), [0, 1], task="CartPole-v1", source="rule")
    env.close()
    return dataset


def assert_same(got: DemoDataset, want: DemoDataset) -> None:
    for name in ARRAYS:
        a, b = getattr(got, name), getattr(want, name)
        assert a.dtype == b.dtype, name
        assert np.array_equal(a, b), name
    assert got.meta.episode_returns == want.meta.episode_returns
    assert got.meta.plain_returns == want.meta.plain_returns


def write_minari(dataset_id, episodes, env="CartPole-v1", observation_space=None, action_space=None):
    """A Minari dataset made directly from (observations, actions, rewards, terminations, truncations)."""
    buffers = [
        minari.data_collector.EpisodeBuffer(observations=o, actions=a, rewards=r, terminations=te, truncations=tr)
        for o, a, r, te, tr in episodes
    ]
    with pytest.warns(UserWarning):  # minari's nags about the author and so on
        minari.create_dataset_from_buffers(
            dataset_id,
            buffers,
            env=env,
            observation_space=observation_space,
            action_space=action_space,
            algorithm_name="test",
            description="test",
        )


def episode(steps, obs_dim=4, terminated=True, truncated=False):
    terminations, truncations = np.zeros(steps, bool), np.zeros(steps, bool)
    terminations[-1], truncations[-1] = terminated, truncated
    return (
        np.arange((steps + 1) * obs_dim, dtype=np.float32).reshape(steps + 1, obs_dim) / 100,
        np.zeros(steps, np.int64),
        np.ones(steps, np.float32),
        terminations,
        truncations,
    )


def test_round_trip_preset(mountaincar, cache):
    directory = to_minari(mountaincar, "mountaincar/imperfect-v0")
    assert directory == cache / "mountaincar" / "imperfect-v0" and (directory / "data").is_dir()
    published = minari.load_dataset("mountaincar/imperfect-v0")
    assert published.env_spec.id == "MountainCar-v0" and published.total_episodes == 3
    assert published.storage.metadata["data_format"] == "hdf5"
    assert published.storage.metadata["algorithm_name"] == "imperfect"
    assert "dqfd_bc_keras" in published.storage.metadata["description"]
    got = from_minari("mountaincar/imperfect-v0", "mountaincar")
    assert_same(got, mountaincar)
    m = got.meta
    assert (m.task, m.env_id, m.timeout, m.obs_dim, m.n_actions) == ("mountaincar", "MountainCar-v0", "bootstrap", 2, 3)
    assert (m.expert, m.epsilon, m.seed) == ("minari:mountaincar/imperfect-v0", 0.0, 0)


def test_round_trip_keeps_each_episode_s_seed_not_the_step_limit(mountaincar):
    """Minari keeps each episode's reset seed (in the episode's metadata); no step limit of ours."""
    assert mountaincar.meta.episode_seeds == [0, 1, 2] and mountaincar.meta.max_steps == 200
    to_minari(mountaincar, "mountaincar/imperfect-v0")
    published = minari.load_dataset("mountaincar/imperfect-v0")
    assert [e["seed"] for e in published.storage.get_episode_metadata(published.episode_indices)] == [0, 1, 2]
    m = from_minari("mountaincar/imperfect-v0", "mountaincar").meta
    assert (m.episode_seeds, m.max_steps, m.keys, m.fps) == ([0, 1, 2], None, {}, None)
    later = mountaincar.episodes()[1:]
    to_minari(concatenate(later, source="later"), "mountaincar/later-v0")
    assert from_minari("mountaincar/later-v0", "mountaincar").meta.episode_seeds == [1, 2]


def test_episodes_without_a_seed_read_as_none(mountaincar):
    write_minari("cartpole/unseeded-v0", [episode(4), episode(3)])
    assert from_minari("cartpole/unseeded-v0", "CartPole-v1").meta.episode_seeds == [None, None]
    seeds = [None, 5, None]
    unknown = dataclasses.replace(mountaincar, meta=dataclasses.replace(mountaincar.meta, episode_seeds=seeds))
    to_minari(unknown, "mountaincar/unknown-v0")  # e.g. a version-1 file's: exported without seeds
    assert from_minari("mountaincar/unknown-v0", "mountaincar").meta.episode_seeds == seeds


def test_check_exportable_needs_only_the_meta(monkeypatch, mountaincar):
    """A caller can check before recording anything, without Minari: the messages `to_minari` gives."""
    monkeypatch.setitem(sys.modules, "minari", None)
    check_exportable("mountaincar", "bootstrap", {}, "mountaincar/imperfect-v0")
    with pytest.raises(ConfigError, match=r"^minari:mc/naive-v0: the dataset was recorded with timeout='naive'"):
        check_exportable("mountaincar", "naive", {}, "mc/naive-v0")
    with pytest.raises(ConfigError, match=r"^minari:cp-v0: task 'cartpole' has shaped rewards"):
        check_exportable("cartpole", "bootstrap", {}, "cp-v0")


def test_round_trip_generic_env_id(cartpole_v1):
    assert cartpole_v1.n_episodes == 2 and cartpole_v1.meta.env_id == "CartPole-v1"
    to_minari(cartpole_v1, "cartpole/rule-v0")
    got = from_minari("cartpole/rule-v0", "CartPole-v1")
    assert_same(got, cartpole_v1)
    assert got.meta.env_id == "CartPole-v1"


def test_naive_turns_truncations_into_terminations():
    short = record("mountaincar", "imperfect", 2, seed=0, max_steps=50)
    assert short.truncated.any()
    to_minari(short, "mountaincar/short-v0")
    naive = from_minari("mountaincar/short-v0", "mountaincar", timeout="naive")
    assert np.array_equal(naive.terminated, short.terminated | short.truncated)
    assert not naive.truncated.any() and naive.meta.timeout == "naive"
    assert np.array_equal(naive.obs, short.obs) and np.array_equal(naive.rewards, short.rewards)
    assert_same(from_minari("mountaincar/short-v0", "mountaincar"), short)


def test_both_flags_count_as_terminated():
    write_minari("both-v0", [episode(3, terminated=True, truncated=True)])
    got = from_minari("both-v0", "CartPole-v1")
    assert got.terminated[-1] and not got.truncated.any()


def test_refuses_another_env(mountaincar):
    to_minari(mountaincar, "mountaincar/imperfect-v0")
    with pytest.raises(
        DemoFileError,
        match=r"minari:mountaincar/imperfect-v0: was recorded on MountainCar-v0, "
        r"but task 'acrobot' is Acrobot-v1",
    ):
        from_minari("mountaincar/imperfect-v0", "acrobot")


def test_refuses_shaped_tasks(cartpole_v1):
    shaped = record("cartpole", "imperfect", 1, seed=0)
    with pytest.raises(ConfigError, match=r"shaped rewards \(a fall penalty\).*--env CartPole-v1"):
        to_minari(shaped, "cartpole/shaped-v0")
    with pytest.raises(ConfigError, match=r"shaped rewards \(a goal reward\).*--env MountainCar-v0"):
        to_minari(record("mountaincar-goals", "imperfect", 1, seed=0, max_steps=20), "mc/goals-v0")
    to_minari(cartpole_v1, "cartpole/rule-v0")
    with pytest.raises(ConfigError, match=r"minari:cartpole/rule-v0: task 'cartpole' has shaped rewards"):
        from_minari("cartpole/rule-v0", "cartpole")


def test_refuses_to_export_naive():
    naive = record("mountaincar", "imperfect", 1, seed=0, timeout="naive", max_steps=50)
    with pytest.raises(ConfigError, match="timeout='naive'.*record it again with --timeout bootstrap"):
        to_minari(naive, "mountaincar/naive-v0")


def test_existing_id_needs_force(mountaincar, cache):
    to_minari(mountaincar, "mountaincar/imperfect-v0")
    with pytest.raises(ConfigError, match="a Minari dataset of that id exists at .*pass --force"):
        to_minari(mountaincar, "mountaincar/imperfect-v0")
    first = mountaincar.episodes()[0]
    to_minari(first, "mountaincar/imperfect-v0", force=True)
    assert_same(from_minari("mountaincar/imperfect-v0", "mountaincar"), first)
    assert [p.name for p in (cache / "mountaincar").iterdir() if p.name.startswith(".")] == []


def test_refuses_a_missing_dataset(cache):
    looked = re.escape(str(cache / "nowhere" / "none-v0"))
    with pytest.raises(
        DemoFileError,
        match=rf"minari:nowhere/none-v0: not in the local Minari cache "
        rf"\(looked in {looked}\)",
    ):
        from_minari("nowhere/none-v0", "mountaincar")


def test_refuses_a_malformed_id():
    with pytest.raises(ConfigError, match="malformed Minari dataset id 'no-version'"):
        from_minari("no-version", "mountaincar")


def test_refuses_time_aware(mountaincar):
    to_minari(mountaincar, "mountaincar/imperfect-v0")
    with pytest.raises(ConfigError, match="timeout='time-aware'.*does not record"):
        from_minari("mountaincar/imperfect-v0", "mountaincar", timeout="time-aware")


def test_refuses_mismatched_spaces():
    box3 = gym.spaces.Box(-np.inf, np.inf, (3,), np.float32)
    write_minari(
        "cartpole/three-v0", [episode(5, obs_dim=3)], observation_space=box3, action_space=gym.spaces.Discrete(2)
    )
    assert minari.load_dataset("cartpole/three-v0").env_spec.id == "CartPole-v1"
    with pytest.raises(
        DemoFileError,
        match=re.escape(
            "minari:cartpole/three-v0: mismatched spaces: dataset has "
            "Box(3,) float32/Discrete(2), task CartPole-v1 has "
            "Box(4,) float32/Discrete(2)"
        ),
    ):
        from_minari("cartpole/three-v0", "CartPole-v1")
    box4 = gym.spaces.Box(-np.inf, np.inf, (4,), np.float32)
    with pytest.raises(DemoFileError, match=r"mismatched spaces: dataset has .*/Discrete\(3\)"):
        _check_spaces("x", (box4, gym.spaces.Discrete(3)), "CartPole-v1", box4, 2)
    with pytest.raises(DemoFileError, match="mismatched spaces"):
        _check_spaces("x", (box4, gym.spaces.Discrete(2, start=1)), "CartPole-v1", box4, 2)
    _check_spaces("x", (box4, gym.spaces.Discrete(2)), "CartPole-v1", box4, 2)


def test_refuses_incomplete_episodes():
    write_minari("cartpole/open-v0", [episode(4), episode(3, terminated=False)])
    with pytest.raises(DemoFileError, match="minari:cartpole/open-v0: episode 1 is incomplete"):
        from_minari("cartpole/open-v0", "CartPole-v1")


def test_refuses_a_dataset_without_env():
    write_minari(
        "noenv-v0",
        [episode(3)],
        env=None,
        observation_space=gym.spaces.Box(-np.inf, np.inf, (4,), np.float32),
        action_space=gym.spaces.Discrete(2),
    )
    with pytest.raises(DemoFileError, match="minari:noenv-v0: names no env"):
        from_minari("noenv-v0", "CartPole-v1")


def test_without_minari_says_how_to_install(monkeypatch, mountaincar):
    monkeypatch.setitem(sys.modules, "minari", None)  # `import minari` now raises ImportError
    for call in (lambda: from_minari("a/b-v0", "mountaincar"), lambda: to_minari(mountaincar, "a/b-v0")):
        with pytest.raises(ConfigError, match=r"pip install -r requirements-extras.txt") as error:
            call()
        assert "\n" not in str(error.value)


@pytest.mark.slow
def test_cli_export_then_train_from_the_minari_dataset(cache, tmp_path):
    """A user's path: record a plain env with a rule, publish it with `demos export`, train on it
    with `train.py --demos minari:ID` (the commands, answered in this process, share the local cache)."""
    import json

    demos = tmp_path / "chain.npz"
    assert (
        run(
            "-m",
            "dqfd_bc_keras.demos",
            "record",
            "--env",
            "toy_envs:ToyChain-v0",
            "--policy",
            "toy_envs:go_right",
            "--episodes",
            "20",
            "--out",
            demos,
        ).returncode
        == 0
    )
    done = run("-m", "dqfd_bc_keras.demos", "export", demos, "--minari", "toy/chain-v0")
    assert done.returncode == 0 and "wrote Minari dataset toy/chain-v0" in done.stdout, done.stderr
    again = run("-m", "dqfd_bc_keras.demos", "export", demos, "--minari", "toy/chain-v0")
    assert again.returncode == 2 and "pass --force to replace it" in again.stderr
    out = tmp_path / "run"
    done = run(
        "train.py",
        "--env",
        "toy_envs:ToyChain-v0",
        "--demos",
        "minari:toy/chain-v0",
        "--quick",
        "--quiet",
        "--out",
        out,
    )
    assert done.returncode == 0, done.stderr
    assert json.loads((out / "demonstrations.json").read_text())["expert"] == "minari:toy/chain-v0"
    assert json.loads((out / "eval.json").read_text())["mean_return"] == 1.0


def test_an_env_minari_cannot_serialise_is_refused_in_one_line(cache):
    """Minari stores the env's spec as JSON: an env registered with a callable entry point (not a
    "module:Class" string) cannot be, and the export says so without leaving a dataset behind."""
    import toy_envs

    if "ToyChainCallable-v0" not in gym.registry:
        gym.register("ToyChainCallable-v0", entry_point=toy_envs.Chain, max_episode_steps=20)
    env = envs.make_task("ToyChainCallable-v0")
    dataset = rollout(env, toy_envs.go_right, [0], task="ToyChainCallable-v0", source="rule")
    with pytest.raises(ConfigError, match="Minari could not write it .*does not support serialising callables"):
        to_minari(dataset, "toy/callable-v0")
    assert not (cache / "toy" / "callable-v0").exists()


@pytest.mark.slow
def test_env_kwargs_are_compared_with_the_datasets_env_spec(cache, tmp_path):
    """A dataset recorded on ToyChain-v0 made with size=7 (Minari keeps the kwargs in its env_spec):
    refused without the kwargs or with others, in one line naming both; trained on with them."""
    import dataclasses
    import json

    import toy_envs  # noqa: F401  (registers ToyChain-v0)

    spec = dataclasses.replace(gym.spec("ToyChain-v0"), kwargs={"size": 7})
    walks = [
        (
            np.eye(7, dtype=np.float32)[:7],
            np.ones(6, np.int64),
            np.r_[np.zeros(5), 1.0].astype(np.float32),
            np.r_[np.zeros(5, bool), True],
            np.zeros(6, bool),
        )
        for _ in range(20)
    ]
    write_minari("toy/chain7-v0", walks, env=spec)
    assert minari.load_dataset("toy/chain7-v0").env_spec.kwargs == {"size": 7}
    with pytest.raises(
        DemoFileError,
        match=re.escape(
            'minari:toy/chain7-v0: was recorded with env kwargs {"size": 7}, but the task is made with {"size": 6}'
        ),
    ):
        from_minari("toy/chain7-v0", "toy_envs:ToyChain-v0", env_kwargs={"size": 6})
    with pytest.raises(DemoFileError, match=re.escape('but the task is made with {"size": 5}')):  # the default
        from_minari("toy/chain7-v0", "toy_envs:ToyChain-v0")
    data = from_minari("toy/chain7-v0", "toy_envs:ToyChain-v0", env_kwargs={"size": 7, "observe": "flat"})
    assert data.meta.env_kwargs == {"size": 7, "observe": "flat"} and data.obs.shape == (120, 7)

    out = tmp_path / "run"
    done = run(
        "train.py",
        "--env",
        "toy_envs:ToyChain-v0",
        "--env-kwargs",
        "size=7",
        "--demos",
        "minari:toy/chain7-v0",
        "--quick",
        "--quiet",
        "--out",
        out,
    )
    assert done.returncode == 0, done.stderr
    assert json.loads((out / "eval.json").read_text())["lengths"] == [6, 6]
