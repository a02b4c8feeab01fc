"""Arms: the runs of one configuration, how they are named, and how a bayes arm finds its ce pair.

Runs are read from their files (never from their directory names) and grouped into arms by
config.json: every field except `seed`. Which fields may tell two arms apart in a name, and which
a bayes arm may differ from its ce arm in, follow from the methods' declarations (methods.py).
"""

from __future__ import annotations

import dataclasses
import functools
import json
from dataclasses import dataclass

import numpy as np

from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.core.methods import METHODS, method_fields
from dqfd_bc_keras.experiments.metrics import PER_RUN
from dqfd_bc_keras.experiments.run_files import FinishedRun

BAYES_ONLY = tuple(sorted(set(METHODS["bayes"].reads) - set(METHODS["ce"].reads)))
"""Config fields only the bayes loss reads (methods.py): a bayes arm pairs with the ce arm equal in
every other field."""


@dataclass
class ArmRuns:
    """The runs of one configuration (all fields but the seed)."""

    config: Config
    """Its runs' configuration, with the seed of its first run (`fields` leaves the seed out)."""
    runs: list[FinishedRun]
    name: str = ""

    @functools.cached_property
    def fields(self) -> dict[str, object]:
        """Every config field but the seed, by name: what tells two arms apart."""
        return {k: v for k, v in self.config.to_dict().items() if k != "seed"}

    @property
    def setting(self) -> str:
        return f"{self.config.task}/{self.config.timeout}"

    @property
    def label(self) -> str:
        return f"{self.setting} · {self.name}"

    def values(self, metric: str) -> np.ndarray:
        return np.array([PER_RUN[metric](run) for run in self.runs], dtype=float)


def find_arm(arms: list[ArmRuns], config: Config) -> ArmRuns | None:
    """The arm whose runs have `config` (its seed aside), if any ran."""
    fields = {k: v for k, v in config.to_dict().items() if k != "seed"}
    return next((a for a in arms if a.fields == fields), None)


def common_seeds(first: ArmRuns, second: ArmRuns) -> tuple[ArmRuns, ArmRuns]:
    """The two arms restricted to the seeds both ran: a comparison the pre-registration plans
    within one suite stays the same when one of its arms gets more seeds in another suite."""
    seeds = {r.config.seed for r in first.runs} & {r.config.seed for r in second.runs}
    kept = [dataclasses.replace(arm, runs=[r for r in arm.runs if r.config.seed in seeds]) for arm in (first, second)]
    return kept[0], kept[1]


def group_arms(runs: list[FinishedRun]) -> list[ArmRuns]:
    """Runs with equal configs but for `seed` form an arm; each arm is named by its expert loss
    and every field in which the arms of its setting (task, timeout) differ."""
    arms: dict[str, ArmRuns] = {}
    for run in runs:
        fields = {k: v for k, v in run.config.to_dict().items() if k != "seed"}
        arm = arms.setdefault(json.dumps(fields, sort_keys=True), ArmRuns(run.config, []))
        if all(r.config.seed != run.config.seed for r in arm.runs):  # a run repeated elsewhere counts once
            arm.runs.append(run)
    for arm in arms.values():
        arm.runs.sort(key=lambda r: r.config.seed)
        peers = [a.fields for a in arms.values() if a.setting == arm.setting]
        varying = [
            k
            for k in arm.fields
            if k not in ("task", "timeout", "expert_loss")
            and len({json.dumps(p[k]) for p in peers}) > 1
            and not (k in method_fields() and k not in arm.config.method.reads)
        ]
        arm.name = " ".join([arm.config.expert_loss, *(f"{k}={arm.fields[k]}" for k in varying)])
    return sorted(arms.values(), key=lambda a: a.label)


def preset_distance(arm: ArmRuns, overrides: tuple[tuple[str, object], ...] = ()) -> int:
    """How many config fields besides the loss (and the timeout) differ from the task preset with
    `overrides`: 0 for the paper's and the baselines' arms, more for a sensitivity or benchmark variant."""
    preset = Config.for_task(arm.config.task, **dict(overrides)).to_dict()
    return sum(v != preset[k] for k, v in arm.fields.items() if k not in ("expert_loss", "timeout"))


def bayes_ce_pairs(
    arms: list[ArmRuns], task: str, timeout: str | None, overrides: tuple[tuple[str, object], ...] = ()
) -> list[tuple[ArmRuns, ArmRuns | None]]:
    """Each bayes arm of the setting (`task`, `timeout` or any if None, and the config fields of
    `overrides`) with its ce arm (equal in every field but the Bayes-only ones and the loss), the
    reference pair first: the one closest to the task preset with `overrides`."""

    def strip(arm: ArmRuns) -> dict:
        return {k: v for k, v in arm.fields.items() if k not in ("expert_loss", *BAYES_ONLY)}

    def selected(arm: ArmRuns) -> bool:
        return (
            arm.config.task == task
            and timeout in (None, arm.config.timeout)
            and all(arm.fields[k] == v for k, v in overrides)
        )

    pairs = [
        (b, next((c for c in arms if c.config.expert_loss == "ce" and strip(c) == strip(b)), None))
        for b in arms
        if b.config.expert_loss == "bayes" and selected(b)
    ]
    return sorted(pairs, key=lambda p: (p[1] is None, preset_distance(p[0], overrides), -len(p[0].runs), p[0].label))


@dataclass(frozen=True)
class Setting:
    """Where a claim is tested: the arms of `task` under `timeout` (None: any) whose config has the
    fields of `overrides`, so one task can carry several readings of a claim (C2)."""

    task: str
    timeout: str | None
    overrides: tuple[tuple[str, object], ...] = ()
    reading: str = ""
    """Which reading of the claim this setting is, when it has several."""

    @property
    def name(self) -> str:
        return " ".join([f"{self.task}/{self.timeout or '*'}", *(f"{k}={v}" for k, v in self.overrides)])

    def pairs(self, arms: list[ArmRuns]) -> list[tuple[ArmRuns, ArmRuns | None]]:
        return bayes_ce_pairs(arms, self.task, self.timeout, self.overrides)
