"""Greedy episodes on the plain env, and loading the saved models that play them.

Scores are always those of the unmodified Gymnasium env (CartPole-v1 with its 500-step limit,
MountainCar-v0), so they compare with the rest of the field; the goal-count task additionally
reports its metric, the flags reached per episode on the task env (the paper's Figs. 9–11).
"""

from __future__ import annotations

import json
import zipfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import keras
import numpy as np
import tensorflow as tf

from dqfd_bc_keras.choices import POLICY_FILES, TIMEOUT_MODES
from dqfd_bc_keras.core.bc import BCModel
from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.core.methods import BUILT_IN, playing_saved_run
from dqfd_bc_keras.core.uncertainty import EnsembleDense
from dqfd_bc_keras.envs.episodes import EvalResult, Policy, check_video, play, video_env
from dqfd_bc_keras.envs.make import get_task, make_plain_env, make_task, task_slug, task_spaces
from dqfd_bc_keras.envs.objects import unmade_env
from dqfd_bc_keras.errors import ConfigError, ModelFileError
from dqfd_bc_keras.runtime import keras_conversions

FRAME_LAYERS = (keras.layers.Conv2D, keras.layers.Rescaling, keras.layers.Flatten, keras.layers.Reshape)
"""Layers of a network on frames (networks.torso_layers), which plays through the model itself."""


def _float32(variable: keras.Variable) -> np.ndarray:
    """A Keras variable's values as float32 NumPy (NumPy 2's warning about the conversion silenced)."""
    with keras_conversions():
        return keras.ops.convert_to_numpy(variable).astype(np.float32)


class GreedyPolicy:
    """argmax_a of a Keras model's output: an MLP's computed in NumPy on a copy of its weights, a
    convolutional network's by one compiled call of the model.

    An MLP's action in NumPy costs a fraction of a graph call's fixed price, and `model.predict`
    costs a thousand times more (docs/PERFORMANCE.md): evaluations take seconds, not minutes. A
    convolution's arithmetic is worth the call.
    """

    def __init__(
        self,
        layers: list[tuple[str, np.ndarray, np.ndarray]],
        kind: str,
        forward: Callable[[np.ndarray], np.ndarray] | None = None,
    ) -> None:
        """`layers`: ("scale", mean, std) | ("relu" | "linear", kernel, bias), applied in order;
        or `forward`, the model itself, for a network on frames."""
        self.layers, self.kind, self.forward = layers, kind, forward

    @classmethod
    def from_model(cls, model: keras.Model) -> GreedyPolicy:
        """From a Q-network (functional, `networks.build_q_network`) or a `BCModel` (logits)."""
        kind = model_kind(model)
        layers = model.body + model.stack if kind == "bc" else model.layers
        if any(isinstance(layer, FRAME_LAYERS) for layer in layers):
            call = tf.function(lambda x: model(x, training=False), autograph=False)
            rank = len(model.net_input.shape) if kind == "bc" else len(model.inputs[0].shape) - 1

            def forward(obs: np.ndarray) -> np.ndarray:
                batch = obs.ndim > rank
                values = call(tf.constant(obs if batch else obs[None])).numpy()
                return values if batch else values[0]

            return cls([], kind, forward=forward)
        ops: list[tuple[str, np.ndarray, np.ndarray]] = []
        for layer in layers:
            if isinstance(layer, (keras.layers.InputLayer, keras.layers.Dropout)):
                continue  # dropout is the identity at inference
            if isinstance(layer, keras.layers.Normalization) and not layer.invert:
                mean = _float32(layer.mean).reshape(-1)
                var = _float32(layer.variance).reshape(-1)
                std = np.maximum(np.sqrt(var), np.float32(keras.config.epsilon()))  # as Keras does
                ops.append(("scale", mean, std))
                continue
            if not isinstance(layer, (keras.layers.Dense, EnsembleDense)):
                raise ModelFileError(
                    f"unsupported layer {layer.name!r} ({type(layer).__name__}) in model {model.name!r}"
                )
            activation = keras.activations.serialize(layer.activation)
            if activation not in ("relu", "linear"):
                raise ModelFileError(
                    f"unsupported activation {activation!r} of layer {layer.name!r} in model {model.name!r}"
                )
            kernel = _float32(layer.kernel)
            bias = _float32(layer.bias) if getattr(layer, "use_bias", True) else np.zeros(kernel.shape[1], np.float32)
            ops.append((activation, kernel, bias))
        return cls(ops, kind)

    def values(self, obs: np.ndarray) -> np.ndarray:
        """The model's output for a batch (B, d) or one state (d,): Q-values, or BC logits
        (an ensemble's: log of its members' mean policy, (K, in, out) kernels)."""
        if self.forward is not None:
            return self.forward(np.asarray(obs))
        obs = np.asarray(obs, dtype=np.float32)
        x = np.atleast_2d(obs)
        for op, a, b in self.layers:
            if op == "scale":
                x = (x - a) / b
            else:
                x = x @ a + b
                if op == "relu":
                    x = np.maximum(x, 0.0)
        if x.ndim == 3:  # (K, B, A) members' logits
            probs = np.exp(x - x.max(axis=2, keepdims=True))
            x = np.log((probs / probs.sum(axis=2, keepdims=True)).mean(axis=0) + 1e-12)
        return x if obs.ndim > 1 else x[0]

    def __call__(self, obs: np.ndarray) -> int:
        """The greedy action for one state (d,)."""
        return int(np.argmax(self.values(obs)))


def model_kind(model: keras.Model) -> str:
    """ "bc" for a `BCModel`, "q" for a one-input, one-output functional model; else an error."""
    if isinstance(model, BCModel):
        return "bc"
    if len(getattr(model, "inputs", None) or ()) == 1 and len(model.outputs) == 1:
        return "q"
    raise ModelFileError(f"model {model.name!r} is neither a Q-network nor a BC model")


def evaluate(
    policy: Policy,
    task: str,
    episodes: int,
    seed: int,
    timeout: str = "bootstrap",
    max_steps: int | None = None,
    env_kwargs: dict[str, Any] | None = None,
    progress: Callable[[int], None] | None = None,
) -> EvalResult:
    """Play `episodes` episodes of `policy` on task `task`'s plain env (episode i: seed + i).

    `timeout`/`max_steps`/`env_kwargs` are the training run's: in time-aware mode the
    observation carries the time feature the agent learned with. Goal-count tasks replay the
    same seeds on the task env, where the car restarts at the flag, to count the goals.
    `progress(done)` is called after each episode.
    """
    if episodes < 1:
        raise ConfigError(f"episodes must be ≥ 1, got {episodes}")
    if timeout not in TIMEOUT_MODES:
        raise ConfigError(f"unknown timeout mode {timeout!r}; expected one of {TIMEOUT_MODES}")
    seeds = range(seed, seed + episodes)
    with make_plain_env(task, timeout, max_steps, env_kwargs=env_kwargs) as env:
        played = play(env, policy, seeds, progress=progress)
    goals = None
    if get_task(task).goal_count:
        with make_task(task, timeout, max_steps, env_kwargs=env_kwargs) as env:
            goals = play(env, policy, seeds).goals
    return EvalResult(
        task,
        getattr(policy, "kind", "custom"),
        seed,
        played.returns,
        played.lengths,
        goals,
        timeout,
        dict(env_kwargs or {}),
    )


def record_video(
    policy: Policy,
    task: str,
    directory: str | Path,
    episodes: int,
    seed: int,
    timeout: str = "bootstrap",
    max_steps: int | None = None,
    env_kwargs: dict[str, Any] | None = None,
) -> list[Path]:
    """Play `episodes` greedy episodes on the plain env (as `evaluate`) and save each as an MP4
    in `directory` with Gymnasium's `RecordVideo` (needs `moviepy`); returns the files."""
    prefix = task_slug(task)
    check_video(directory, prefix)
    env = make_plain_env(task, timeout, max_steps, render_mode="rgb_array", env_kwargs=env_kwargs)
    env = video_env(env, directory, prefix)
    play(env, policy, range(seed, seed + episodes))
    env.close()  # RecordVideo writes the last episode's file
    return sorted(Path(directory).glob(f"{prefix}-episode-*.mp4"))


def load_model(path: str | Path) -> keras.Model:
    """A saved `.keras` model (safe mode), or a one-line `ModelFileError` naming the problem."""
    path = Path(path)
    if not path.exists():
        raise ModelFileError(f"{path}: no such file or directory")
    if path.is_dir():
        raise ModelFileError(f"{path}: is a directory, not a .keras model file")
    if path.suffix != ".keras":
        raise ModelFileError(f"{path}: not a .keras model file (expected the .keras suffix)")
    if not zipfile.is_zipfile(path):  # Keras would call such a file "not found"
        raise ModelFileError(f"{path}: corrupt or not a Keras model (not a .keras zip archive)")
    try:
        return keras.saving.load_model(path, compile=False)  # weights only: no optimizer needed
    except Exception as error:
        detail = (str(error).strip().splitlines() or [""])[0]
        raise ModelFileError(f"{path}: Keras cannot load it ({type(error).__name__}: {detail})") from error


def check_model_fits(
    model: keras.Model, obs_shape: int | tuple[int, ...], n_actions: int, path: str | Path, task: str | None = None
) -> None:
    """`ModelFileError` unless `model` maps observations of `obs_shape` (a vector's features, or
    the frames' shape) to `n_actions` outputs."""
    if model_kind(model) == "bc":
        inputs, outputs = model.net_input.shape, model.n_actions
    else:
        inputs, outputs = tuple(model.inputs[0].shape[1:]), model.outputs[0].shape[-1]
    expected = (obs_shape,) if isinstance(obs_shape, int) else tuple(obs_shape)
    name = f"task {task}" if task else "the task"
    if tuple(inputs) != expected:
        if len(inputs) == len(expected) == 1:
            raise ModelFileError(f"{path}: model expects {inputs[0]} observation features, {name} gives {expected[0]}")
        raise ModelFileError(f"{path}: model expects observations of shape {tuple(inputs)}, {name} gives {expected}")
    if outputs != n_actions:
        raise ModelFileError(f"{path}: model has {outputs} outputs, {name} has {n_actions} actions")


@dataclass(frozen=True)
class EvalSettings:
    """Where a policy was loaded from and the env settings it was trained with."""

    model_path: Path
    task: str
    timeout: str = "bootstrap"
    max_steps: int | None = None
    env_kwargs: dict[str, Any] = field(default_factory=dict)


def load_policy(
    target: str | Path,
    policy: str | None = None,
    task: str | None = None,
    max_steps: int | None = None,
    env_kwargs: dict[str, Any] | None = None,
) -> tuple[GreedyPolicy, EvalSettings]:
    """The greedy policy saved at `target` (a run directory or a `.keras` file) and its settings.

    `policy` picks the run directory's model: "q" (`q_network.keras`, the default) or "bc"
    (`bc_model.keras`); a `.keras` file is played as it is, and must be of kind `policy` if
    that is given. Task, timeout, max_steps and env kwargs come from the `config.json` in the
    run directory or beside the file; `task`, `max_steps` and `env_kwargs` override them (a
    task other than the config's keeps none of its env settings), and `task` is required
    without one.
    """
    if policy is not None and policy not in POLICY_FILES:
        raise ConfigError(f"policy {policy!r} is not one of {sorted(POLICY_FILES)}")
    target = Path(target)
    if not target.exists():  # before looking for a config.json beside it
        raise ModelFileError(f"{target}: no such file or directory")
    model_path = target / POLICY_FILES[policy or "q"] if target.is_dir() else target
    config = read_config(model_path.parent / "config.json", task)
    if target.is_dir() and not model_path.exists():
        built_in = config is not None and config.expert_loss in BUILT_IN  # a user's method is not imported here
        why = (
            f" (expert loss {config.expert_loss!r} fits no BC model)"
            if config and built_in and not config.uses_bc
            else ""
        )
        raise ModelFileError(f"{target}: run directory without {model_path.name}{why}")
    model = load_model(model_path)
    try:
        greedy = GreedyPolicy.from_model(model)
    except ModelFileError as error:
        raise ModelFileError(f"{model_path}: {error}") from None
    if policy is not None and greedy.kind != policy:
        raise ModelFileError(f"{model_path}: a {greedy.kind!r} model, not a {policy!r} one")
    if task is None:
        if config is None:
            raise ConfigError(f"{target}: no config.json beside the model says which task it plays; pass --task")
        task = config.task
    own = config if config is not None and task == config.task else None  # the config's env settings apply
    settings = EvalSettings(
        model_path,
        task,
        config.timeout if config else "bootstrap",
        max_steps if max_steps is not None else own.max_steps if own else None,
        dict(env_kwargs) if env_kwargs is not None else dict(own.env_kwargs) if own else {},
    )
    spaces = task_spaces(settings.task, settings.env_kwargs)
    obs_shape = spaces.layout.frames.shape if spaces.layout.frames is not None else spaces.input_dim(settings.timeout)
    check_model_fits(model, obs_shape, spaces.n_actions, model_path, settings.task)
    return greedy, settings


def read_config(path: Path, task: str | None = None) -> Config | None:
    """The run's `config.json`, None when there is none, a `ConfigError` naming it when unusable.
    Read for its settings only: the module of a method of the user's own is not imported (its code
    does not run). `task`, the task the run is played on instead of its own, stands in for the id of
    a Python env object, which no other process can make (`unmade_env`)."""
    if not path.is_file():
        return None
    try:
        fields = json.loads(path.read_text())
        if not isinstance(fields, dict):
            raise ConfigError("expected a JSON object of config fields")
        if unmade_env(fields.get("task")):
            if task is None:
                raise ConfigError(
                    f"trained on a Python env object ({fields['task']}), which no other process can make: "
                    "evaluate it from Python, DQfD.load(path, env=...).evaluate(), or here with --env ID, "
                    "a registered id of the same env"
                )
            fields = {**fields, "task": task}
        with playing_saved_run():
            return Config.from_dict(fields)
    except json.JSONDecodeError as error:
        raise ConfigError(f"{path}: not valid JSON ({error})") from None
    except (OSError, TypeError, ValueError) as error:
        raise ConfigError(f"{path}: {error}") from None
