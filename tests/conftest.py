"""Fixtures shared by the tests: the strong CartPole expert's demonstrations, one fitted BC model per
kind of fit and one finished `--quick` run per expert loss (each made once per session, as the first
test asks for it), and the process-wide state every test leaves as it found it. First of all, the
process is configured as the command lines configure theirs (`runtime.configure`), before anything
imports TensorFlow: the tests run in-process what the commands run, with the commands' numbers."""

from dqfd_bc_keras import runtime

runtime.configure()

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import keras
import pytest
from helpers import Answer, call, forgetting

from dqfd_bc_keras.core.bc import build_bc_model
from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.core.methods import METHODS
from dqfd_bc_keras.demos import DemoDataset, record


@pytest.fixture(autouse=True)
def forget_what_the_test_registered(tmp_path_factory) -> Iterator[None]:
    """A command run in this process, or a user's module it imports from the test's temporary
    directory, must not change what a later test on the same worker sees."""
    with forgetting(tmp_path_factory.getbasetemp()):
        yield


@pytest.fixture(scope="session")
def demos() -> DemoDataset:
    """5 episodes (2,500 transitions) of CartPole's strong expert."""
    return record("cartpole", "strong", episodes=5, seed=0)


@pytest.fixture(scope="session")
def held_out() -> DemoDataset:
    """2 other episodes of the same expert, never trained on."""
    return record("cartpole", "strong", episodes=2, seed=100)


@pytest.fixture(scope="session")
def bc_models(demos) -> dict:
    """{expert_loss: BC model fitted with the defaults} for every registered method with a BC model:
    one model per kind of fit (`Method.bc_fit`: MAP for bayes, MLE for ce and bc_margin), shared by
    the methods of that kind, so a new method finds its model here without an edit."""
    keras.utils.set_random_seed(0)
    by_fit = {}
    for fit in sorted({m.bc_fit for m in METHODS.values() if m.uses_bc}):  # map, then mle: one seed sequence
        loss = next(m.name for m in METHODS.values() if m.bc_fit == fit and m.q_learning)
        config = Config.for_task("cartpole", expert_loss=loss)
        by_fit[fit] = build_bc_model(config, 4, 2, demos.obs_scale())
        by_fit[fit].fit_demos(demos.obs, demos.actions, epochs=config.bc_epochs)
    return {name: by_fit[m.bc_fit] for name, m in METHODS.items() if m.uses_bc}


@dataclass(frozen=True)
class QuickRun:
    """A finished `train.py --quick` run (seed 0) and what the command answered."""

    out: Path
    answer: Answer


@pytest.fixture(scope="session")
def quick_run(tmp_path_factory) -> Callable[[str], QuickRun]:
    """`quick_run(loss)`: `train.py --quick --expert-loss LOSS --out …`, trained in this process when a
    test first asks for it, then shared. Read-only: a test that changes a run copies `out` first."""
    finished: dict[str, QuickRun] = {}

    def train(loss: str = "bayes") -> QuickRun:
        if loss not in finished:
            out = tmp_path_factory.mktemp(f"quick-{loss}") / "run"
            answer = call("train.py", "--quick", "--expert-loss", loss, "--out", out)
            assert answer.returncode == 0, answer.stderr
            finished[loss] = QuickRun(out, answer)
        return finished[loss]

    return train


@pytest.fixture
def finished(quick_run) -> Path:
    """The session's finished `train.py --quick` run (read-only: a test copies it before it changes it)."""
    return quick_run().out
