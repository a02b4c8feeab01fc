"""`DQfD`: Algorithm 1 from Python, exactly as `train.py` runs it (the same seed and settings give
the same metrics), with an env and demonstrations given as Python objects.

    model = DQfD("cartpole", demos="imperfect", seed=0, total_steps=20_000)   # any Config field
    model.learn(20_000)                       # steps 1–5; a second learn goes on with the same run
    model.predict(obs)                        # the greedy action(s), in NumPy (not Keras' predict)
    model.evaluate(100)                       # evaluate.py's EvalResult
    model.save("runs/mine")                   # a run directory evaluate.py and train.py --resume read

Nothing is written to disk unless asked: `out=` trains into a run directory as `train.py --out`
does (checkpoints, atomic files, the lock), `save` writes one at the end.
"""

from __future__ import annotations

import dataclasses
import json
import sys
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from dqfd_bc_keras import demos as demo_io
from dqfd_bc_keras.core.config import Config, unknown_field
from dqfd_bc_keras.core.memory import check_memory
from dqfd_bc_keras.core.methods import BUILT_IN, METHODS, Method, register
from dqfd_bc_keras.demos.recording import callable_name, try_demonstrator
from dqfd_bc_keras.envs.frames import as_frames
from dqfd_bc_keras.envs.make import checked_spaces, task_spaces
from dqfd_bc_keras.envs.objects import PYTHON_ENV_PREFIX, env_id_of
from dqfd_bc_keras.errors import BrokenRunError, ConfigError, DqfdWarning, RunDirectoryError, one_line
from dqfd_bc_keras.evaluation import EvalResult, GreedyPolicy
from dqfd_bc_keras.runs.directory import RunDirectory, continue_run, save_run, saved_config, train
from dqfd_bc_keras.runs.writers import is_run
from dqfd_bc_keras.seeds import EVAL_SEED
from dqfd_bc_keras.training.loop import Learner, build, evaluate_at, record_demos, run_evaluation, train_with_callback
from dqfd_bc_keras.training.records import EpisodeRow, EvalRow
from dqfd_bc_keras.training.state import TrainingState

EnvLike = str | gym.Env | Callable[[], gym.Env]
DemosLike = demo_io.DemoDataset | str | Path | Callable[[np.ndarray], int] | None


class DQfD:
    """Deep Q-learning from demonstrations (with a BC model and the Bayesian expert loss by default).

    `env`: a preset name or Gymnasium id, a `gymnasium.Env` or a zero-argument factory of one. An
    env object no id can make is registered in this process (`envs.env_id_of`): evaluation plays
    a fresh copy of it (the factory's, or a deep copy of the instance; an instance that cannot be
    copied is played itself, so its evaluation episodes, reset with their own seeds, come between
    training's). `max_steps=` gives an env without a time limit of its own one.
    `demos`: a `DemoDataset`, a `.npz` path, `minari:ID`, or a demonstrator recorded for
    `demo_episodes` episodes: a preset expert's name, `module:function`, a `.keras` model or a Python
    callable obs → action. `expert_loss`: a registered method's name or a `Method`. `out`: a run
    directory to train into. Any other keyword is a Config field.
    """

    def __init__(
        self,
        env: EnvLike = "cartpole",
        demos: DemosLike = None,
        *,
        expert_loss: str | Method | None = None,
        seed: int = 0,
        out: str | Path | None = None,
        **fields: Any,
    ) -> None:
        for key in fields:
            if key == "task" or key not in Config.__dataclass_fields__:
                raise ConfigError(
                    f"DQfD({key}=…): " + ("the task is the env argument" if key == "task" else unknown_field(key))
                )
        task, env_kwargs, limit = env_id_of(env)
        if isinstance(expert_loss, Method):
            expert_loss = _method_name(expert_loss)
        settings = {"env_kwargs": env_kwargs, "seed": seed, **({"max_steps": limit} if limit else {}), **fields}
        if expert_loss is not None:
            settings["expert_loss"] = expert_loss
        dataset, self._source, rule, expert = _demonstrations(demos, task, settings)
        if expert is not None:
            settings["expert"] = expert
        self.config = Config.for_task(task, **settings)
        checked_spaces(self.config)  # a bad env or torso refused here, not at `learn`
        if rule is not None and self.config.uses_demos:  # step 1 for a callable: recorded now, given to training
            dataset = record_demos(self.config, rule)
        elif dataset is None and self.config.uses_demos:
            try_demonstrator(self.config)  # a named demonstrator answers (or fails) here, not at `learn`
        self.dataset, self.out = dataset, None if out is None else Path(out)
        self.learner: Learner | None = None
        self.state: TrainingState | None = None
        self._run: RunDirectory | None = None
        self._policy: GreedyPolicy | None = None

    # --- Algorithm 1 ------------------------------------------------------------------------------
    def learn(
        self,
        total_timesteps: int | None = None,
        callback: Callable[[EpisodeRow | EvalRow], object] | None = None,
        progress_bar: bool = False,
    ) -> DQfD:
        """Train `total_timesteps` more env steps (the config's `total_steps` if not given; steps 1–2
        at the first call); `callback` is given each episode's and evaluation's row, and a `False`
        from it stops training there. Early stopping (`early_stop_window`) ends it too."""
        if total_timesteps is None:
            total_timesteps = self.config.total_steps
        if int(total_timesteps) < 1:
            raise ConfigError(f"learn(total_timesteps={total_timesteps}): must be ≥ 1")
        self._policy = None  # the weights change
        done = 0 if self.learner is None else int(self.learner.interaction.env_steps.numpy())
        budget = done + int(total_timesteps)
        if self.out is not None:
            result = (
                train(
                    dataclasses.replace(self.config, total_steps=budget),
                    self.out,
                    self.dataset,
                    quiet=not progress_bar,
                    source=self._source,
                    callback=callback,
                )
                if self._run is None
                else continue_run(self._run, budget, callback)
            )
            self._run = result.run
            self.learner, self.state = self._run.learner, self._run.state
        else:
            if self.learner is None:
                config = dataclasses.replace(self.config, total_steps=budget)
                check_memory(config, checked_spaces(config))
                self.learner, self.state = build(config, self.dataset)[0], TrainingState()
            else:
                self.learner.extend(budget)
            self._train(callback, progress_bar)
        self.config = self.learner.config
        return self

    def _train(self, callback: Callable[[EpisodeRow | EvalRow], object] | None, progress_bar: bool) -> None:
        """Steps 3–5 in memory: the rows kept in `state`, given to `callback`."""
        learner, state = self.learner, self.state
        bar = None
        if progress_bar:
            from tqdm import tqdm

            bar = tqdm(
                total=learner.config.total_steps, unit="step", initial=int(learner.interaction.env_steps.numpy())
            )

        def on_episode(_: Learner, __: TrainingState, row: EpisodeRow) -> None:
            if bar is not None:
                bar.update(row.env_step - bar.n)

        def on_eval(points: list[int]) -> list[EvalRow]:
            return evaluate_at(learner, state, points)

        try:
            train_with_callback(learner, state, on_episode, on_eval, callback)
        finally:
            if bar is not None:
                bar.close()

    # --- the trained policy -----------------------------------------------------------------------
    def predict(self, obs: Any, deterministic: bool = True) -> int | np.ndarray:
        """The greedy action for one observation as the env gives it (an int), or for a batch of them
        (an int array): observations are flattened, and frames kept, as in training. Only greedy
        actions exist (`deterministic=False` is refused)."""
        if not deterministic:
            raise ConfigError("predict(deterministic=False): DQfD's policy is the greedy one")
        if self.config.timeout == "time-aware":
            raise ConfigError("predict: a time-aware run also needs the time left; play it with evaluate()")
        learner = self._trained()
        layout = task_spaces(self.config.task, self.config.env_kwargs).layout
        if layout.image:
            x = as_frames(obs, layout.frames.channels_first)
            batch = None if x.ndim == len(layout.frames.shape) else len(x)
        else:
            batch = _batch_size(layout.kept, obs)
            x = layout.flatten(obs, batch)
        if self._policy is None:  # one copy of the weights (one traced call for frames) until learn changes them
            self._policy = GreedyPolicy.from_model(learner.agent.q_network)
        values = self._policy.values(x)
        return int(np.argmax(values)) if batch is None else np.argmax(values, axis=-1).astype(np.int64)

    def evaluate(self, episodes: int = 100, seed: int = EVAL_SEED) -> EvalResult:
        """Greedy episodes on the plain env, as `evaluate.py` plays them (episode i reset with `seed` + i)."""
        return run_evaluation(self.config, self._trained().agent, episodes, seed)

    def _trained(self) -> Learner:
        if self.learner is None:
            raise ConfigError("the model has not been trained: call learn() first")
        return self.learner

    # --- files ------------------------------------------------------------------------------------
    def save(self, path: str | Path) -> Path:
        """Write a complete run directory at `path` (replacing a run there). What a later process
        cannot make again (an env object, a Python callable as the expert) is said in one warning."""
        learner = self._trained()
        c = self.config
        lost = [
            what
            for what, yes in (
                (
                    f"the env {c.task} (an object: DQfD.load(path, env=...) needs it again)",
                    c.task.startswith(PYTHON_ENV_PREFIX),
                ),
                (
                    f"the method {c.expert_loss!r} (registered in this process: register it again to learn more)",
                    c.expert_loss not in BUILT_IN and ":" not in c.expert_loss,
                ),
                (f"the expert {c.expert!r} (its demonstrations are saved)", c.expert.startswith("python callable ")),
            )
            if yes
        ]
        if lost:
            warnings.warn(f"{path}: a later process cannot make {' nor '.join(lost)}", DqfdWarning, stacklevel=2)
        if self._run is not None and Path(path) == self.out:
            return self.out
        save_run(path, learner, self.state, self._source)
        return Path(path)

    @classmethod
    def load(cls, path: str | Path, env: EnvLike | None = None) -> DQfD:
        """The model saved in run directory `path`, ready to predict, evaluate or learn more; `env`
        gives the env again (required when it was a Python object)."""
        path = Path(path)
        if not (path / "checkpoints" / "latest.json").is_file():
            held = (
                "does not exist"
                if not path.exists()
                else "is not a directory"
                if not path.is_dir()
                else ("has no checkpoint (checkpoints/latest.json)" if is_run(path) else "is not a run directory")
            )
            raise RunDirectoryError(f"{path} {held}: DQfD.load reads a run directory that save, out= or train.py wrote")
        try:
            saved_task = json.loads((path / "config.json").read_text())["task"]
        except (OSError, ValueError, KeyError, TypeError) as error:
            raise BrokenRunError(f"{path / 'config.json'}: cannot be read ({one_line(error)})") from None
        changes = {}
        if env is not None:
            task, env_kwargs, _ = env_id_of(env, saved_task if saved_task.startswith(PYTHON_ENV_PREFIX) else None)
            changes = {"task": task, **({} if isinstance(env, str) else {"env_kwargs": env_kwargs})}
        elif saved_task.startswith(PYTHON_ENV_PREFIX) and saved_task not in gym.registry:
            raise ConfigError(
                f"{path}: trained on a Python env object ({saved_task}); give it again: DQfD.load(path, env=...)"
            )
        config = dataclasses.replace(saved_config(path), **changes)
        given = path / "checkpoints" / "demos_given.npz"
        dataset = demo_io.load(given) if given.is_file() else None
        learner = build(config, dataset, fresh=False)[0]
        run = RunDirectory(config, path, learner, TrainingState(), quiet=True)
        run.restore_checkpoint()
        model = cls.__new__(cls)
        model.config, model.dataset, model.out, model._run, model._policy = config, dataset, None, None, None
        model.learner, model.state = learner, run.state
        demos_json = path / "demonstrations.json"
        model._source = json.loads(demos_json.read_text()).get("source") if demos_json.is_file() else None
        return model

    def __repr__(self) -> str:
        return f"DQfD({self.config.task!r}, expert_loss={self.config.expert_loss!r}, seed={self.config.seed})"


def _demonstrations(
    demos: DemosLike, task: str, settings: dict[str, Any]
) -> tuple[demo_io.DemoDataset | None, str | None, Callable | None, str | None]:
    """What `demos` gives: (a dataset given or loaded, its source, a Python rule to record, the
    config's `expert`), None where it gives nothing; `settings` make the task's preset."""
    if isinstance(demos, demo_io.DemoDataset):
        return demos, "python", None, demo_io.given_expert("a Python DemoDataset", demos)
    if isinstance(demos, (str, Path)) and (str(demos).endswith(".npz") or str(demos).startswith("minari:")):
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


def _method_name(method: Method) -> str:
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


def _batch_size(space: gym.Space, obs: Any) -> int | None:
    """None for one observation of `space` (its numeric parts), else the length of the batch."""
    if isinstance(space, gym.spaces.Dict):
        key = next(iter(space.spaces))
        return _batch_size(space.spaces[key], obs[key])
    if isinstance(space, gym.spaces.Tuple):
        return _batch_size(space.spaces[0], obs[getattr(space, "indices", range(1))[0]])
    x = np.asarray(obs)
    return None if x.ndim == len(space.shape or ()) else len(x)
