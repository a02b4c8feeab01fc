"""Demonstration datasets: record → save → load round trip, and every rejection's message."""

import dataclasses
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import call

from dqfd_bc_keras.demos import ARRAYS, DemoDataset, concatenate, load, record, save, validate
from dqfd_bc_keras.envs.make import get_task
from dqfd_bc_keras.errors import ConfigError, DemoFileError, OutputExistsError


@pytest.fixture(scope="module")
def dataset() -> DemoDataset:
    return record("cartpole-200", "imperfect", episodes=3, seed=7)


def write(path, ds: DemoDataset, **overrides):
    """Save `ds` with some arrays (or `meta`, a dict or raw string) replaced, bypassing `save`."""
    arrays = {name: getattr(ds, name) for name in ARRAYS}
    arrays["meta"] = np.array(json.dumps(dataclasses.asdict(ds.meta)))
    for key, value in overrides.items():
        if key == "meta" and isinstance(value, dict):
            value = np.array(json.dumps(value))
        arrays[key] = value
    np.savez(path, **{k: v for k, v in arrays.items() if v is not None})
    return path


def test_recorded_dataset_matches_the_format(dataset):
    n = len(dataset)
    assert dataset.obs.shape == (n, 4) and dataset.obs.dtype == np.float32
    assert dataset.actions.dtype == np.int64 and set(np.unique(dataset.actions)) <= {0, 1}
    assert dataset.terminated.dtype == np.bool_ and dataset.episode_ids.dtype == np.int64
    assert list(np.unique(dataset.episode_ids)) == [0, 1, 2]
    m = dataset.meta
    assert (m.task, m.env_id, m.expert, m.seed, m.obs_dim, m.n_actions) == (
        "cartpole-200",
        "CartPole-v1",
        "imperfect",
        7,
        4,
        2,
    )
    # Returns in meta are the sums of the stored rewards, episode by episode.
    sums = [dataset.rewards[dataset.episode_ids == e].sum() for e in range(3)]
    np.testing.assert_allclose(m.episode_returns, sums)
    # Plain CartPole-v1 pays +1 per step: the plain return is the episode length.
    np.testing.assert_array_equal(m.plain_returns, np.bincount(dataset.episode_ids))


def test_round_trip_is_exact(dataset, tmp_path):
    path = tmp_path / "demos.npz"
    save(dataset, path)
    loaded = load(path, task="cartpole-200", timeout="bootstrap")
    assert loaded.meta == dataset.meta
    for name in ARRAYS:
        np.testing.assert_array_equal(getattr(loaded, name), getattr(dataset, name))
        assert getattr(loaded, name).dtype == getattr(dataset, name).dtype
    with np.load(path, allow_pickle=False) as raw:  # readable without this package
        assert json.loads(str(raw["meta"]))["format_version"] == 2


def test_recorded_dataset_knows_its_seeds_and_step_limit(dataset):
    """Episode i was reset with seed + i and played under the task's limit, or --max-steps'."""
    assert dataset.meta.episode_seeds == [7, 8, 9]
    assert dataset.meta.max_steps == get_task("cartpole-200").max_steps == 200
    assert (dataset.meta.keys, dataset.meta.fps) == ({}, None)  # a program's demonstrations
    short = record("mountaincar", "imperfect", episodes=2, seed=3, max_steps=50)
    assert short.meta.max_steps == 50 and short.meta.episode_seeds == [3, 4]
    timed = record("mountaincar", "imperfect", episodes=1, seed=0, timeout="time-aware", max_steps=40)
    assert timed.meta.max_steps == 40


def test_episode_seeds_replay_the_recorded_episodes(dataset):
    """What `show` relies on: resetting with an episode's seed and re-applying its actions gives its states."""
    from dqfd_bc_keras.envs.make import make_task

    with make_task("cartpole-200", max_steps=dataset.meta.max_steps) as env:
        for episode, seed in zip(dataset.episodes(), dataset.meta.episode_seeds, strict=True):
            obs, _ = env.reset(seed=seed)
            states = [obs]
            for action in episode.actions[:-1]:
                states.append(env.step(int(action))[0])
            np.testing.assert_array_equal(np.asarray(states, np.float32), episode.obs)


def test_a_person_s_keys_and_fps_round_trip(dataset, tmp_path):
    played = dataclasses.replace(
        dataset, meta=dataclasses.replace(dataset.meta, keys={"": 0, "right": 1, "left+up": 1}, fps=12.5)
    )
    path = tmp_path / "played.npz"
    save(played, path)
    loaded = load(path)
    assert loaded.meta == played.meta
    m = loaded.meta
    assert (m.max_steps, m.episode_seeds, m.keys, m.fps) == (200, [7, 8, 9], {"": 0, "right": 1, "left+up": 1}, 12.5)
    assert 'keys         {"": 0, "right": 1, "left+up": 1} at 12.5 fps' in loaded.summary()


def test_a_version_1_file_is_still_read(dataset, tmp_path):
    """Users and run directories hold version-1 files: they load, without what they never recorded."""
    old = dataclasses.asdict(dataset.meta) | {"format_version": 1}
    for key in ("max_steps", "episode_seeds", "keys", "fps"):
        del old[key]
    loaded = load(write(tmp_path / "v1.npz", dataset, meta=old), task="cartpole-200", timeout="bootstrap")
    m = loaded.meta
    assert (m.max_steps, m.episode_seeds, m.keys, m.fps) == (None, [None, None, None], {}, None)
    assert m.episode_returns == dataset.meta.episode_returns and m.format_version == 2
    for name in ARRAYS:
        np.testing.assert_array_equal(getattr(loaded, name), getattr(dataset, name))
    assert "(seeds not recorded)" in loaded.summary()
    save(loaded, tmp_path / "v2.npz")  # written again: version 2, every key
    with np.load(tmp_path / "v2.npz", allow_pickle=False) as raw:
        fields = json.loads(str(raw["meta"]))
    assert fields["format_version"] == 2 and fields["episode_seeds"] == [None, None, None]
    assert load(tmp_path / "v2.npz").meta == m


def test_a_version_2_file_needs_every_key(dataset, tmp_path):
    meta = dataclasses.asdict(dataset.meta)
    del meta["episode_seeds"]
    with pytest.raises(DemoFileError, match=re.escape("bad.npz: meta lacks ['episode_seeds']")):
        load(write(tmp_path / "bad.npz", dataset, meta=meta))


@pytest.mark.parametrize(
    "change, match",
    [
        ({"episode_seeds": [7, "3", 9]}, "meta's episode_seeds must be a list of ints or nulls, got '3'"),
        ({"episode_seeds": [7, True, 9]}, "meta's episode_seeds must be a list of ints or nulls, got True"),
        ({"episode_seeds": 7}, "meta's episode_seeds must be list, got 7"),
        ({"keys": {"a": "x"}}, "meta's keys must map key names to int actions, got 'a': 'x'"),
        ({"keys": {"a": False}}, "meta's keys must map key names to int actions, got 'a': False"),
        ({"keys": []}, r"meta's keys must be dict, got \[\]"),
        ({"fps": "30"}, "meta's fps must be int or float or NoneType, got '30'"),
        ({"max_steps": 2.5}, "meta's max_steps must be int or NoneType, got 2.5"),
        ({"episode_seeds": [7, 8]}, "3 episodes, 2 seeds in meta's episode_seeds"),
    ],
)
def test_rejects_wrong_version_2_fields(dataset, tmp_path, change, match):
    meta = dataclasses.asdict(dataset.meta) | change
    with pytest.raises(DemoFileError, match=match):
        load(write(tmp_path / "bad.npz", dataset, meta=meta))


def test_validate_counts_one_seed_per_episode(dataset):
    short = dataclasses.replace(dataset, meta=dataclasses.replace(dataset.meta, episode_seeds=[7, 8]))
    with pytest.raises(DemoFileError, match=r"^somewhere.npz: 3 episodes, 2 seeds in meta's episode_seeds$"):
        validate(Path("somewhere.npz"), short)


def test_episodes_and_concatenate_keep_each_episode_s_seed(dataset):
    parts = dataset.episodes()
    assert [p.meta.episode_seeds for p in parts] == [[7], [8], [9]]
    other = record("cartpole-200", "strong", episodes=2, seed=20)
    joined = concatenate([*parts[::-1], other], source="mixed")
    assert joined.meta.episode_seeds == [9, 8, 7, 20, 21]
    validate(Path("joined"), joined)
    assert "(seeds 9, 8, 7, 20, 21)" in joined.summary()
    assert "(seeds 7..9)" in dataset.summary()


def test_recording_is_deterministic_and_epsilon_changes_actions():
    a = record("mountaincar", "imperfect", episodes=1, seed=3)
    b = record("mountaincar", "imperfect", episodes=1, seed=3)
    noisy = record("mountaincar", "imperfect", episodes=1, seed=3, epsilon=0.5)
    np.testing.assert_array_equal(a.obs, b.obs)
    assert noisy.meta.epsilon == 0.5 and not np.array_equal(a.actions[:50], noisy.actions[:50])


def test_time_aware_and_goal_count_datasets():
    ds = record("mountaincar-goals", "strong", episodes=1, seed=0, timeout="time-aware")
    assert ds.obs.shape[1] == ds.meta.obs_dim == 3
    assert len(ds) == 200 and ds.terminated[-1] and not ds.truncated[-1]
    assert (ds.rewards == 100.0).sum() >= 1  # the strong expert reaches the flag within 200 steps


def test_save_refuses_to_overwrite_without_force(dataset, tmp_path):
    path = tmp_path / "demos.npz"
    save(dataset, path)
    before = path.read_bytes()
    with pytest.raises(OutputExistsError, match="exists; pass --force"):
        save(record("cartpole", "strong", episodes=1), path)
    assert path.read_bytes() == before
    save(record("cartpole", "strong", episodes=1), path, force=True)
    assert load(path).meta.task == "cartpole"


def test_rejects_a_missing_file_and_a_non_npz(tmp_path):
    with pytest.raises(DemoFileError, match="nothere.npz: no such file"):
        load(tmp_path / "nothere.npz")
    text = tmp_path / "notes.npz"
    text.write_text("not a dataset")
    with pytest.raises(DemoFileError, match="notes.npz: is not an .npz file"):
        load(text)


def test_rejects_pickled_objects(dataset, tmp_path):
    path = write(tmp_path / "p.npz", dataset, obs=np.array([{"a": 1}], dtype=object))
    with pytest.raises(DemoFileError, match="pickled objects"):
        load(path)


@pytest.mark.parametrize(
    "change, match",
    [
        ({"rewards": None}, r"missing key\(s\) \['rewards'\]"),
        ({"actions": "float"}, "actions must be int64 with 1 dimension"),
        ({"obs": "3d"}, r"obs must be float32 with 2 dimension\(s\)"),
        ({"next_obs": "short"}, "next_obs has .* rows, actions has"),
        ({"obs": "nan"}, "obs holds non-finite values"),
        ({"rewards": "inf"}, "rewards holds non-finite values"),
        ({"actions": "out of range"}, r"actions must lie in \[0, 2\), got values in \[0, 5\]"),
        ({"obs": "wide"}, "obs has 5 features, meta says obs_dim=4"),
        ({"truncated": "cut"}, "an episode does not end with terminated or truncated"),
        ({"next_obs": "shuffled"}, "next_obs does not match the following obs"),
        ({"episode_ids": "reversed"}, "episode_ids must count 0, 1, 2"),
    ],
)
def test_rejects_bad_arrays_with_the_problem_named(dataset, tmp_path, change, match):
    ((key, how),) = change.items()
    value = getattr(dataset, key).copy() if how is not None else None
    n = len(dataset)
    if how == "float":
        value = value.astype(np.float32)
    elif how == "3d":
        value = value[:, :, None]
    elif how == "short":
        value = value[:-1]
    elif how in ("nan", "inf"):
        value.flat[5] = np.nan if how == "nan" else np.inf
    elif how == "out of range":
        value[3] = 5
    elif how == "wide":
        value = np.hstack([value, value[:, :1]])
    elif how == "cut":
        value[:] = False
    elif how == "shuffled" or how == "reversed":
        value = value[::-1].copy()
    assert value is None or len(value) in (n, n - 1)
    with pytest.raises(DemoFileError, match=match):
        load(write(tmp_path / "bad.npz", dataset, **{key: value}))


@pytest.mark.parametrize(
    "meta, match",
    [
        ("not json", "meta is not valid JSON"),
        ({"format_version": 99}, "format_version 99 is not 1 or 2"),
        ({"format_version": 2, "task": "cartpole"}, "meta lacks"),
        ({"format_version": 1, "task": "cartpole"}, "meta lacks"),
    ],
)
def test_rejects_bad_meta(dataset, tmp_path, meta, match):
    raw = np.array(meta) if isinstance(meta, str) else meta
    with pytest.raises(DemoFileError, match=match):
        load(write(tmp_path / "bad.npz", dataset, meta=raw))


def test_rejects_an_empty_dataset(dataset, tmp_path):
    empty = {name: getattr(dataset, name)[:0] for name in ARRAYS}
    meta = dataclasses.asdict(dataset.meta) | {"episode_returns": [], "plain_returns": []}
    with pytest.raises(DemoFileError, match="the dataset is empty"):
        load(write(tmp_path / "empty.npz", dataset, meta=meta, **empty))


def test_rejects_another_task_or_timeout(dataset, tmp_path):
    path = tmp_path / "d.npz"
    save(dataset, path)
    with pytest.raises(DemoFileError, match="recorded on task 'cartpole-200', not on the requested 'mountaincar'"):
        load(path, task="mountaincar")
    with pytest.raises(DemoFileError, match="recorded with timeout='bootstrap', not the requested 'naive'"):
        load(path, timeout="naive")


def test_record_rejects_bad_arguments():
    with pytest.raises(ConfigError, match="unknown task 'pong'"):
        record("pong", "strong", episodes=1)
    with pytest.raises(ConfigError, match="expert='median' is none of strong, imperfect, module:function"):
        record("cartpole", "median", episodes=1)
    with pytest.raises(ConfigError, match="episodes must be ≥ 1, got 0"):
        record("cartpole", "strong", episodes=0)


REPO = Path(__file__).resolve().parents[1]


def cli(*args, cwd=REPO):
    """`python -m dqfd_bc_keras.demos ARGS` as a process of its own, as a user runs it."""
    return subprocess.run(
        [sys.executable, "-m", "dqfd_bc_keras.demos", *args],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=cwd,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )


def test_cli_record_and_inspect(tmp_path):
    out = tmp_path / "d.npz"
    done = cli(
        "record", "--task", "mountaincar", "--expert", "imperfect", "--episodes", "2", "--seed", "1", "--out", str(out)
    )
    assert done.returncode == 0, done.stderr
    assert done.stderr == ""  # no TensorFlow log lines
    shown = cli("inspect", str(out))
    assert shown.returncode == 0
    assert "task         mountaincar (MountainCar-v0" in shown.stdout
    assert "episodes     2 (seeds 1..2)" in shown.stdout and "mean ± std" in shown.stdout
    assert load(out).meta.seed == 1


@pytest.mark.parametrize(
    "args, message",
    [
        (["record", "--task", "pong", "--expert", "strong", "--out", "x.npz"], "invalid choice: 'pong'"),
        (["record", "--task", "cartpole", "--expert", "median", "--out", "x.npz"], "expert='median' is none of"),
        (
            ["record", "--task", "cartpole", "--expert", "strong", "--episodes", "0", "--out", "x.npz"],
            "must be a positive integer, got 0",
        ),
        (["record", "--task", "cartpole", "--expert", "strong", "--out", "x.txt"], "--out must end in .npz"),
        (["inspect", "missing.npz"], "missing.npz: no such file"),
    ],
)
def test_cli_errors_are_one_line_and_exit_2(tmp_path, args, message):
    done = call("dqfd_bc_keras.demos", *args, cwd=tmp_path)
    assert done.returncode == 2
    assert message in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert not (tmp_path / "x.npz").exists()


def test_cli_does_not_overwrite_without_force(tmp_path):
    out = tmp_path / "d.npz"
    args = ["record", "--task", "cartpole", "--expert", "strong", "--episodes", "1", "--out", str(out)]
    assert call("dqfd_bc_keras.demos", *args).returncode == 0
    before = out.read_bytes()
    again = call("dqfd_bc_keras.demos", *args[:-2], "--seed", "5", "--out", str(out))
    assert again.returncode == 2 and "exists; pass --force" in again.stderr
    assert out.read_bytes() == before
    assert call("dqfd_bc_keras.demos", *args, "--force").returncode == 0


def test_load_reads_one_snapshot_while_a_writer_replaces_the_file(tmp_path, monkeypatch):
    """`demos play` rewrites its file after every episode: a reader at that moment gets the old
    dataset or the new one, never the arrays of one with the header of the other."""
    from dqfd_bc_keras.demos import npz

    one, two = (record("cartpole", "imperfect", n, max_steps=30) for n in (1, 2))
    path, newer = tmp_path / "d.npz", tmp_path / "newer.npz"
    save(one, path)
    save(two, newer)
    read = npz._read

    def replaced_meanwhile(*args):
        if newer.exists():
            os.replace(newer, path)
        return read(*args)

    monkeypatch.setattr(npz, "_read", replaced_meanwhile)
    got = load(path)
    assert got.n_episodes == 1 and np.array_equal(got.obs, one.obs)
    assert load(path).n_episodes == 2
