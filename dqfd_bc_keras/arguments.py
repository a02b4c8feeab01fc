"""What the Python API (`model.DQfD`) takes from a user, checked as it is given: a count, a flag or
a path of the wrong type is one `ConfigError` line naming the argument, not a NumPy error three
calls down or a value silently taken (`learn("100")`, `predict(deterministic="no")`). Also what
`DQfD(...)` makes of its demonstrations and its method, and `learn` of its callbacks and progress bar.

Config fields given as `DQfD` keywords are not checked here: they go to `Config`, which checks
every field wherever a config is made.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, cast

import numpy as np

from dqfd_bc_keras import demos as demo_io
from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.core.methods import METHODS, Method, register
from dqfd_bc_keras.demos.recording import callable_name
from dqfd_bc_keras.envs.given import a_kind
from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.tasks import Rule
from dqfd_bc_keras.training.records import EpisodeRow, EvalRow

Callback = Callable[[EpisodeRow | EvalRow], object]
Callbacks = Callback | Sequence[Callback] | None
DemosLike = demo_io.DemoDataset | str | Path | Rule | None
DEMONSTRATORS = "a preset expert's name, module:function, a .keras model or a function obs → action"


def check_int(call: str, name: str, value: object, low: int, high: int | None = None) -> None:
    """An int (a NumPy integer too; not a bool, a float or text) in [low, high]."""
    wanted = f"an int ≥ {low}" if high is None else f"an int in [{low}, {high}]"
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise ConfigError(f"{call}({name}={_short(value)}): expected {wanted}, not {a_kind(value)}")
    if value < low or (high is not None and value > high):
        raise ConfigError(f"{call}({name}={value}): expected {wanted}")


def check_bool(call: str, name: str, value: object) -> None:
    if not isinstance(value, (bool, np.bool_)):
        raise ConfigError(f"{call}({name}={_short(value)}): expected True or False, not {a_kind(value)}")


def check_path(call: str, name: str, value: object) -> None:
    """A str or os.PathLike, not empty (`Path("")` is the working directory)."""
    if not isinstance(value, (str, os.PathLike)) or str(value) == "":
        got = "an empty path" if isinstance(value, (str, os.PathLike)) else a_kind(value)
        raise ConfigError(f"{call}({name}={_short(value)}): expected a path (str or pathlib.Path), not {got}")


def _short(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


# --- DQfD(env, demos, expert=...) ----------------------------------------------------------------


def demonstrator(demos: DemosLike, expert: object) -> DemosLike:
    """`demos`, or `expert` (the command line's `--expert`) in its place: who demonstrates, as
    `demos=` takes a demonstrator; demonstrations themselves (a dataset, a file) are `demos=`."""
    if expert is None:
        return demos
    if demos is not None:
        raise ConfigError(
            f"DQfD(demos={_short(demos)}, expert={_short(expert)}): demos gives the demonstrations (or who "
            "records them) and expert would record them: give one"
        )
    if isinstance(expert, demo_io.DemoDataset) or is_demo_source(expert):
        raise ConfigError(
            f"DQfD(expert={_short(expert)}): expert is who demonstrates ({DEMONSTRATORS}); "
            "demonstrations themselves are given as demos="
        )
    if not (isinstance(expert, (str, Path)) or callable(expert)):
        raise ConfigError(f"DQfD(expert={_short(expert)}): expected {DEMONSTRATORS}, not {a_kind(expert)}")
    return expert


def is_demo_source(demos: object) -> bool:
    """A .npz file or a Minari dataset's id: demonstrations to load, not a demonstrator."""
    return isinstance(demos, (str, Path)) and (str(demos).endswith(".npz") or str(demos).startswith("minari:"))


def demonstrations(
    demos: DemosLike, task: str, settings: dict[str, Any]
) -> tuple[demo_io.DemoDataset | None, str | None, Rule | None, str | None]:
    """What `demos` gives: (a dataset given or loaded, its source, a Python rule to record, the
    config's `expert`), None where it gives nothing; `settings` make the task's preset."""
    if isinstance(demos, demo_io.DemoDataset):
        return demos, "python", None, demo_io.given_expert("a Python DemoDataset", demos)
    if is_demo_source(demos):
        preset = Config.for_task(task, **settings)
        dataset = demo_io.load_source(str(demos), task, preset.timeout, preset.env_kwargs, preset.demo_capacity)
        return dataset, demo_io.given_source(dataset), None, demo_io.given_expert(str(demos), dataset)
    if isinstance(demos, (str, Path)):
        return None, None, None, str(demos)
    if callable(demos):
        return None, "recorded", demos, callable_name(demos)
    if demos is None:
        return None, None, None, None
    raise ConfigError(
        f"DQfD(env, demos): demos is a DemoDataset, a .npz file, minari:DATASET_ID, a demonstrator's "
        f"name or a function obs → action, not {type(demos).__name__}"
    )


def method_name(method: Method) -> str:
    """The name a config gives `method`: `module:NAME` when it is an attribute of the module its term
    comes from (a later process imports it from there, as `--expert-loss module:NAME`), else its
    own name, registered in this process."""
    if METHODS.get(method.name) is method:
        return method.name
    module = sys.modules.get(getattr(method.term, "__module__", None) or "")
    if module is not None and module.__name__ != "__main__":
        for attribute, value in vars(module).items():
            if value is method:
                return f"{module.__name__}:{attribute}"
    register(method)
    return method.name


# --- learn(callback=..., progress_bar=...) -------------------------------------------------------


def callbacks(callback: Callbacks) -> list[Callback]:
    """`callback` as a list of functions of a row. Stable-Baselines3's `BaseCallback` objects are
    refused: they are called at every env step, and DQfD's steps run inside one TensorFlow graph
    call per episode, with nothing of Python between them."""
    given = (
        []
        if callback is None
        else list(callback)
        if isinstance(callback, (list, tuple))
        else [cast(Callback, callback)]
    )
    for one in given:
        if any(
            c.__name__ == "BaseCallback" and c.__module__.startswith("stable_baselines3") for c in type(one).__mro__
        ):
            raise ConfigError(
                f"learn(callback={type(one).__name__}(...)): Stable-Baselines3's callbacks are called at every "
                "env step, and DQfD's steps run inside one TensorFlow graph call per episode; pass a function "
                "of each episode's and evaluation's row (EpisodeRow, EvalRow) that returns False to stop"
            )
        if not callable(one):
            raise ConfigError(
                f"learn(callback={_short(one)}): expected a function of each row or a list of them, not {a_kind(one)}"
            )
    return given


def told(callbacks: list[Callback], bar: Any = None) -> Callback | None:
    """One callback giving each row to every one of `callbacks` (False from any stops training)
    and moving the progress bar `bar` to each episode's step."""
    if not callbacks and bar is None:
        return None

    def tell(row: EpisodeRow | EvalRow) -> bool:
        if bar is not None and isinstance(row, EpisodeRow):
            bar.update(row.env_step - bar.n)
        answers = [callback(row) for callback in callbacks]  # each sees every row, as SB3's CallbackList
        return all(answer is not False for answer in answers)

    return tell


def step_bar(total: int, done: int) -> Any:
    """A tqdm bar of env steps: a widget in Jupyter (with ipywidgets), else text on stderr, a
    terminal or not."""
    from tqdm.auto import tqdm

    return tqdm(total=total, initial=done, unit="step", dynamic_ncols=True)
