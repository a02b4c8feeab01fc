"""`DQfD`: Algorithm 1 from Python, exactly as `train.py` runs it (the same seed and settings give
the same metrics), with an env and demonstrations given as Python objects, in Stable-Baselines3's shape.

    model = DQfD("cartpole", demos="imperfect", seed=0, total_steps=20_000)   # any Config field
    model.learn(20_000)                       # steps 1–5; a second learn goes on with the same run
    action, _ = model.predict(obs)            # SB3's (action, state): the greedy action(s), in NumPy
    model.evaluate(100)                       # evaluate.py's EvalResult
    model.save("runs/mine")                   # a run directory evaluate.py and train.py --resume read
    DQfD.load("runs/mine", resume=True).learn()   # train.py --resume --out runs/mine

Nothing is written to disk unless asked: `out=` trains into a run directory as `train.py --out`
does (checkpoints, atomic files, the lock), `save` writes one at the end. A learn stopped by an
exception or Ctrl-C keeps the step it reached: the next learn goes on from there (in the same run
directory with `out=`).
"""

from __future__ import annotations

import dataclasses
import json
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from dqfd_bc_keras import demos as demo_io
from dqfd_bc_keras.arguments import (
    Callback,
    Callbacks,
    DemosLike,
    callbacks,
    check_bool,
    check_int,
    check_path,
    demonstrations,
    demonstrator,
    method_name,
    step_bar,
    told,
)
from dqfd_bc_keras.core.config import Config, unknown_field
from dqfd_bc_keras.core.memory import check_memory
from dqfd_bc_keras.core.methods import BUILT_IN, Method
from dqfd_bc_keras.demos.recording import try_demonstrator
from dqfd_bc_keras.envs.given import network_input
from dqfd_bc_keras.envs.make import TaskSpaces, checked_spaces, make_plain_env, task_spaces
from dqfd_bc_keras.envs.objects import PYTHON_ENV_PREFIX, env_id_of, stand_in, unmade_env
from dqfd_bc_keras.envs.observations import FlattenObservation, describe
from dqfd_bc_keras.errors import (
    BrokenRunError,
    ConfigError,
    DqfdWarning,
    OutputExistsError,
    RunDirectoryError,
    one_line,
)
from dqfd_bc_keras.evaluation import EvalResult, GreedyPolicy
from dqfd_bc_keras.files import DirectoryLock
from dqfd_bc_keras.runs.directory import RunDirectory, continue_run, save_run, train
from dqfd_bc_keras.runs.resume import saved_config
from dqfd_bc_keras.runs.writers import COMPLETE, is_run
from dqfd_bc_keras.seeds import EVAL_SEED, MAX_SEED
from dqfd_bc_keras.training.demonstrations import record_demos
from dqfd_bc_keras.training.loop import Learner, build, evaluate_at, run_evaluation, train_with_callback
from dqfd_bc_keras.training.state import TrainingState

EnvLike = str | gym.Env | Callable[[], gym.Env]


class DQfD:
    """Deep Q-learning from demonstrations (with a BC model and the Bayesian expert loss by default).

    `env`: a preset name or Gymnasium id, a `gymnasium.Env` or a zero-argument factory of one. An
    env object no id can make is registered in this process (`envs.env_id_of`): evaluation plays
    a fresh copy of it (the factory's, or a deep copy of the instance; an instance that cannot be
    copied is played itself, so its evaluation episodes, reset with their own seeds, come between
    training's). `max_steps=` gives an env without a time limit of its own one.
    `demos`: a `DemoDataset`, a `.npz` path, `minari:ID`, or a demonstrator recorded for
    `demo_episodes` episodes: a preset expert's name, `module:function`, a `.keras` model or a Python
    callable obs → action; `expert=` (the command line's word) takes the demonstrators alone.
    `expert_loss`: a registered method's name or a `Method`. `out`: a run directory to train into.
    Any other keyword is a Config field.
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
        demos = demonstrator(demos, fields.pop("expert", None))
        if out is not None:
            check_path("DQfD", "out", out)
        task, env_kwargs, limit = env_id_of(env)
        if isinstance(expert_loss, Method):
            expert_loss = method_name(expert_loss)
        settings = {"env_kwargs": env_kwargs, "seed": seed, **({"max_steps": limit} if limit else {}), **fields}
        if expert_loss is not None:
            settings["expert_loss"] = expert_loss
        dataset, self._source, rule, expert = demonstrations(demos, task, settings)
        if expert is not None:
            settings["expert"] = expert
        if dataset is not None:
            settings["demo_episodes"] = demo_io.given_episodes("demos", dataset, fields.get("demo_episodes"))
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
    def learn(self, total_timesteps: int | None = None, callback: Callbacks = None, progress_bar: bool = False) -> DQfD:
        """Train `total_timesteps` more env steps; without a number, up to the config's `total_steps`
        (the rest of a learn that was stopped), or `total_steps` more once they are done. The first
        call runs steps 1–2. `callback`, a function or a list of them, is given each episode's and
        evaluation's row; a `False` from any stops training there, as early stopping
        (`early_stop_window`) does. Stopped by an exception or Ctrl-C, the model keeps the step it
        reached and the next learn goes on from it, in the same run directory with `out=`."""
        given = callbacks(callback)
        check_bool("learn", "progress_bar", progress_bar)
        done = self.num_timesteps
        if total_timesteps is None:
            budget = self.config.total_steps if done < self.config.total_steps else done + self.config.total_steps
        else:
            check_int("learn", "total_timesteps", total_timesteps, 1)
            budget = done + int(total_timesteps)
        self._policy = None  # the weights change
        bar = step_bar(budget, done) if progress_bar else None
        try:
            tell = told(given, bar)
            if self.out is None:
                self._learn_in_memory(budget, tell)
            elif self._run is None:
                if (self.out / "checkpoints" / "latest.json").is_file():
                    raise OutputExistsError(
                        f"{self.out} already holds a run: DQfD.load({str(self.out)!r}, resume=True) continues it; "
                        "choose another out= for a new one"
                    )
                config = dataclasses.replace(self.config, total_steps=budget)

                def started(run: RunDirectory) -> None:  # kept however training ends: the next learn goes on
                    self._run = run

                train(config, self.out, self.dataset, quiet=True, source=self._source, callback=tell, started=started)
            else:
                continue_run(self._run, budget, tell)
        finally:
            if bar is not None:
                bar.close()
            if self._run is not None:
                self.learner, self.state = self._run.learner, self._run.state
            if self.learner is not None:
                self.config = self.learner.config
        return self

    def _learn_in_memory(self, budget: int, tell: Callback | None) -> None:
        """Steps 1–2 at the first call; steps 3–5 to `budget` steps, the rows kept in `state`."""
        if self.learner is None:
            config = dataclasses.replace(self.config, total_steps=budget)
            check_memory(config, checked_spaces(config))
            self.learner, self.state = build(config, self.dataset)[0], TrainingState()
        else:
            self.learner.extend(budget)
        learner, state = self.learner, self.state
        assert state is not None  # set with the learner
        train_with_callback(learner, state, lambda *_: None, lambda points: evaluate_at(learner, state, points), tell)

    # --- the trained policy, in Stable-Baselines3's terms ------------------------------------------
    def predict(
        self, observation: Any, state: Any = None, episode_start: Any = None, deterministic: bool = True
    ) -> tuple[int | np.ndarray, None]:
        """SB3's `predict`: (the greedy action, None). One observation as the env gives it gets an
        int, a batch of them an int64 array (observations flattened, frames kept, as in training).
        The policy has no recurrent state: `state` and `episode_start` are taken and unused, and the
        state returned is None. Only greedy actions exist (`deterministic=False` is refused)."""
        check_bool("predict", "deterministic", deterministic)
        if not deterministic:
            raise ConfigError("predict(deterministic=False): DQfD's policy is the greedy one")
        if self.config.timeout == "time-aware":
            raise ConfigError("predict: a time-aware run also needs the time left; play it with evaluate()")
        learner = self._trained()
        x, batch = network_input(self._spaces().layout, observation)
        if self._policy is None:  # one copy of the weights (one traced call for frames) until learn changes them
            self._policy = GreedyPolicy.from_model(learner.agent.q_network)
        values = self._policy.values(x)
        return (int(np.argmax(values)) if batch is None else np.argmax(values, axis=-1).astype(np.int64)), None

    def evaluate(self, episodes: int = 100, seed: int = EVAL_SEED) -> EvalResult:
        """Greedy episodes on the plain env, as `evaluate.py` plays them (episode i reset with `seed` + i)."""
        check_int("evaluate", "episodes", episodes, 1)
        check_int("evaluate", "seed", seed, 0, MAX_SEED)
        return run_evaluation(self.config, self._trained().agent, int(episodes), int(seed))

    @property
    def num_timesteps(self) -> int:
        """Env steps trained on so far (SB3's `num_timesteps`)."""
        return 0 if self.learner is None else int(self.learner.interaction.env_steps.numpy())

    @property
    def observation_space(self) -> gym.Space:
        """The env's own observation space: what `predict` takes."""
        return self._spaces().layout.space

    @property
    def action_space(self) -> gym.spaces.Discrete:
        return gym.spaces.Discrete(self._spaces().n_actions)

    def get_env(self) -> gym.Env:
        """A new env of the task as `evaluate` plays it, giving observations as `predict` takes them.
        SB3 returns its training VecEnv; this is a `gymnasium.Env` (`DummyVecEnv([model.get_env])`
        makes a VecEnv of it): training's own env counts interactions, and is not to be stepped."""
        c = self.config
        env = make_plain_env(c.task, c.timeout, c.max_steps, env_kwargs=c.env_kwargs)
        if isinstance(env, gym.wrappers.TimeLimit) and isinstance(env.env, FlattenObservation):
            env.env = env.env.env  # the env's own observations (a dict, a state's index), as predict takes them
        return env

    def _spaces(self) -> TaskSpaces:
        return task_spaces(self.config.task, self.config.env_kwargs)

    def _trained(self) -> Learner:
        if self.learner is None:
            raise ConfigError("the model has not been trained: call learn() first")
        return self.learner

    # --- files ------------------------------------------------------------------------------------
    def save(self, path: str | Path) -> Path:
        """Write a complete run directory at `path` (replacing a run there); the model's own run
        directory (`out=`, `load(resume=True)`) is finished where it is. What a later process cannot
        make again (an env object, a Python callable as the expert) is said in one warning."""
        check_path("save", "path", path)
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
        if self._run is not None and self.out is not None and Path(path).resolve() == self.out.resolve():
            if not (self.out / COMPLETE).is_file():  # a learn stopped halfway: the run ends at the step it reached
                with DirectoryLock(self.out):
                    self._run.finish()
            return self.out
        assert self.state is not None  # set with the learner
        save_run(path, learner, self.state, self._source)
        return Path(path)

    @classmethod
    def load(cls, path: str | Path, env: EnvLike | None = None, resume: bool = False) -> DQfD:
        """The model saved in run directory `path`, ready to predict, evaluate or learn more; `env`
        gives the env again (required when it was a Python object). `resume=True`: `learn` goes on
        training into `path`, as `train.py --resume --out path` does; else `path` is left as it is."""
        check_path("DQfD.load", "path", path)
        check_bool("DQfD.load", "resume", resume)
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
            saved = json.loads((path / "config.json").read_text())
            saved_task = saved["task"]
        except (OSError, ValueError, KeyError, TypeError) as error:
            raise BrokenRunError(f"{path / 'config.json'}: cannot be read ({one_line(error)})") from None
        changes: dict[str, Any] = {}
        if isinstance(env, str) and unmade_env(saved_task):
            stand_in(saved_task, env)  # the id makes the object's env, under the run's own id
        elif env is not None:
            task, env_kwargs, _ = env_id_of(env, saved_task if saved_task.startswith(PYTHON_ENV_PREFIX) else None)
            changes = {"task": task, **({} if isinstance(env, str) else {"env_kwargs": env_kwargs})}
        elif unmade_env(saved_task):
            raise ConfigError(
                f"{path}: trained on a Python env object ({saved_task}); give it again: DQfD.load(path, env=...), "
                "the object or a registered id of the same env"
            )
        config = dataclasses.replace(saved_config(path), **changes)
        if env is not None:
            _check_same_observations(path, saved.get("observation"), config)
        given = path / "checkpoints" / "demos_given.npz"
        dataset = demo_io.load(given) if given.is_file() else None
        learner = build(config, dataset, fresh=False)[0]
        run = RunDirectory(config, path, learner, TrainingState(), quiet=True)
        try:
            run.restore_checkpoint()
        except BrokenRunError as error:
            if env is None:
                raise
            spaces = task_spaces(config.task, config.env_kwargs)
            raise ConfigError(  # the actions: config.json records only the observations
                f"DQfD.load({str(path)!r}, env=...): the env given ({describe(spaces.layout.space)}, "
                f"{spaces.n_actions} actions) does not fit the networks the run trained "
                f"({one_line(error.__context__ or error)}): give the env it was trained on"
            ) from None
        model = cls.__new__(cls)
        model.config, model.dataset, model._policy = config, dataset, None
        model.out, model._run = (path, run) if resume else (None, None)
        model.learner, model.state = learner, run.state
        demos_json = path / "demonstrations.json"
        model._source = json.loads(demos_json.read_text()).get("source") if demos_json.is_file() else None
        return model

    def __repr__(self) -> str:
        return f"DQfD({self.config.task!r}, expert_loss={self.config.expert_loss!r}, seed={self.config.seed})"


def _check_same_observations(path: Path, saved: dict | None, config: Config) -> None:
    """The env given to `load` observes what the run's networks take (config.json's "observation")."""
    given = task_spaces(config.task, config.env_kwargs).layout.to_dict()
    if saved and (saved.get("features"), saved.get("frames")) != (given["features"], given["frames"]):
        raise ConfigError(
            f"DQfD.load({str(path)!r}, env=...): the run was trained on observations {saved.get('space')} "
            f"({saved.get('features')} features), and the env given observes {given['space']} "
            f"({given['features']} features): give the env it was trained on"
        )
