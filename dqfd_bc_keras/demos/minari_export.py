"""Demonstrations published as a Minari dataset in the local cache (`demos export --minari`,
`demos play --minari`): only what Gymnasium's conventions let a Minari user read as they assume
(demos/minari.py reads them back)."""

from __future__ import annotations

import dataclasses
import os
import shutil
import warnings
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from dqfd_bc_keras.demos.dataset import DemoDataset
from dqfd_bc_keras.demos.minari import dataset_dir, import_minari, refuse_shaped
from dqfd_bc_keras.envs.make import get_task, task_spaces
from dqfd_bc_keras.errors import ConfigError, one_line
from dqfd_bc_keras.plugins import bare_id

DATA_FORMAT = "hdf5"
"""Minari's storage format for the datasets we write: its extra needs only h5py, which Keras
already depends on (the `arrow`/`parquet` formats need pyarrow, a large extra wheel)."""


def check_exportable(task: str, timeout: str, env_kwargs: dict[str, Any], dataset_id: str) -> None:
    """Refuse, in one `ConfigError` naming `minari:dataset_id`, demonstrations of `task` (made with
    `env_kwargs`, recorded with `timeout`) that `to_minari` cannot publish: a caller can check
    before recording anything. Only `bootstrap` datasets of unshaped tasks with flat observations:
    their flags and rewards mean what Gymnasium's do, which is what a Minari user assumes, and
    they are the env's own."""
    where = f"minari:{dataset_id}"
    if timeout != "bootstrap":
        raise ConfigError(
            f"{where}: the dataset was recorded with timeout={timeout!r}, so its flags at the "
            "time limit do not mean what Gymnasium's do; record it again with --timeout bootstrap"
        )
    refuse_shaped(get_task(task), where)  # also imports the env's module (`module:Env-v0`)
    layout = task_spaces(task, env_kwargs).layout
    if layout.image:
        raise ConfigError(
            f"{where}: the dataset's observations are frames ({layout.text()}); writing Minari "
            "datasets of frames is not supported yet (keep them as .npz)"
        )
    if not layout.flat:
        raise ConfigError(
            f"{where}: the dataset's observations were flattened from {layout.text()}; a Minari "
            "dataset holds the env's own observations, so record it with Minari's DataCollector"
        )


def to_minari(dataset: DemoDataset, dataset_id: str, force: bool = False) -> Path:
    """Publish `dataset` in the local Minari cache as `dataset_id`; returns its directory.

    Only what `check_exportable` accepts. Each episode keeps its reset seed (where known). An
    existing dataset is replaced only with `force`, and only once the new one is written. No
    reference scores are computed (that would roll the env out again).
    """
    minari = import_minari()
    from minari.data_collector import EpisodeBuffer

    m = dataset.meta
    check_exportable(m.task, m.timeout, m.env_kwargs, dataset_id)
    where = f"minari:{dataset_id}"
    env_spec = gym.spec(bare_id(m.env_id))  # Minari cannot parse the module prefix: give it the spec
    env_spec = dataclasses.replace(env_spec, kwargs={**env_spec.kwargs, **m.env_kwargs})
    directory = dataset_dir(dataset_id)
    if directory.exists() and not force:
        raise ConfigError(f"{where}: a Minari dataset of that id exists at {directory}; pass --force to replace it")

    starts = np.flatnonzero(np.diff(dataset.episode_ids, prepend=-1))
    ends = np.append(starts[1:], len(dataset))
    buffers = [
        EpisodeBuffer(
            observations=np.concatenate([dataset.obs[a:b], dataset.next_obs[b - 1 : b]]),
            actions=dataset.actions[a:b],
            rewards=dataset.rewards[a:b],
            terminations=dataset.terminated[a:b],
            truncations=dataset.truncated[a:b],
            seed=seed,
        )
        for a, b, seed in zip(starts, ends, m.episode_seeds, strict=True)
    ]
    description = (
        f"Demonstrations exported by dqfd_bc_keras: task {m.task} ({m.env_id}), demonstrator "
        f"{m.expert}, epsilon={m.epsilon:g}, seed={m.seed}, {len(buffers)} episodes, "
        f"{len(dataset)} steps, timeout=bootstrap (Gymnasium's flags)."
    )

    # Replacing: keep the old dataset under a hidden name (Minari skips dot-directories) until
    # the new one is complete, so a failed export leaves the cache as it was.
    backup = directory.with_name(f".{directory.name}.replaced-{os.getpid()}") if directory.exists() else None
    if backup is not None:
        directory.rename(backup)
    try:
        with warnings.catch_warnings():  # the nags about author, email, code link and eval env we do not know
            warnings.filterwarnings("ignore", message=r".*is set to None", category=UserWarning)
            minari.create_dataset_from_buffers(
                dataset_id,
                buffers,
                env=env_spec,
                algorithm_name=m.expert,
                description=description,
                data_format=DATA_FORMAT,
            )
    except BaseException as error:
        shutil.rmtree(directory, ignore_errors=True)
        if backup is not None:
            backup.rename(directory)
        if isinstance(error, Exception):
            raise ConfigError(f"{where}: Minari could not write it ({one_line(error)})") from error
        raise
    if backup is not None:
        shutil.rmtree(backup, ignore_errors=True)
    return directory
