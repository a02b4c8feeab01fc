"""Demonstration files: a dataset as a plain `.npz`, written atomically and read back with every
check a learner relies on.

File format (version 1), readable with `numpy.load(path, allow_pickle=False)`: the arrays of
`demo_data.ARRAYS`, and

    meta  0-d str: JSON {format_version, task, env_id, timeout, obs_dim, n_actions, expert,
                         epsilon, seed, episode_returns, plain_returns, env_kwargs, observation}

`env_kwargs` and `observation` are optional (files written before they existed load as {} and "").
"""

from __future__ import annotations

import dataclasses
import errno
import json
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from .demo_data import ARRAYS, FORMAT_VERSION, DemoDataset, DemoMeta, validate
from .envs import get_task, task_spaces
from .errors import ConfigError, DemoFileError
from .files import atomic_path
from .wrappers import TIMEOUT_MODES


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
    validate(path, dataset)
    if task is not None and meta.task != task:
        raise DemoFileError(path, f"was recorded on task {meta.task!r}, not on the requested {task!r}")
    if task is not None and meta.env_kwargs != dict(env_kwargs or {}):
        raise DemoFileError(path, f"was recorded with env kwargs {json.dumps(meta.env_kwargs)}, not the "
                                  f"requested {json.dumps(dict(env_kwargs or {}))}")
    if task is not None:  # the task's spaces now, which its env's package may have changed since
        spaces = task_spaces(task, env_kwargs)
        features = spaces.input_dim(meta.timeout)
        frames = None if spaces.layout.frames is None else list(spaces.layout.frames.shape)
        if meta.obs_shape != frames:
            raise DemoFileError(path, f"holds observations of shape {meta.obs_shape or [meta.obs_dim]}, but task "
                                      f"{task} observes {frames or [features]}")
        if meta.obs_dim != features or meta.n_actions != spaces.n_actions:
            raise DemoFileError(path, f"holds observations of {meta.obs_dim} features and {meta.n_actions} actions, "
                                      f"but task {task} has {features} features and {spaces.n_actions} actions")
    if timeout is not None and meta.timeout != timeout:
        raise DemoFileError(
            path, f"was recorded with timeout={meta.timeout!r}, not the requested {timeout!r} "
            "(the flags at the time limit differ; record it again with --timeout)")
    return dataset


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
    "format_version": (int,), "env_kwargs": (dict,), "observation": (str,), "obs_shape": (list, type(None)),
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
    optional = {"env_kwargs", "observation", "obs_shape"}
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
