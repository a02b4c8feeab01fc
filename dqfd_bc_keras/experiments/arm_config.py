"""An arm: one Config of a suite, over seeds, named by what it changes from its task's preset, so
that arms equal in config get one name and suites sharing an `--out` share their runs.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import re
from dataclasses import dataclass

from dqfd_bc_keras.core.config import QUICK, Config, preset_defaults, shared_defaults
from dqfd_bc_keras.envs.make import get_task, task_slug


@dataclass(frozen=True)
class Arm:
    """One configuration of a suite; its seeds 0 … seeds − 1 are the runs."""

    task: str
    timeout: str
    expert_loss: str
    overrides: tuple[tuple[str, object], ...] = ()
    """Further Config fields, only those that differ from the task preset."""
    label: str = ""
    """Suffix of the arm's name that says what the overrides change."""
    seeds: int = 10

    @property
    def name(self) -> str:
        return "-".join(filter(None, (task_slug(self.task), self.timeout, self.expert_loss, self.label)))

    def __hash__(self) -> int:  # an override may be a dict (env_kwargs); equal arms have equal names
        return hash(self.name)

    def config(self, seed: int) -> Config:
        return Config.for_task(
            self.task, timeout=self.timeout, expert_loss=self.expert_loss, seed=seed, **dict(self.overrides)
        )


_SHORT = {
    "sigma0_sq": "sigma",
    "expert": "",
    "eval_every": "eval",
    "dynamic_demos": "dyn",
    "early_stop_window": "stopwindow",
    "total_steps": "steps",
    "bayes_prior": "prior",
    "mc_dropout": "mcdropout",
    "uncertainty": "",
    "expert_epsilon": "eps",
    "demo_episodes": "demos",
    "env_kwargs": "",
}


def _label(key: str, value: object) -> str:
    """One override in an arm's name: `sigma0.1`, `demos5`, `use_lidar=false` (a dict of env kwargs;
    a long one becomes a hash of it)."""
    if isinstance(value, dict):
        text = json.dumps(value, sort_keys=True, separators=(",", "="))
        text = re.sub(r"[^\w.,=+-]", "", text.replace(":", "-"))
        return text if len(text) <= 48 else "kw" + hashlib.sha1(text.encode()).hexdigest()[:10]
    return f"{_SHORT.get(key, key)}{value:g}" if isinstance(value, float) else f"{_SHORT.get(key, key)}{value}"


def arm(task: str, timeout: str, expert_loss: str, seeds: int = 10, **overrides: object) -> Arm:
    """An arm that keeps only the overrides differing from the task preset, labelled by them:
    arms equal in config get one name, so suites sharing an `--out` share their runs."""
    preset = preset_defaults(task, expert_loss)
    changed = {k: v for k, v in overrides.items() if preset[k] != v}
    label = "-".join(_label(k, v) for k, v in changed.items())
    return Arm(task, timeout, expert_loss, tuple(changed.items()), task_slug(label), seeds)


def on_shared_defaults(a: Arm) -> Arm:
    """Arm `a` on its preset's shared defaults where its method has its own there since
    (`TaskSpec.method_defaults`), under the same name: a study run before keeps what its committed runs
    are, and reruns them so (the efficiency suite, PREREGISTRATION §15's and §16's runs of the defaults)."""
    shared = shared_defaults(a.task)
    own = get_task(a.task).method_defaults.get(a.expert_loss, {})
    fields = dict(a.overrides)
    return dataclasses.replace(a, overrides=(*a.overrides, *((k, shared[k]) for k in own if k not in fields)))


def quick(a: Arm) -> Arm:
    """Arm `a` on the QUICK budget (its own fields kept), one seed, labelled `quick`."""
    fields = dict(a.overrides)
    return dataclasses.replace(
        a,
        overrides=(*a.overrides, *((k, v) for k, v in QUICK.items() if k not in fields)),
        label="-".join(filter(None, (a.label, "quick"))),
        seeds=1,
    )
