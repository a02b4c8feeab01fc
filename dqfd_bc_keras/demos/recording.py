"""Demonstrators and recording: a task's scripted experts, a user's rule `module:function` or a
saved `.keras` model made into a demonstrator (`make_demonstrator`), played on a task env, its
complete episodes kept as a dataset (`record`, `rollout`, `EpisodeRecorder`, which also records
the agent's greedy policy and the agent itself while it trains). `experts.py` is the public face
of the demonstrators.

A user's rule runs inside the recording loop: whatever it raises or answers that is no action is
one line naming the rule and its file:line, and `try_demonstrator` asks it for its first action
before TensorFlow loads.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, SupportsFloat, cast

import numpy as np

from dqfd_bc_keras.choices import EXPERT_NAMES
from dqfd_bc_keras.demos.dataset import ARRAYS, DemoDataset, DemoMeta
from dqfd_bc_keras.envs.episodes import Policy, play
from dqfd_bc_keras.envs.make import get_task, make_plain_env, make_task, task_spaces
from dqfd_bc_keras.errors import ConfigError, DqfdError, one_line
from dqfd_bc_keras.plugins import bare_id, load, raised_at, where
from dqfd_bc_keras.seeds import demo_seed
from dqfd_bc_keras.tasks import NOT_REMADE, TASKS, Rule, check_demonstrator, families, family_preset

if TYPE_CHECKING:
    from dqfd_bc_keras.core.config import Config


def _defined_at(rule: Rule) -> str:
    """The file:line of `rule`'s definition (a function's), else its module's name."""
    code = getattr(rule, "__code__", None)
    return where(code.co_filename, code.co_firstlineno) if code else getattr(rule, "__module__", "?")


def _check_choice(kind: str, value: str, choices: Sequence[str]) -> None:
    if value not in choices:
        raise ConfigError(f"unknown {kind} {value!r}; valid choices: {', '.join(choices)}")


@dataclass(frozen=True)
class Demonstrator:
    """obs -> action: `rule`, replaced with prob. epsilon by a uniformly random action.

    What the rule raises, and an answer that is not an int action in [0, n_actions) (a float, a
    bool, a string, an out-of-range int; a numpy integer or a 0-d integer array is one), is a
    `ConfigError` naming the rule and where it is: a rule is often the user's code."""

    name: str
    rule: Rule = field(repr=False)
    n_actions: int
    epsilon: float
    rng: np.random.Generator = field(repr=False, compare=False)

    def __call__(self, obs: np.ndarray) -> int:
        if self.rng.random() < self.epsilon:
            return int(self.rng.integers(self.n_actions))
        try:
            action = self.rule(np.asarray(obs))
        except DqfdError:
            raise
        except Exception as error:
            code = getattr(self.rule, "__code__", None)
            raise ConfigError(
                f"{self.name} raised {one_line(error)} ({raised_at(error, code.co_filename if code else None)})"
            ) from None
        try:
            value = np.asarray(action)
            ok = value.ndim == 0 and value.dtype.kind in "iu" and 0 <= value < self.n_actions
        except (TypeError, ValueError):
            ok = False
        if not ok:
            raise ConfigError(
                f"{self.name} returned {action!r} ({type(action).__name__}); a demonstrator returns an "
                f"int action in [0, {self.n_actions}) ({_defined_at(self.rule)})"
            )
        return int(value)


def _check_epsilon(epsilon: float) -> float:
    if not 0.0 <= epsilon <= 1.0:
        raise ConfigError(f"epsilon must be in [0, 1], got {epsilon!r}")
    return float(epsilon)


def make_expert(family: str, name: str, epsilon: float = 0.0, seed: int | None = None) -> Demonstrator:
    """Build a validated expert whose random actions come from its own generator seeded with `seed`."""
    _check_choice("family", family, families())
    preset = family_preset(family)
    if name not in preset.experts:
        raise ConfigError(
            f"unknown expert name {name!r}; valid choices: {', '.join(preset.experts)} (the scripted "
            f"experts of {family}: choose one with --expert)"
        )
    return Demonstrator(
        f"{family}/{name}",
        preset.experts[name],
        task_spaces(preset.name).n_actions,
        _check_epsilon(epsilon),
        np.random.default_rng(seed),
    )


def make_demonstrator(
    name: str, task: str, epsilon: float = 0.0, seed: int | None = None, env_kwargs: dict | None = None
) -> Demonstrator:
    """The demonstrator `name` on `task` (made with `env_kwargs`): a scripted expert of the task's
    family (strong | imperfect, or a preset's own names), a rule `module:function` (an importable
    function of the observation as the networks see it, flattened, → action), or the greedy
    policy of a saved `.keras` Q-network or BC model (checked against the task's spaces)."""
    check_demonstrator(name, get_task(task))
    if name.startswith(NOT_REMADE):
        raise ConfigError(
            f"expert {name!r} existed only in the Python process that used it: give the "
            "demonstrations themselves (--demos FILE.npz)"
        )
    n_actions = task_spaces(task, env_kwargs).n_actions  # first: an env we cannot learn on is the error
    family = get_task(task).family
    if name in EXPERT_NAMES or name in get_task(task).experts:
        if family is None:
            raise ConfigError(
                f"{task} has no scripted {name} expert: give demonstrations with --demos FILE.npz or "
                "minari:DATASET_ID, or a demonstrator module:function or model.keras with --expert (from "
                "Python: DQfD(env, demos), demos a file, a dataset, a demonstrator's name or a function)"
                + _presets_of(get_task(task).env_id)
            )
        return make_expert(family, name, epsilon, seed)
    if name.endswith(".keras"):
        from dqfd_bc_keras.evaluation import load_policy  # loads Keras: only when a model demonstrates

        rule: Rule = load_policy(name, None, task, env_kwargs=env_kwargs or {})[0]
    else:
        rule = cast(Rule, load(name, f"demonstrator {name}", callable, "function"))
    return Demonstrator(name, rule, n_actions, _check_epsilon(epsilon), np.random.default_rng(seed))


def _presets_of(env_id: str) -> str:
    """A hint naming the presets whose scripted experts play the env `env_id` ("" if none do)."""
    bare, scripted = bare_id(env_id), families()
    presets = [spec.name for spec in TASKS.values() if spec.env_id == bare and spec.family in scripted]
    if not presets:
        return ""
    which = f"the preset {presets[0]} plays" if len(presets) == 1 else f"the presets {', '.join(presets)} play"
    return f"; {which} {bare} with scripted experts (--task {presets[0]}; from Python: DQfD('{presets[0]}'))"


def try_demonstrator(config: Config) -> None:
    """Ask `config.expert` for its action on the first observation it will be recorded from
    (`training.demonstrations`), without its epsilon: a rule that cannot be imported, raises or
    answers no action is one line in about a second, before TensorFlow loads and before a run
    directory exists. A `.keras` model is checked when it is loaded (that needs TensorFlow)."""
    if config.expert.endswith(".keras"):
        return
    policy = make_demonstrator(config.expert, config.task, env_kwargs=config.env_kwargs)
    env = make_task(config.task, timeout=config.timeout, max_steps=config.max_steps, env_kwargs=config.env_kwargs)
    try:
        obs, _ = env.reset(seed=demo_seed(config.seed))
        policy(obs)
    finally:
        env.close()


def expert_returns(family: str, name: str, episodes: int = 100, seed: int = 0, epsilon: float = 0.0) -> np.ndarray:
    """Undiscounted returns of the expert on the plain env (`envs.make_plain_env`: frames as
    uint8, the preset's limit where the env has none); episode i is reset with seed + i."""
    expert = make_expert(family, name, epsilon, seed)
    with make_plain_env(family_preset(family).name) as env:
        returns = play(env, expert, range(seed, seed + episodes)).returns
    return np.asarray(returns, dtype=np.float64)


def callable_name(rule: Rule) -> str:
    """How a run names a Python callable given as its demonstrator (tasks.NOT_REMADE): no later
    process can call it again, so the name says what it was, never a reference to import."""
    return f"python callable {getattr(rule, '__qualname__', type(rule).__name__)}"


def record(
    task: str,
    expert: str | Demonstrator | Rule,
    episodes: int,
    seed: int = 0,
    epsilon: float = 0.0,
    timeout: str = "bootstrap",
    max_steps: int | None = None,
    env_kwargs: dict[str, Any] | None = None,
) -> DemoDataset:
    """Run the demonstrator `expert` (`make_demonstrator`: strong | imperfect |
    module:function | model.keras; a Python callable obs → action; or one already made) for
    `episodes` episodes of `task` made with `env_kwargs`, `max_steps` steps at most; episode i
    resets with seed + i."""
    if episodes < 1:
        raise ConfigError(f"episodes must be ≥ 1, got {episodes}")
    if isinstance(expert, Demonstrator):
        policy = expert
    elif callable(expert):
        n_actions = task_spaces(task, env_kwargs).n_actions
        policy = Demonstrator(
            callable_name(expert), expert, n_actions, _check_epsilon(epsilon), np.random.default_rng(seed)
        )
    else:
        policy = make_demonstrator(expert, task, epsilon=epsilon, seed=seed, env_kwargs=env_kwargs)
    source = policy.name if callable(expert) else expert
    with make_task(task, timeout=timeout, max_steps=max_steps, env_kwargs=env_kwargs) as env:
        dataset = rollout(
            env,
            policy,
            range(seed, seed + episodes),
            task=task,
            source=source,
            epsilon=epsilon,
            seed=seed,
            env_kwargs=env_kwargs,
        )
    return dataset


class EpisodeRecorder:
    """Transitions of complete episodes as they are played, turned into a dataset on demand.

    One recorder serves scripted demonstrations, greedy roll-outs, the agent's own training
    episodes (dynamic demonstrations) and a person's play (`keys`, `fps`: the key map and frame
    rate they played with), so every D_demo episode has the same layout and meta, each with the
    seed it was reset with, to be played again.
    """

    def __init__(
        self,
        env,
        *,
        task: str,
        source: str,
        epsilon: float = 0.0,
        seed: int = 0,
        env_kwargs: dict[str, Any] | None = None,
        keys: dict[str, int] | None = None,
        fps: float | None = None,
    ) -> None:
        self.task, self.source, self.epsilon, self.seed = task, source, float(epsilon), int(seed)
        self.env_kwargs = dict(env_kwargs or {})
        self.keys, self.fps = dict(keys or {}), None if fps is None else float(fps)
        shape = env.observation_space.shape
        self.frames = len(shape) > 1  # envs.make_task flattens all but frames
        self.obs_dim, self.n_actions = int(np.prod(shape)), int(env.action_space.n)
        self.obs_shape = [int(n) for n in shape] if self.frames else None
        self.timeout = env.get_wrapper_attr("mode")
        self.max_steps = int(env.get_wrapper_attr("max_steps"))  # `TimeLimitMode`'s limit (`TimeFeature`'s is the same)
        self.clear()

    def clear(self) -> None:
        """Forget every recorded episode (and the one being played)."""
        self.columns: dict[str, list] = {name: [] for name in ARRAYS}
        self.returns: list[float] = []
        self.plain_returns: list[float] = []
        self.seeds: list[int | None] = []
        self.open = 0

    def reset(self, obs: np.ndarray, seed: int | None) -> None:
        """A new episode starts in `obs`, the env reset with `seed` (None: without one); an
        unfinished one before it is dropped."""
        for column in self.columns.values():
            del column[len(column) - self.open :]
        self.obs, self.open, self.ret, self.plain = obs, 0, 0.0, 0.0
        self.episode_seed = None if seed is None else int(seed)

    def step(
        self, action: int, next_obs: np.ndarray, reward: SupportsFloat, terminated: bool, truncated: bool, info: dict
    ) -> None:
        values = (self.obs, action, reward, next_obs, terminated, truncated, len(self.returns))
        for name, value in zip(ARRAYS, values, strict=True):
            self.columns[name].append(value)
        self.obs, self.open = next_obs, self.open + 1
        self.ret += float(reward)
        self.plain += info["plain_reward"]
        if terminated or truncated:
            self.returns.append(self.ret)
            self.plain_returns.append(self.plain)
            self.seeds.append(self.episode_seed)
            self.open = 0

    def dataset(self) -> DemoDataset:
        """The complete episodes recorded so far (an episode still being played is left out)."""
        if not self.returns:
            raise ConfigError("no complete episode has been recorded")
        end = len(self.columns["actions"]) - self.open
        meta = DemoMeta(
            task=self.task,
            env_id=get_task(self.task).env_id,
            timeout=self.timeout,
            obs_dim=self.obs_dim,
            n_actions=self.n_actions,
            expert=self.source,
            epsilon=self.epsilon,
            seed=self.seed,
            episode_returns=list(self.returns),
            plain_returns=list(self.plain_returns),
            env_kwargs=dict(self.env_kwargs),
            observation=task_spaces(self.task, self.env_kwargs).layout.text(),
            obs_shape=self.obs_shape,
            max_steps=self.max_steps,
            episode_seeds=list(self.seeds),
            keys=dict(self.keys),
            fps=self.fps,
        )
        dtypes = {name: dtype for name, (dtype, _) in ARRAYS.items()} | {
            "obs": meta.obs_dtype,
            "next_obs": meta.obs_dtype,
        }
        arrays: dict[str, np.ndarray] = {
            name: np.asarray(self.columns[name][:end], dtype=dtypes[name]) for name in ARRAYS
        }
        return DemoDataset(**arrays, meta=meta)


def rollout(
    env,
    policy: Policy,
    seeds: Sequence[int],
    *,
    task: str,
    source: str,
    epsilon: float = 0.0,
    seed: int = 0,
    env_kwargs: dict[str, Any] | None = None,
) -> DemoDataset:
    """One complete episode of `policy` on the task env `env` per seed, as a dataset.

    `source` names the demonstrator in the metadata (a scripted expert, or the agent's
    greedy policy for dynamic demonstrations); `env_kwargs` are those `env` was made with.
    """
    recorder = EpisodeRecorder(env, task=task, source=source, epsilon=epsilon, seed=seed, env_kwargs=env_kwargs)
    play(env, policy, seeds, recorder)
    return recorder.dataset()
