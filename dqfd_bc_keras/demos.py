"""Demonstration datasets: record them with any demonstrator (a scripted expert, a rule
`module:function`, a saved `.keras` model), save them as plain `.npz`, and load them back with
every check a learner relies on; Minari datasets convert both ways (`minari_io`).

File format (version 1), readable with `numpy.load(path, allow_pickle=False)`:

    obs (N, d) float32   actions (N,) int64   rewards (N,) float32   next_obs (N, d) float32
    terminated (N,) bool   truncated (N,) bool   episode_ids (N,) int64
    meta  0-d str: JSON {format_version, task, env_id, timeout, obs_dim, n_actions, expert,
                         epsilon, seed, episode_returns, plain_returns, env_kwargs, observation}

`obs` are the flat vectors the networks take (`observations`: a Dict or a grid is flattened);
`meta.observation` names the env's own space. `env_kwargs` and `observation` are optional
(files written before they existed load as {} and "").

Transitions are stored in time order, episode after episode, and every episode is complete
(its last transition is terminated or truncated), so n-step returns can be read off directly.

    python -m dqfd_bc_keras.demos record --task cartpole --expert imperfect --episodes 5 --out demos.npz
    python -m dqfd_bc_keras.demos record --env Acrobot-v1 --policy my_rules:swing --out acrobot.npz
    python -m dqfd_bc_keras.demos record --env flappy_bird_gymnasium:FlappyBird-v0 --env-kwargs use_lidar=false \
        --max-steps 1000 --policy my_rules:flap --out flappy.npz
    python -m dqfd_bc_keras.demos inspect demos.npz
    python -m dqfd_bc_keras.demos export demos.npz --minari mountaincar/imperfect-v0
"""

from __future__ import annotations

import dataclasses
import errno
import json
import sys
import zipfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .cli import ArgumentParser, add_task_arguments, chosen_task, env_settings, positive_int, run
from .envs import get_task, make_task, task_spaces
from .errors import ConfigError, DemoFileError
from .experts import EXPERT_NAMES, make_demonstrator
from .files import atomic_path
from .wrappers import TIMEOUT_MODES

FORMAT_VERSION = 1

ARRAYS: dict[str, tuple[type, int]] = {
    # name: (dtype, number of dimensions)
    "obs": (np.float32, 2),
    "actions": (np.int64, 1),
    "rewards": (np.float32, 1),
    "next_obs": (np.float32, 2),
    "terminated": (np.bool_, 1),
    "truncated": (np.bool_, 1),
    "episode_ids": (np.int64, 1),
}


@dataclass(frozen=True)
class DemoMeta:
    """Where a dataset comes from; stored as the JSON string `meta`."""

    task: str
    env_id: str
    timeout: str
    obs_dim: int
    n_actions: int
    expert: str
    epsilon: float
    seed: int
    episode_returns: list[float]
    """Return of each episode under the task's rewards (what the learner sees)."""
    plain_returns: list[float]
    """Return of each episode under the plain env's rewards (what the field reports)."""
    format_version: int = FORMAT_VERSION
    env_kwargs: dict[str, Any] = dataclasses.field(default_factory=dict)
    """The keyword arguments the env was made with."""
    observation: str = ""
    """The env's own observation space and how it was flattened ("" in files that predate it)."""


@dataclass(frozen=True)
class DemoDataset:
    """Demonstration transitions in time order, one complete episode after another."""

    obs: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    next_obs: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    episode_ids: np.ndarray
    meta: DemoMeta

    def __len__(self) -> int:
        return len(self.actions)

    @property
    def n_episodes(self) -> int:
        return len(self.meta.episode_returns)

    def episodes(self) -> list[DemoDataset]:
        """The dataset split into one dataset per episode (ids restart at 0)."""
        starts = np.flatnonzero(np.diff(self.episode_ids, prepend=-1))
        ends = np.append(starts[1:], len(self))
        return [
            DemoDataset(**{name: getattr(self, name)[a:b] for name in ARRAYS if name != "episode_ids"},
                        episode_ids=np.zeros(b - a, np.int64),
                        meta=dataclasses.replace(self.meta, episode_returns=[self.meta.episode_returns[i]],
                                                 plain_returns=[self.meta.plain_returns[i]]))
            for i, (a, b) in enumerate(zip(starts, ends))
        ]

    def obs_scale(self) -> tuple[np.ndarray, np.ndarray]:
        """(mean, std) of the demonstrated states, per feature: the networks' input scaling."""
        return self.obs.mean(axis=0), self.obs.std(axis=0)

    def summary(self) -> str:
        """A few human-readable lines: provenance, size and returns."""
        m = self.meta
        returns = np.asarray(m.episode_returns)
        plain = np.asarray(m.plain_returns)
        return "\n".join([
            f"task         {m.task} ({m.env_id}, timeout={m.timeout}, obs_dim={m.obs_dim}, "
            f"n_actions={m.n_actions})",
            *([f"env kwargs   {json.dumps(m.env_kwargs)}"] if m.env_kwargs else []),
            *([f"observation  {m.observation}"] if m.observation else []),
            f"expert       {m.expert} (epsilon={m.epsilon:g}, seed={m.seed})",
            f"episodes     {self.n_episodes}",
            f"transitions  {len(self)}",
            f"returns      {' '.join(f'{r:g}' for r in returns)}",
            f"mean ± std   {returns.mean():.1f} ± {returns.std():.1f}  "
            f"(plain env: {plain.mean():.1f} ± {plain.std():.1f})",
        ])


def record(
    task: str,
    expert: str,
    episodes: int,
    seed: int = 0,
    epsilon: float = 0.0,
    timeout: str = "bootstrap",
    max_steps: int | None = None,
    env_kwargs: dict[str, Any] | None = None,
) -> DemoDataset:
    """Run the demonstrator `expert` (`experts.make_demonstrator`: strong | imperfect |
    module:function | model.keras) for `episodes` episodes of `task` made with `env_kwargs`,
    `max_steps` steps at most; episode i resets with seed + i."""
    if episodes < 1:
        raise ConfigError(f"episodes must be ≥ 1, got {episodes}")
    policy = make_demonstrator(expert, task, epsilon=epsilon, seed=seed, env_kwargs=env_kwargs)
    env = make_task(task, timeout=timeout, max_steps=max_steps, env_kwargs=env_kwargs)
    dataset = rollout(env, policy, [seed + i for i in range(episodes)], task=task, source=expert,
                      epsilon=epsilon, seed=seed, env_kwargs=env_kwargs)
    env.close()
    return dataset


class EpisodeRecorder:
    """Transitions of complete episodes as they are played, turned into a dataset on demand.

    One recorder serves scripted demonstrations, greedy roll-outs and the agent's own training
    episodes (dynamic demonstrations), so every D_demo episode has the same layout and meta.
    """

    def __init__(self, env, *, task: str, source: str, epsilon: float = 0.0, seed: int = 0,
                 env_kwargs: dict[str, Any] | None = None) -> None:
        self.task, self.source, self.epsilon, self.seed = task, source, float(epsilon), int(seed)
        self.env_kwargs = dict(env_kwargs or {})
        self.obs_dim, self.n_actions = int(env.observation_space.shape[0]), int(env.action_space.n)
        self.timeout = env.get_wrapper_attr("mode")
        self.clear()

    def clear(self) -> None:
        """Forget every recorded episode (and the one being played)."""
        self.columns: dict[str, list] = {name: [] for name in ARRAYS}
        self.returns: list[float] = []
        self.plain_returns: list[float] = []
        self.open = 0

    def reset(self, obs: np.ndarray) -> None:
        """A new episode starts in `obs`; an unfinished one before it is dropped."""
        for column in self.columns.values():
            del column[len(column) - self.open:]
        self.obs, self.open, self.ret, self.plain = obs, 0, 0.0, 0.0

    def step(self, action: int, next_obs: np.ndarray, reward: float, terminated: bool, truncated: bool,
             info: dict) -> None:
        values = (self.obs, action, reward, next_obs, terminated, truncated, len(self.returns))
        for name, value in zip(ARRAYS, values):
            self.columns[name].append(value)
        self.obs, self.open = next_obs, self.open + 1
        self.ret += float(reward)
        self.plain += info["plain_reward"]
        if terminated or truncated:
            self.returns.append(self.ret)
            self.plain_returns.append(self.plain)
            self.open = 0

    @property
    def episodes(self) -> int:
        return len(self.returns)

    def dataset(self) -> DemoDataset:
        """The complete episodes recorded so far (an episode still being played is left out)."""
        if not self.returns:
            raise ConfigError("no complete episode has been recorded")
        end = len(self.columns["actions"]) - self.open
        meta = DemoMeta(
            task=self.task, env_id=get_task(self.task).env_id, timeout=self.timeout, obs_dim=self.obs_dim,
            n_actions=self.n_actions, expert=self.source, epsilon=self.epsilon, seed=self.seed,
            episode_returns=list(self.returns), plain_returns=list(self.plain_returns),
            env_kwargs=dict(self.env_kwargs), observation=task_spaces(self.task, self.env_kwargs).layout.text(),
        )
        arrays = {name: np.asarray(self.columns[name][:end], dtype=dtype) for name, (dtype, _) in ARRAYS.items()}
        return DemoDataset(**arrays, meta=meta)


def rollout(
    env, policy: Callable[[np.ndarray], int], seeds: Sequence[int], *, task: str, source: str,
    epsilon: float = 0.0, seed: int = 0, env_kwargs: dict[str, Any] | None = None,
) -> DemoDataset:
    """One complete episode of `policy` on the task env `env` per seed, as a dataset.

    `source` names the demonstrator in the metadata (a scripted expert, or the agent's
    greedy policy for dynamic demonstrations); `env_kwargs` are those `env` was made with.
    """
    recorder = EpisodeRecorder(env, task=task, source=source, epsilon=epsilon, seed=seed, env_kwargs=env_kwargs)
    for episode_seed in seeds:
        obs, _ = env.reset(seed=int(episode_seed))
        recorder.reset(obs)
        done = False
        while not done:
            action = policy(obs)
            obs, reward, terminated, truncated, info = env.step(action)
            recorder.step(action, obs, reward, terminated, truncated, info)
            done = terminated or truncated
    return recorder.dataset()


def concatenate(parts: Sequence[DemoDataset], source: str) -> DemoDataset:
    """One dataset of the episodes of `parts`, in order, episode ids renumbered 0, 1, 2, …"""
    first = parts[0].meta
    offsets = np.cumsum([0] + [p.n_episodes for p in parts[:-1]])
    arrays = {name: np.concatenate([getattr(p, name) for p in parts]) for name in ARRAYS if name != "episode_ids"}
    arrays["episode_ids"] = np.concatenate([p.episode_ids + off for p, off in zip(parts, offsets)])
    meta = dataclasses.replace(
        first, expert=source,
        episode_returns=[r for p in parts for r in p.meta.episode_returns],
        plain_returns=[r for p in parts for r in p.meta.plain_returns],
    )
    return DemoDataset(**arrays, meta=meta)


def save(dataset: DemoDataset, path: str | Path, force: bool = False) -> None:
    """Write `dataset` to `path` atomically; an existing file is kept unless `force`."""
    arrays = {name: getattr(dataset, name) for name in ARRAYS}
    meta = np.array(json.dumps(dataclasses.asdict(dataset.meta)))
    with atomic_path(path, overwrite=force) as tmp:
        np.savez_compressed(tmp, meta=meta, **arrays)


def _not_a_file(path: Path) -> str:
    """What `path` is, when it is not a regular file."""
    try:
        path.stat()
    except OSError as error:
        if error.errno == errno.ELOOP:
            return "is a symbolic link loop"
        return "is a broken symbolic link" if path.is_symlink() else "no such file"
    return "is a directory, not an .npz file" if path.is_dir() else "is not a regular file"


def load(path: str | Path, task: str | None = None, timeout: str | None = None,
         env_kwargs: dict[str, Any] | None = None, max_transitions: int | None = None) -> DemoDataset:
    """Read and validate a dataset; with `task`/`timeout`, also check it was recorded for them
    (with `task`, on an env made with `env_kwargs`: none when not given, and with the task's
    observation features and actions); with `max_transitions`, check its size from the file's
    header before any array is read.

    Raises `DemoFileError` naming the file and the problem for anything a learner could trip
    on later: not an npz, pickled objects, missing keys, wrong shapes or dtypes, non-finite
    values, actions out of range, incomplete episodes, another task, an empty dataset.
    """
    path = Path(path)
    if not path.is_file():
        raise DemoFileError(path, _not_a_file(path))
    if not zipfile.is_zipfile(path):
        raise DemoFileError(path, "is not an .npz file")
    if max_transitions is not None:
        rows = _rows(path)
        if rows is not None and rows > max_transitions:
            raise DemoFileError(path, f"holds {rows} transitions, more than demo_capacity={max_transitions} "
                                      "(raise it with --set demo_capacity=N, or give fewer demonstrations)")
    try:
        with np.load(path, allow_pickle=False) as data:
            contents = {key: data[key] for key in data.files}
    except ValueError as error:  # numpy refuses object arrays without allow_pickle
        raise DemoFileError(path, f"holds pickled objects, which are not accepted ({error})") from None
    except (OSError, zipfile.BadZipFile, EOFError) as error:
        raise DemoFileError(path, f"is not a readable .npz file ({error})") from None
    missing = [key for key in (*ARRAYS, "meta") if key not in contents]
    if missing:
        raise DemoFileError(path, f"missing key(s) {missing}")
    meta = _parse_meta(path, contents["meta"])
    dataset = DemoDataset(**{name: contents[name] for name in ARRAYS}, meta=meta)
    _validate(path, dataset)
    if task is not None and meta.task != task:
        raise DemoFileError(path, f"was recorded on task {meta.task!r}, not on the requested {task!r}")
    if task is not None and meta.env_kwargs != dict(env_kwargs or {}):
        raise DemoFileError(path, f"was recorded with env kwargs {json.dumps(meta.env_kwargs)}, not the "
                                  f"requested {json.dumps(dict(env_kwargs or {}))}")
    if task is not None:  # the task's spaces now, which its env's package may have changed since
        spaces = task_spaces(task, env_kwargs)
        features = spaces.input_dim(meta.timeout)
        if meta.obs_dim != features or meta.n_actions != spaces.n_actions:
            raise DemoFileError(path, f"holds observations of {meta.obs_dim} features and {meta.n_actions} actions, "
                                      f"but task {task} has {features} features and {spaces.n_actions} actions")
    if timeout is not None and meta.timeout != timeout:
        raise DemoFileError(
            path, f"was recorded with timeout={meta.timeout!r}, not the requested {timeout!r} "
            "(the flags at the time limit differ; record it again with --timeout)")
    return dataset


def load_source(source: str, task: str, timeout: str, env_kwargs: dict[str, Any] | None = None,
                max_transitions: int | None = None) -> DemoDataset:
    """Demonstrations for `task` (made with `env_kwargs`) from `source`: a `.npz` file of ours or
    `minari:DATASET_ID` (a dataset in the local Minari cache, converted by `minari_io.from_minari`),
    of at most `max_transitions` transitions."""
    if source.startswith("minari:"):
        from .minari_io import from_minari  # optional dependency

        return from_minari(source.removeprefix("minari:"), task, timeout, env_kwargs, max_transitions)
    return load(source, task=task, timeout=timeout, env_kwargs=env_kwargs, max_transitions=max_transitions)


def _rows(path: Path) -> int | None:
    """How many transitions the file holds, from the header of its `actions` array (its data unread)."""
    try:
        with zipfile.ZipFile(path) as archive, archive.open("actions.npy") as file:
            version = np.lib.format.read_magic(file)
            read = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
            shape = read(file)[0]
    except (KeyError, ValueError, OSError, zipfile.BadZipFile):
        return None  # the full load names what is wrong
    return int(shape[0]) if shape else None


META_TYPES: dict[str, tuple[type, ...]] = {
    "task": (str,), "env_id": (str,), "timeout": (str,), "obs_dim": (int,), "n_actions": (int,), "expert": (str,),
    "epsilon": (int, float), "seed": (int,), "episode_returns": (list,), "plain_returns": (list,),
    "format_version": (int,), "env_kwargs": (dict,), "observation": (str,),
}
"""The JSON type of each meta field (a bool is not a number here)."""


def _parse_meta(path: Path, raw: np.ndarray) -> DemoMeta:
    if raw.ndim != 0 or raw.dtype.kind != "U":
        raise DemoFileError(path, f"meta must be a JSON string, got an array of dtype {raw.dtype}")
    try:
        fields = json.loads(str(raw))
    except json.JSONDecodeError as error:
        raise DemoFileError(path, f"meta is not valid JSON ({error})") from None
    if not isinstance(fields, dict):
        raise DemoFileError(path, "meta must be a JSON object")
    if fields.get("format_version") != FORMAT_VERSION:
        raise DemoFileError(path, f"format_version {fields.get('format_version')!r} is not {FORMAT_VERSION}")
    names = {field.name for field in dataclasses.fields(DemoMeta)}
    optional = {"env_kwargs", "observation"}
    missing = sorted(names - optional - fields.keys())
    if missing:
        raise DemoFileError(path, f"meta lacks {missing}")
    for key, kinds in META_TYPES.items():
        value = fields.get(key)
        if key in fields and (isinstance(value, bool) or not isinstance(value, kinds)):
            raise DemoFileError(path, f"meta's {key} must be {' or '.join(k.__name__ for k in kinds)}, got {value!r}")
    for key in ("episode_returns", "plain_returns"):
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in fields[key]):
            raise DemoFileError(path, f"meta's {key} must be a list of numbers")
    meta = DemoMeta(**{key: fields[key] for key in names if key in fields})
    try:
        get_task(meta.task)
    except ConfigError as error:
        raise DemoFileError(path, f"meta names a task that cannot be made here: {error}") from None
    if meta.timeout not in TIMEOUT_MODES:
        raise DemoFileError(path, f"meta names unknown timeout mode {meta.timeout!r}")
    return meta


def _validate(path: Path, ds: DemoDataset) -> None:
    """Every check that does not need the environment; raises DemoFileError on the first failure."""
    for name, (dtype, ndim) in ARRAYS.items():
        array = getattr(ds, name)
        if array.dtype != dtype or array.ndim != ndim:
            raise DemoFileError(path, f"{name} must be {np.dtype(dtype).name} with {ndim} dimension(s), "
                                      f"got {array.dtype} with shape {array.shape}")
    n, m = len(ds.actions), ds.meta
    if n == 0 or m.episode_returns == []:
        raise DemoFileError(path, "the dataset is empty")
    for name in ARRAYS:
        if len(getattr(ds, name)) != n:
            raise DemoFileError(path, f"{name} has {len(getattr(ds, name))} rows, actions has {n}")
    for name in ("obs", "next_obs"):
        if getattr(ds, name).shape[1] != m.obs_dim:
            raise DemoFileError(path, f"{name} has {getattr(ds, name).shape[1]} features, meta says obs_dim={m.obs_dim}")
    for name in ("obs", "rewards", "next_obs"):
        if not np.isfinite(getattr(ds, name)).all():
            raise DemoFileError(path, f"{name} holds non-finite values (NaN or inf)")
    if ds.actions.min() < 0 or ds.actions.max() >= m.n_actions:
        raise DemoFileError(path, f"actions must lie in [0, {m.n_actions}), got values in "
                                  f"[{ds.actions.min()}, {ds.actions.max()}]")
    starts = np.flatnonzero(np.diff(ds.episode_ids)) + 1
    if (np.diff(ds.episode_ids) < 0).any() or ds.episode_ids[0] != 0 or ds.episode_ids[-1] != len(starts):
        raise DemoFileError(path, "episode_ids must count 0, 1, 2, … in time order")
    if len(starts) + 1 != len(m.episode_returns):
        raise DemoFileError(path, f"{len(starts) + 1} episodes in episode_ids, "
                                  f"{len(m.episode_returns)} returns in meta")
    ends = np.append(starts - 1, n - 1)
    if not (ds.terminated[ends] | ds.truncated[ends]).all():
        raise DemoFileError(path, "an episode does not end with terminated or truncated")
    inner = np.setdiff1d(np.arange(n - 1), ends)
    if not np.array_equal(ds.next_obs[inner], ds.obs[inner + 1]):
        raise DemoFileError(path, "next_obs does not match the following obs inside an episode")


def main(argv: Sequence[str] | None = None) -> int:
    parser = ArgumentParser(prog="python -m dqfd_bc_keras.demos", description=__doc__.split("\n\n")[0])
    commands = parser.add_subparsers(dest="command", required=True)
    rec = commands.add_parser("record", help="record a dataset with a demonstrator")
    add_task_arguments(rec, required=True)
    rec.add_argument("--expert", "--policy", dest="expert", required=True,
                     help=f"a preset's {' | '.join(EXPERT_NAMES)}, a rule module:function (obs → action) "
                          "or a saved model.keras (its greedy policy)")
    rec.add_argument("--episodes", type=positive_int, default=5)
    rec.add_argument("--seed", type=int, default=0, help="episode i resets with seed + i")
    rec.add_argument("--epsilon", type=float, default=0.0, help="probability of a random action")
    rec.add_argument("--timeout", choices=TIMEOUT_MODES, default="bootstrap")
    rec.add_argument("--out", required=True, help="the .npz file to write")
    rec.add_argument("--force", action="store_true", help="overwrite an existing file")
    ins = commands.add_parser("inspect", help="print a dataset's summary")
    ins.add_argument("path")
    exp = commands.add_parser("export", help="publish a dataset in the local Minari cache")
    exp.add_argument("path", help="the .npz dataset (recorded with --timeout bootstrap)")
    exp.add_argument("--minari", required=True, metavar="DATASET_ID", help="e.g. acrobot/imperfect-v0")
    exp.add_argument("--force", action="store_true", help="replace an existing Minari dataset of that id")
    args = parser.parse_args(argv)
    if args.command == "record":
        if not args.out.endswith(".npz"):
            raise ConfigError(f"--out must end in .npz, got {args.out!r}")
        env = env_settings(args)
        dataset = record(chosen_task(args), args.expert, args.episodes, args.seed, args.epsilon, args.timeout,
                         env.get("max_steps"), env.get("env_kwargs"))
        save(dataset, args.out, force=args.force)
        print(f"wrote {args.out}")
    elif args.command == "export":
        from .minari_io import to_minari  # optional dependency

        dataset = load(args.path)
        print(f"wrote Minari dataset {args.minari} to {to_minari(dataset, args.minari, force=args.force)}")
    else:
        dataset = load(args.path)
    print(dataset.summary())
    return 0


if __name__ == "__main__":
    sys.exit(run(main))
