"""Demonstrations to and from Minari datasets (Farama's offline-RL format), never over the network.

Only the local Minari cache is used: its root is `MINARI_DATASETS_PATH`, else
`~/.minari/datasets`, and a dataset `ns/name-v0` lives in `<root>/ns/name-v0/data`. To read a
published dataset, download it first yourself (`minari download ns/name-v0`).

A Minari episode holds T actions and T + 1 observations with Gymnasium's flags, which is our
`bootstrap` timeout mode; it becomes T transitions of our format (`demos.dataset.ARRAYS`):

    obs = observations[:-1]   next_obs = observations[1:]   actions int64   rewards float32
    terminated / truncated bool (a step with both flags counts as terminated, as `TimeLimitMode` does)

Minari keeps the plain env's rewards, so tasks with shaped rewards (cartpole's fall penalty,
mountaincar-goals' goal reward) are refused both ways: use the plain env id (`CartPole-v1`).
Minari is optional (`pip install -r requirements-extras.txt`); it is imported only here, lazily.
Writing a dataset is `demos/minari_export.py`'s.

    python -m dqfd_bc_keras.demos export demos.npz --minari mountaincar/imperfect-v0
    python train.py --env CartPole-v1 --demos minari:cartpole/expert-v0
"""

from __future__ import annotations

import json
from pathlib import Path
from types import ModuleType
from typing import Any

import gymnasium as gym
import numpy as np

from dqfd_bc_keras.choices import TIMEOUT_MODES
from dqfd_bc_keras.demos.dataset import ARRAYS, DemoDataset, DemoMeta, validate
from dqfd_bc_keras.envs.kwargs import effective_kwargs
from dqfd_bc_keras.envs.make import TaskSpaces, TaskSpec, get_task, task_spaces
from dqfd_bc_keras.envs.observations import ObservationLayout, describe
from dqfd_bc_keras.errors import ConfigError, DemoFileError, one_line
from dqfd_bc_keras.plugins import bare_id

_ABSENT = object()


def import_minari() -> ModuleType:
    """The `minari` module, or a one-line `ConfigError` saying how to install it."""
    try:
        import minari
    except ImportError as error:
        raise ConfigError(
            f"Minari datasets need the optional dependency minari ({error}): pip install -r requirements-extras.txt"
        ) from None
    return minari


def dataset_dir(dataset_id: str) -> Path:
    """Where the local cache keeps `dataset_id` (checked to be a well-formed Minari id)."""
    from minari.dataset.minari_dataset import parse_dataset_id
    from minari.storage.datasets_root_dir import get_dataset_path

    try:
        parse_dataset_id(dataset_id)
    except (ValueError, TypeError):  # TypeError: an id without its -vN version
        raise ConfigError(
            f"malformed Minari dataset id {dataset_id!r}: expected (namespace/)name-vN, e.g. mountaincar/imperfect-v0"
        ) from None
    return get_dataset_path(dataset_id)


def refuse_shaped(spec: TaskSpec, what: str) -> None:
    """Minari datasets carry the plain env's rewards: a shaped task would mix two reward scales."""
    shaping = (
        "a fall penalty" if spec.fall_penalty is not None else "a goal reward" if spec.goal_reward is not None else None
    )
    if shaping is not None:
        raise ConfigError(
            f"{what}: task {spec.name!r} has shaped rewards ({shaping}) but a Minari dataset "
            f"holds the plain env's rewards; use the plain env id instead, e.g. --env {spec.env_id}"
        )


def _check_spaces(
    where: Path, dataset_spaces: tuple[gym.Space, gym.Space], task: str, task_obs: gym.Space, n_actions: int
) -> None:
    """The dataset's spaces must be the task env's own: the same kinds and shapes (a Box's
    bounds may differ) and Discrete(n) from 0."""
    obs_space, action_space = dataset_spaces
    actions_ok = (
        isinstance(action_space, gym.spaces.Discrete)
        and int(action_space.start) == 0
        and int(action_space.n) == n_actions
    )
    if describe(obs_space) != describe(task_obs) or not actions_ok:
        raise DemoFileError(
            where,
            f"mismatched spaces: dataset has {describe(obs_space)}/{action_space}, "
            f"task {task} has {describe(task_obs)}/Discrete({n_actions})",
        )


def _open_checked(
    where: Path, dataset_id: str, task: str, timeout: str, env_kwargs: dict[str, Any], max_transitions: int | None
) -> tuple[Any, TaskSpaces]:
    """The Minari dataset, opened and checked against the task before any episode is read."""
    minari = import_minari()
    if timeout not in TIMEOUT_MODES:
        raise ConfigError(f"unknown timeout mode {timeout!r}; expected one of {TIMEOUT_MODES}")
    if timeout == "time-aware":
        raise ConfigError(
            f"{where}: timeout='time-aware' needs the time left in every state, which a Minari "
            "dataset does not record; use --timeout bootstrap (or naive)"
        )
    spec = get_task(task)
    refuse_shaped(spec, str(where))
    directory = dataset_dir(dataset_id)
    if not (directory / "data").is_dir():
        raise DemoFileError(
            where,
            f"not in the local Minari cache (looked in {directory}); datasets are never "
            f"downloaded here: run `minari download {dataset_id}` or set MINARI_DATASETS_PATH",
        )
    try:
        source = minari.load_dataset(dataset_id, download=False)
    except Exception as error:  # corrupt metadata, an unsupported version, a missing storage extra
        raise DemoFileError(where, f"cannot be read ({one_line(error)})") from None

    if source.env_spec is None:
        raise DemoFileError(
            where, f"names no env (its env_spec is empty), so it cannot be checked against {spec.env_id}"
        )
    if bare_id(source.env_spec.id) != bare_id(spec.env_id):
        raise DemoFileError(where, f"was recorded on {source.env_spec.id}, but task {task!r} is {spec.env_id}")
    spaces = task_spaces(task, env_kwargs)
    theirs = effective_kwargs(spec.env_id, dict(source.env_spec.kwargs or {}))
    ours = effective_kwargs(spec.env_id, env_kwargs)
    if theirs != ours:  # the keys that differ, with the constructor's and registration's defaults filled in
        keys = sorted(k for k in {*theirs, *ours} if theirs.get(k, _ABSENT) != ours.get(k, _ABSENT))
        recorded, made = ({k: kwargs.get(k, "(not given)") for k in keys} for kwargs in (theirs, ours))
        raise DemoFileError(
            where, f"was recorded with env kwargs {json.dumps(recorded)}, but the task is made with {json.dumps(made)}"
        )
    if spaces.layout.image:
        raise DemoFileError(
            where,
            f"task {task!r} observes frames ({spaces.layout.text()}); reading Minari datasets of "
            "frames is not supported yet: convert it to an .npz (docs/DEMONSTRATIONS.md)",
        )
    if max_transitions is not None and source.total_steps > max_transitions:
        raise DemoFileError(
            where,
            f"holds {source.total_steps} transitions, more than demo_capacity={max_transitions} "
            "(raise it with --set demo_capacity=N)",
        )
    _check_spaces(where, (source.observation_space, source.action_space), task, spaces.layout.space, spaces.n_actions)
    return source, spaces


def _transitions(
    where: Path, index: int, episode: Any, layout: ObservationLayout, timeout: str
) -> tuple[np.ndarray, ...]:
    """Episode `index` as the columns of `ARRAYS`, refused in one line if it is empty, incomplete,
    ends early or does not fit the task's observation space."""
    steps = len(episode.rewards)
    try:
        observations = layout.flatten(episode.observations, batch=steps + 1)
    except (KeyError, IndexError, TypeError, ValueError) as error:
        raise DemoFileError(
            where,
            f"episode {index} has {steps} steps and observations that do not fit "
            f"{describe(layout.space)} × {steps + 1} ({one_line(error)})",
        ) from None
    terminated = np.asarray(episode.terminations, dtype=bool)
    truncated = np.asarray(episode.truncations, dtype=bool) & ~terminated
    if steps == 0:
        raise DemoFileError(where, f"episode {index} has no steps")
    if not (terminated[-1] or truncated[-1]):
        raise DemoFileError(where, f"episode {index} is incomplete: its last step is neither terminated nor truncated")
    if (terminated[:-1] | truncated[:-1]).any():
        raise DemoFileError(where, f"episode {index} ends (terminated or truncated) before its last step")
    if timeout == "naive":
        terminated, truncated = terminated | truncated, np.zeros_like(truncated)
    return (
        observations[:-1],
        np.asarray(episode.actions, dtype=np.int64).reshape(-1),
        np.asarray(episode.rewards, dtype=np.float32),
        observations[1:],
        terminated,
        truncated,
        np.full(steps, index, np.int64),
    )


def _seeds(source: Any) -> list[int | None]:
    """Each episode's reset seed, which Minari keeps in the episode's metadata (not its
    `EpisodeData`); None for an episode recorded without one."""
    metadata = source.storage.get_episode_metadata(source.episode_indices)
    return [None if m.get("seed") is None else int(m["seed"]) for m in metadata]


def from_minari(
    dataset_id: str,
    task: str,
    timeout: str = "bootstrap",
    env_kwargs: dict[str, Any] | None = None,
    max_transitions: int | None = None,
) -> DemoDataset:
    """Read the Minari dataset `dataset_id` from the local cache as demonstrations for `task`
    made with `env_kwargs`.

    Never downloads. Refuses, in one line naming the dataset: a missing dataset (and where it
    looked), another env, other env kwargs (compared with the registration's defaults filled
    in on both sides), other spaces, a shaped-reward task, `timeout="time-aware"` (there is no
    time feature to add) and incomplete episodes. Observations are flattened as the task's are
    (`observations`). `naive` records every truncation as a termination, as our naive mode
    does; `bootstrap` keeps Gymnasium's flags. Each episode's reset seed is kept where Minari
    has one; the step limit is not known (`max_steps` None).
    """
    env_kwargs = dict(env_kwargs or {})
    where = Path(f"minari:{dataset_id}")
    source, spaces = _open_checked(where, dataset_id, task, timeout, env_kwargs, max_transitions)
    layout = spaces.layout
    columns: dict[str, list[np.ndarray]] = {name: [] for name in ARRAYS}
    returns: list[float] = []
    try:
        episodes = list(source.iterate_episodes())
        seeds = _seeds(source)
    except Exception as error:
        raise DemoFileError(where, f"cannot be read ({one_line(error)})") from None
    for index, episode in enumerate(episodes):
        for name, value in zip(ARRAYS, _transitions(where, index, episode, layout, timeout), strict=True):
            columns[name].append(value)
        returns.append(float(np.sum(columns["rewards"][-1], dtype=np.float64)))
    if not returns:
        raise DemoFileError(where, "the dataset is empty")

    spec = get_task(task)
    meta = DemoMeta(
        task=task,
        env_id=spec.env_id,
        timeout=timeout,
        obs_dim=layout.dim,
        n_actions=spaces.n_actions,
        expert=f"minari:{dataset_id}",
        epsilon=0.0,
        seed=0,
        episode_returns=returns,
        plain_returns=list(returns),
        env_kwargs=env_kwargs,
        observation=layout.text(),
        max_steps=None,  # Minari records no limit of ours (an env spec's own may not be what the episodes had)
        episode_seeds=seeds,
    )
    dataset = DemoDataset(
        **{name: np.concatenate(columns[name]).astype(dtype, copy=False) for name, (dtype, _) in ARRAYS.items()},
        meta=meta,
    )
    validate(where, dataset)
    return dataset
