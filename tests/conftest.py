"""Fixtures shared by the learning tests: the strong CartPole expert's demonstrations and one
fitted BC model per kind (fitted once per session: each fit takes a few seconds)."""

import dqfd_bc_keras  # noqa: F401  (first: TF settings; custom objects, Gymnasium ids)
import keras
import pytest
from dqfd_bc_keras.bc import build_bc_model
from dqfd_bc_keras.config import Config
from dqfd_bc_keras.demos import DemoDataset, record


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
    """{expert_loss: BC model fitted with the defaults}: MAP for bayes, MLE for ce and bc_margin."""
    keras.utils.set_random_seed(0)
    models = {}
    for loss in ("bayes", "ce"):
        config = Config.for_task("cartpole", expert_loss=loss)
        models[loss] = build_bc_model(config, 4, 2, demos.obs_scale())
        models[loss].fit_demos(demos.obs, demos.actions, epochs=config.bc_epochs)
    models["bc_margin"] = models["ce"]
    return models
