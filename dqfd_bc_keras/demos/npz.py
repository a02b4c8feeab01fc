"""Demonstration files: a dataset as a plain `.npz`, written atomically and read back with every
check a learner relies on.

File format (version 2), readable with `numpy.load(path, allow_pickle=False)`: the arrays of
`demos.dataset.ARRAYS`, and

    meta  0-d str: JSON {format_version, task, env_id, timeout, obs_dim, n_actions, expert,
                         epsilon, seed, episode_returns, plain_returns, env_kwargs, observation,
                         obs_shape, max_steps, episode_seeds, keys, fps}

Every key is in every file (`obs_shape` null for flat observations, `max_steps` the step limit,
`episode_seeds` one reset seed per episode, `keys` {} and `fps` null for a program's
demonstrations); a file without one is refused. Version 1 had the keys up to `obs_shape`; its
files are still read, without what they never recorded (`max_steps` and `fps` None, every seed
None, `keys` {}). Files are always written as version 2.
"""

from __future__ import annotations

import dataclasses
import errno
import json
import math
import zipfile
import zlib
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from dqfd_bc_keras.choices import TIMEOUT_MODES
from dqfd_bc_keras.demos.dataset import ARRAYS, FORMAT_VERSION, DemoDataset, DemoMeta, check_layout, validate
from dqfd_bc_keras.envs.make import get_task, task_spaces
from dqfd_bc_keras.errors import ConfigError, DemoFileError
from dqfd_bc_keras.files import atomic_path


def save(dataset: DemoDataset, path: str | Path, force: bool = False) -> None:
    """Write `dataset` to `path` atomically; an existing file is kept unless `force`."""
    arrays = {name: getattr(dataset, name) for name in ARRAYS}
    meta = np.array(json.dumps(dataclasses.asdict(dataset.meta) | {"format_version": FORMAT_VERSION}))
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


def load(
    path: str | Path,
    task: str | None = None,
    timeout: str | None = None,
    env_kwargs: dict[str, Any] | None = None,
    max_transitions: int | None = None,
) -> DemoDataset:
    """Read and validate a dataset; with `task`/`timeout`, also check it was recorded for them
    (with `task`, on an env made with `env_kwargs`: none when not given, and with the task's
    observation features and actions); with `max_transitions`, check its size. Every array's
    header is checked (against the others', the meta and its size in the zip) before any is read.

    Raises `DemoFileError` naming the file and the problem for anything a learner could trip
    on later: not an npz, pickled objects, missing keys, wrong shapes or dtypes, non-finite
    values, actions out of range, incomplete episodes, another task, an empty dataset.
    """
    path = Path(path)
    if not path.is_file():
        raise DemoFileError(path, _not_a_file(path))
    with path.open("rb") as file:  # one snapshot: a writer may replace the file (atomically) meanwhile
        if not zipfile.is_zipfile(file):
            raise DemoFileError(path, "is not an .npz file")
        headers = _headers(path, file)
        missing = [key for key in (*ARRAYS, "meta") if key not in headers]
        if missing:
            raise DemoFileError(path, f"missing key(s) {missing}")
        rows = headers["actions"][1][0] if headers["actions"][1] else 0
        if max_transitions is not None and rows > max_transitions:
            raise DemoFileError(
                path,
                f"holds {rows} transitions, more than demo_capacity={max_transitions} "
                "(raise it with --set demo_capacity=N, or give fewer demonstrations)",
            )
        meta = _parse_meta(path, _read(path, file, "meta"))
        check_layout(path, meta, {name: headers[name] for name in ARRAYS})
        dataset = DemoDataset(**{name: _read(path, file, name) for name in ARRAYS}, meta=meta)
    validate(path, dataset)
    if task is not None:
        _check_task(path, meta, task, env_kwargs)
    if timeout is not None and meta.timeout != timeout:
        raise DemoFileError(
            path,
            f"was recorded with timeout={meta.timeout!r}, not the requested {timeout!r} "
            "(the flags at the time limit differ; record it again with --timeout)",
        )
    return dataset


def _check_task(path: Path, meta: DemoMeta, task: str, env_kwargs: dict[str, Any] | None) -> None:
    """That the file was recorded on `task` made with `env_kwargs`, whose spaces are still what it holds."""
    if meta.task != task:
        raise DemoFileError(path, f"was recorded on task {meta.task!r}, not on the requested {task!r}")
    if meta.env_kwargs != dict(env_kwargs or {}):
        raise DemoFileError(
            path,
            f"was recorded with env kwargs {json.dumps(meta.env_kwargs)}, not the "
            f"requested {json.dumps(dict(env_kwargs or {}))}",
        )
    spaces = task_spaces(task, env_kwargs)  # the task's spaces now, which its env's package may have changed since
    features = spaces.input_dim(meta.timeout)
    frames = None if spaces.layout.frames is None else list(spaces.layout.frames.shape)
    if meta.obs_shape != frames:
        raise DemoFileError(
            path,
            f"holds observations of shape {meta.obs_shape or [meta.obs_dim]}, but task {task} observes "
            f"{frames or [features]}",
        )
    if meta.obs_dim != features or meta.n_actions != spaces.n_actions:
        raise DemoFileError(
            path,
            f"holds observations of {meta.obs_dim} features and {meta.n_actions} actions, "
            f"but task {task} has {features} features and {spaces.n_actions} actions",
        )


HEADER_READERS = {(1, 0): np.lib.format.read_array_header_1_0, (2, 0): np.lib.format.read_array_header_2_0}
"""The .npy header versions numpy writes for arrays of plain dtypes."""
MAX_DEFLATE_RATIO = 1032
"""The most data deflate gives per compressed byte: a member claiming more is damaged or forged."""


def _headers(path: Path, file: BinaryIO) -> dict[str, tuple[np.dtype, tuple[int, ...]]]:
    """{key: (dtype, shape)} of the file's `.npy` members, from their headers alone, each checked
    against the member's size in the zip: the data a header claims must be exactly what the member
    holds, and no more than its compressed bytes can inflate to. numpy allocates what a header
    claims before reading, so a lying header is a MemoryError (10^12 rows) or a short read."""
    headers = {}
    try:
        with zipfile.ZipFile(file) as archive:
            for info in archive.infolist():
                if not info.filename.endswith(".npy"):
                    continue
                member = f"member {info.filename}"
                with archive.open(info) as stream:
                    try:
                        version = np.lib.format.read_magic(stream)
                        read = HEADER_READERS.get(version)
                        if read is None:
                            raise ValueError(f".npy format version {version} is not read here")
                        shape, _, dtype = read(stream)
                    except ValueError as error:
                        raise DemoFileError(path, f"{member} has no valid .npy header ({error})") from None
                    offset = stream.tell()
                if dtype.hasobject:
                    raise DemoFileError(path, f"{member} holds pickled objects, which are not accepted")
                claimed = math.prod(shape) * dtype.itemsize
                if claimed != info.file_size - offset:
                    raise DemoFileError(
                        path,
                        f"{member} claims shape {shape} of {dtype} ({claimed} bytes), but holds "
                        f"{info.file_size - offset} bytes of data",
                    )
                inflatable = {zipfile.ZIP_STORED: 1, zipfile.ZIP_DEFLATED: MAX_DEFLATE_RATIO}.get(info.compress_type)
                if inflatable is None or info.file_size > inflatable * info.compress_size + 1024:
                    raise DemoFileError(
                        path,
                        f"{member} claims {info.file_size} bytes from {info.compress_size} "
                        "compressed, which its compression cannot give (a damaged file)",
                    )
                headers[info.filename.removesuffix(".npy")] = dtype, tuple(shape)
    except (OSError, zipfile.BadZipFile, EOFError) as error:
        raise DemoFileError(path, f"is not a readable .npz file ({error})") from None
    return headers


def _read(path: Path, file: BinaryIO, key: str) -> np.ndarray:
    """One array of `file` (opened from `path`), its header already checked by `_headers`."""
    try:
        file.seek(0)
        with np.load(file, allow_pickle=False) as data:
            return data[key]
    except (ValueError, OSError, zipfile.BadZipFile, EOFError, zlib.error) as error:
        raise DemoFileError(path, f"member {key}.npy is not readable ({error})") from None


META_TYPES: dict[str, tuple[type, ...]] = {
    "task": (str,),
    "env_id": (str,),
    "timeout": (str,),
    "obs_dim": (int,),
    "n_actions": (int,),
    "expert": (str,),
    "epsilon": (int, float),
    "seed": (int,),
    "episode_returns": (list,),
    "plain_returns": (list,),
    "format_version": (int,),
    "env_kwargs": (dict,),
    "observation": (str,),
    "obs_shape": (list, type(None)),
    "max_steps": (int, type(None)),
    "episode_seeds": (list,),
    "keys": (dict,),
    "fps": (int, float, type(None)),
}
"""The JSON type of each field of `DemoMeta`, each in every file's meta (a bool is not a number here)."""
VERSION_1_DEFAULTS: dict[str, Any] = {"max_steps": None, "keys": {}, "fps": None}
"""What a version-1 file lacks and this version reads it with (`episode_seeds`: None per episode)."""


def _check_types(path: Path, fields: dict[str, Any]) -> None:
    for key, kinds in META_TYPES.items():
        value = fields[key]
        if isinstance(value, bool) or not isinstance(value, kinds):
            raise DemoFileError(path, f"meta's {key} must be {' or '.join(k.__name__ for k in kinds)}, got {value!r}")
    for key in ("episode_returns", "plain_returns"):
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in fields[key]):
            raise DemoFileError(path, f"meta's {key} must be a list of numbers")
    wrong = [v for v in fields["episode_seeds"] if v is not None and (isinstance(v, bool) or not isinstance(v, int))]
    if wrong:
        raise DemoFileError(path, f"meta's episode_seeds must be a list of ints or nulls, got {wrong[0]!r} in it")
    wrong = [f"{k!r}: {v!r}" for k, v in fields["keys"].items() if isinstance(v, bool) or not isinstance(v, int)]
    if wrong:
        raise DemoFileError(path, f"meta's keys must map key names to int actions, got {wrong[0]}")


def _parse_meta(path: Path, raw: np.ndarray) -> DemoMeta:
    if raw.ndim != 0 or raw.dtype.kind != "U":
        raise DemoFileError(path, f"meta must be a JSON string, got an array of dtype {raw.dtype}")
    try:
        fields = json.loads(str(raw))
    except json.JSONDecodeError as error:
        raise DemoFileError(path, f"meta is not valid JSON ({error})") from None
    if not isinstance(fields, dict):
        raise DemoFileError(path, "meta must be a JSON object")
    version = fields.get("format_version")
    if version == 1:  # users and run directories hold them: read on, without what they never recorded
        returns = fields.get("episode_returns")
        seeds = [None] * len(returns) if isinstance(returns, list) else []
        fields = VERSION_1_DEFAULTS | {"episode_seeds": seeds} | fields
    elif version != FORMAT_VERSION:
        raise DemoFileError(path, f"format_version {version!r} is not 1 or {FORMAT_VERSION}")
    missing = [key for key in META_TYPES if key not in fields]
    if missing:
        raise DemoFileError(
            path, f"meta lacks {missing}: written by an older version? Record the demonstrations again with this one"
        )
    _check_types(path, fields)
    fps = None if fields["fps"] is None else float(fields["fps"])
    meta = DemoMeta(**{key: fields[key] for key in META_TYPES} | {"format_version": FORMAT_VERSION, "fps": fps})
    try:
        get_task(meta.task)
    except ConfigError as error:
        raise DemoFileError(path, f"meta names a task that cannot be made here: {error}") from None
    if meta.timeout not in TIMEOUT_MODES:
        raise DemoFileError(path, f"meta names unknown timeout mode {meta.timeout!r}")
    return meta
