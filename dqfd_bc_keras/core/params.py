"""A params file: Config fields a hyperparameter search found (`experiments tune`'s best.json) or a
user wrote, as `train.py --params FILE` and `DQfD(task, **read_params(FILE))` take them."""

from __future__ import annotations

import os
import warnings
from typing import Any

from dqfd_bc_keras.core.config import Config, unknown_field
from dqfd_bc_keras.errors import ConfigError, DqfdWarning
from dqfd_bc_keras.files import read_json


def read_params(path: str | os.PathLike, task: str | None = None) -> dict[str, Any]:
    """The Config fields of a params file: `experiments tune`'s best.json (its `params`) or a JSON
    object of fields, each key checked as `--set` checks it (a misspelt field gets the nearest
    one's name; the task is not a param); the values are checked with the rest of the Config they
    go into. `train.py --params FILE` and `DQfD(task, **read_params(FILE))` read it; given the
    `task` they go to, a best.json tuned on another task says so (a warning: params may transfer)."""
    data = read_json(path, "params file")
    params = data.get("params", data) if isinstance(data, dict) else data
    if not isinstance(params, dict):
        raise ConfigError(
            f'{path}: expected a JSON object of Config fields (or best.json\'s "params"), got {params!r:.80}'
        )
    for key in params:
        if key == "task":
            raise ConfigError(f"{path}: the task is not a param; it is chosen with --task or --env")
        if key not in Config.__dataclass_fields__:
            raise ConfigError(f"{path}: {unknown_field(key)}")
    tuned = data.get("tunes") if isinstance(data, dict) else None
    if task is not None and isinstance(tuned, dict) and tuned.get("task") not in (None, task):
        warnings.warn(f"{path} was tuned on {tuned['task']}, not {task}", DqfdWarning, stacklevel=2)
    return dict(params)
