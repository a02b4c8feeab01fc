"""dqfd_bc_keras: deep Q-learning from demonstrations with a behavioural-cloning model and a
Bayesian supervised expert loss (Kim, Symmetry 2022), in Keras 3 / TensorFlow.

Importing the package is light, so that a command's `--help` answers at once: it does not import
TensorFlow. It sets TensorFlow's environment (runtime.py), arranges for TensorFlow's thread pools
to be set as soon as any module imports it, and registers the task presets as Gymnasium ids
(`dqfd_bc_keras/<task>-v0`). Saved models load with `dqfd_bc_keras.load_model(path)`, which
registers the package's custom Keras objects (`BCModel`, …) first.
"""

from __future__ import annotations

import importlib.abc
import importlib.machinery
import importlib.util
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from dqfd_bc_keras import runtime  # first: its environment variables are read when TensorFlow loads
from dqfd_bc_keras.envs.make import TASKS, make_plain_env, make_task, register_tasks

if TYPE_CHECKING:
    import keras

    from dqfd_bc_keras.core.bc import BCModel
    from dqfd_bc_keras.model import DQfD

__all__ = ["TASKS", "BCModel", "DQfD", "load_model", "make_plain_env", "make_task"]
__version__ = "0.1.0"


class _ConfigureTensorFlow(importlib.abc.MetaPathFinder):
    """Finds `tensorflow` like the other finders, then runs `runtime.configure_tensorflow` right
    after TensorFlow's own import: whichever module imports it first, its thread pools are set
    before its first op."""

    def find_spec(self, name: str, path: object = None, target: object = None) -> importlib.machinery.ModuleSpec | None:
        if name != "tensorflow":
            return None
        sys.meta_path.remove(self)  # once: the search below, and every later import, go past it
        spec = importlib.util.find_spec(name)
        if spec is not None and spec.loader is not None:
            exec_module = spec.loader.exec_module

            def exec_then_configure(module: object) -> None:
                exec_module(module)
                runtime.configure_tensorflow()

            spec.loader.exec_module = exec_then_configure  # type: ignore[method-assign]
        return spec


MOVED = {
    "config": "core.config",
    "losses": "core.losses",
    "expert_terms": "core.expert_terms",
    "methods": "core.methods",
    "networks": "core.networks",
    "optimizers": "core.optimizers",
    "replay": "core.replay",
    "bc": "core.bc",
    "uncertainty": "core.uncertainty",
    "agent": "core.agent",
    "reference": "core.reference",
    "wrappers": "envs.wrappers",
    "observations": "envs.observations",
    "atari": "envs.atari",
    "network_input": "envs.network_input",
    "episodes": "envs.episodes",
    "demo_data": "demos.dataset",
    "demo_files": "demos.npz",
    "minari_io": "demos.minari",
    "recording": "demos.recording",
    "experts": "demos.experts",
    "interaction": "training.interaction",
    "run_state": "training.state",
    "records": "training.records",
    "run_files": "runs.writers",
    "provenance": "runs.provenance",
    "cli": "commands.cli",
}
"""Modules that had a flat path before the package took a folder per layer, and where they live
now: a user's `from dqfd_bc_keras.methods import Method` (docs/EXTENDING.md's plug-ins), an old
pickle or `python -m dqfd_bc_keras.experts` finds the same module object under either name."""


class _MovedModules(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Answers an old path of `MOVED` with the module at its new path (one object, two names)."""

    def find_spec(self, name: str, path: object = None, target: object = None) -> importlib.machinery.ModuleSpec | None:
        old = name.removeprefix(f"{__name__}.")
        if old == name or old not in MOVED:
            return None
        return importlib.machinery.ModuleSpec(name, self)

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> object:
        return importlib.import_module(self._new_name(spec.name))

    def exec_module(self, module: object) -> None:
        """Already executed under its new name."""

    def get_code(self, name: str) -> object:
        """For `python -m` with an old path: runs the new module's code as `__main__`."""
        new = self._new_name(name)
        return importlib.util.find_spec(new).loader.get_code(new)  # type: ignore[union-attr]

    @staticmethod
    def _new_name(name: str) -> str:
        return f"{__name__}.{MOVED[name.removeprefix(f'{__name__}.')]}"


if not any(isinstance(finder, _MovedModules) for finder in sys.meta_path):
    sys.meta_path.append(_MovedModules())

if "tensorflow" in sys.modules:
    runtime.configure_tensorflow()
elif not any(isinstance(finder, _ConfigureTensorFlow) for finder in sys.meta_path):
    sys.meta_path.insert(0, _ConfigureTensorFlow())

register_tasks()


def load_model(path: str | Path) -> keras.Model:
    """A saved `.keras` model (a run's q_network.keras or bc_model.keras, a shipped model) in
    Keras' safe mode, with the package's custom objects registered; a file that is missing, not a
    .keras archive or unreadable is a one-line `ModelFileError`."""
    from dqfd_bc_keras.evaluation import load_model as load  # registers BCModel, EnsembleDense, FusedAdam, …

    return load(path)


def __getattr__(name: str) -> Any:
    """`dqfd_bc_keras.BCModel` and `dqfd_bc_keras.DQfD`, imported (with TensorFlow) only when asked for."""
    if name == "BCModel":
        from dqfd_bc_keras.core.bc import BCModel

        return BCModel
    if name == "DQfD":
        from dqfd_bc_keras.model import DQfD

        return DQfD
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
