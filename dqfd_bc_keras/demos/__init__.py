"""Demonstration datasets: record them with any demonstrator (a scripted expert, a rule
`module:function`, a saved `.keras` model) or play them yourself in a window, save them as plain
`.npz`, load them back with every check a learner relies on, and replay them against the env;
Minari datasets convert both ways (`demos/minari.py`).

This module is the public face of the package's modules: `dataset` (the dataset and its
invariants), `recording` (demonstrators played on a task env), `human` (a person playing:
`play`, and `controls`, the keys and pace it plays with; with `keys` and `window`), `replaying`
(`show`), `npz` (the `.npz` format) and `minari`;
`load_source` reads either kind of source. The command line is `commands/demos.py`:

    python -m dqfd_bc_keras.demos record --task cartpole --expert imperfect --episodes 5 --out demos.npz
    python -m dqfd_bc_keras.demos play --task cartpole --episodes 5 --out mine.npz
    python -m dqfd_bc_keras.demos show mine.npz
    python -m dqfd_bc_keras.demos inspect demos.npz
"""

from __future__ import annotations

from typing import Any

from dqfd_bc_keras.demos.dataset import ARRAYS, FORMAT_VERSION, DemoDataset, DemoMeta, concatenate, validate
from dqfd_bc_keras.demos.human import controls, play
from dqfd_bc_keras.demos.minari import from_minari
from dqfd_bc_keras.demos.minari_export import check_exportable
from dqfd_bc_keras.demos.npz import load, save
from dqfd_bc_keras.demos.recording import EpisodeRecorder, record, rollout
from dqfd_bc_keras.demos.replaying import show
from dqfd_bc_keras.errors import ConfigError

__all__ = [
    "ARRAYS",
    "FORMAT_VERSION",
    "GIVEN",
    "DemoDataset",
    "DemoMeta",
    "EpisodeRecorder",
    "check_exportable",
    "concatenate",
    "controls",
    "given_episodes",
    "given_expert",
    "given_source",
    "load",
    "load_source",
    "play",
    "record",
    "rollout",
    "save",
    "show",
    "validate",
]


def load_source(
    source: str, task: str, timeout: str, env_kwargs: dict[str, Any] | None = None, max_transitions: int | None = None
) -> DemoDataset:
    """Demonstrations for `task` (made with `env_kwargs`) from `source`: a `.npz` file of ours or
    `minari:DATASET_ID` (a dataset in the local Minari cache, converted by `demos.minari.from_minari`),
    of at most `max_transitions` transitions."""
    if source.startswith("minari:"):
        return from_minari(source.removeprefix("minari:"), task, timeout, env_kwargs, max_transitions)
    return load(source, task=task, timeout=timeout, env_kwargs=env_kwargs, max_transitions=max_transitions)


def given_source(dataset: DemoDataset) -> str:
    """Where a dataset given to a run came from, as its metadata says: a Minari dataset or a file."""
    return "minari" if dataset.meta.expert.startswith("minari:") else "file"


GIVEN = "demonstrations from "
"""How `given_expert` names demonstrations given, not recorded (one of tasks.NOT_REMADE)."""


def given_expert(source: str, dataset: DemoDataset) -> str:
    """What a run's config names as its `expert` when demonstrations were given, not recorded:
    where they came from and who demonstrated them, as their metadata says. Not a demonstrator
    any process could call (tasks.registry.NOT_REMADE): the run keeps its D_demo in its checkpoints."""
    by = dataset.meta.expert
    return f"{GIVEN}{source}" + ("" if by == source else f" ({by})")


def given_episodes(source: str, dataset: DemoDataset, asked: int | None = None) -> int:
    """What a run's config records as its `demo_episodes` when demonstrations were given: the
    episodes it trains on, the dataset's. `asked` (a `demo_episodes` given with them) must agree:
    it is how many episodes an expert records, and none is recorded."""
    if asked is not None and asked != dataset.n_episodes:
        raise ConfigError(
            f"{source} holds {dataset.n_episodes} episodes, not demo_episodes={asked} (the episodes an expert "
            "records): drop it, or record that many"
        )
    return dataset.n_episodes
