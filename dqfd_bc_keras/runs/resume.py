"""What resuming a run reads back before any TensorFlow: the config it trained with (checked
against the copy its latest checkpoint keeps) and the D_demo it was given."""

from __future__ import annotations

import dataclasses
import json
import warnings
from pathlib import Path

from dqfd_bc_keras import demos as demo_io
from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.envs.objects import unmade_env
from dqfd_bc_keras.errors import BrokenRunError, DemoFileError, DqfdWarning, RunDirectoryError, one_line
from dqfd_bc_keras.runs.writers import GIVEN_DEMOS, check_dir


def saved_config(out: str | Path) -> Config:
    """The config of the run in `out`, to resume it: its task, env kwargs and step limit come from
    there, not from the command line. A one-line error if there is no run to resume, and if its
    `config.json` is not the one its latest checkpoint was trained with (a copy is in each)."""
    out = Path(out)
    check_dir(out, resume=True, force=False)
    config = read_config(out / "config.json")
    try:
        own = out / "checkpoints" / json.loads((out / "checkpoints" / "latest.json").read_text())["dir"] / "config.json"
    except (OSError, ValueError, KeyError, TypeError):
        return config  # an unreadable latest.json is the restore's to report
    trained = read_config(own)
    if trained.total_steps > config.total_steps and trained == dataclasses.replace(
        config, total_steps=trained.total_steps
    ):
        return trained  # a longer budget (continue_run) was checkpointed, then stopped before config.json said it
    changed = differences(trained.to_dict(), config.to_dict())
    if changed:
        raise BrokenRunError(
            f"{out / 'config.json'}: differs from the config the run was trained with ({own}) in "
            f"{'; '.join(changed)}; put it back, or start the run over with --force"
        )
    return config


def differences(was: dict, now: dict) -> list[str]:
    """The fields whose values differ between two configs' dicts, as `key: now (was before)`."""
    return [
        f"{key}: {now.get(key)!r} (was {was.get(key)!r})"
        for key in sorted({*was, *now})
        if was.get(key) != now.get(key)
    ]


def read_config(path: Path) -> Config:
    """A run's config.json or its checkpoint's copy, holding every field of Config; a run of a
    Python env object is refused as such (only Python can give it its env again), not as broken."""
    try:
        fields = json.loads(path.read_text())
        env = fields.get("task") if isinstance(fields, dict) else None
        if not unmade_env(env):
            return Config.from_dict(fields)
    except (OSError, ValueError) as error:
        raise BrokenRunError(
            f"{path}: cannot be resumed ({one_line(error)}); start the run over with --force"
        ) from None
    raise RunDirectoryError(
        f"{path}: trained on a Python env object ({env}), which no other process can make; "
        "give it again: --env ID, a registered id of the same env, or from Python DQfD.load(path, env=...)"
    )


def restart_demos(
    out: Path, config: Config, dataset: demo_io.DemoDataset | None, resume: bool
) -> demo_io.DemoDataset | None:
    """The D_demo to start over a run stopped before its first checkpoint with: its own, as a
    resume would, if it got as far as keeping it; else `dataset`."""
    warnings.warn(
        f"{out}: no checkpoint yet (the run was stopped before its first); starting it over", DqfdWarning, stacklevel=3
    )
    given = out / "checkpoints" / GIVEN_DEMOS
    return given_demos(given, config) if resume and given.is_file() else dataset


def given_demos(given: Path, config: Config) -> demo_io.DemoDataset:
    """The D_demo a run was given (checkpoints/demos_given.npz), checked against its config."""
    try:
        return demo_io.load(given, task=config.task, timeout=config.timeout, env_kwargs=config.env_kwargs)
    except DemoFileError as error:
        raise BrokenRunError(f"{error}; the run cannot be resumed: start the run over with --force") from None
