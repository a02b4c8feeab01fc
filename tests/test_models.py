"""The trained models shipped in models/: they load in safe mode and still play as eval.json says."""

import json
from pathlib import Path

import keras
import numpy as np
import pytest

import dqfd_bc_keras  # noqa: F401  (registers BCModel)
from dqfd_bc_keras.core.bc import BCModel
from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.envs.make import get_task
from dqfd_bc_keras.evaluation import GreedyPolicy, evaluate

MODELS = Path(__file__).resolve().parents[1] / "models"


SHIPPED = sorted(folder.name for folder in MODELS.iterdir() if (folder / "q_network.keras").is_file())


def test_every_shipped_model_is_in_the_table_of_models_readme():
    table = (MODELS / "README.md").read_text()
    assert len(SHIPPED) >= 8 and all(f"| `{name}/` |" in table for name in SHIPPED)


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_model_plays_as_its_eval_json_says(name):
    folder = MODELS / name
    config = Config.from_dict(json.loads((folder / "config.json").read_text()))
    recorded = json.loads((folder / "eval.json").read_text())
    assert config.expert_loss == "bayes" and config.expert == "imperfect"
    assert recorded["episodes"] == 100 and recorded["task"] == config.task
    threshold = get_task(config.task).solved_return  # 475 / −110 …
    if threshold is not None:  # MinAtar has none; models/README.md says where its model stands (below its teacher)
        assert recorded["mean_return"] >= threshold

    q_network = keras.saving.load_model(folder / "q_network.keras")  # safe mode
    assert isinstance(keras.saving.load_model(folder / "bc_model.keras"), BCModel)
    # The first 5 of the 100 recorded episodes, replayed with their seeds.
    result = evaluate(GreedyPolicy.from_model(q_network), config.task, 5, recorded["seed"], timeout=config.timeout)
    np.testing.assert_allclose(result.returns, recorded["returns"][:5])
    assert abs(result.mean_return - recorded["mean_return"]) <= max(3 * recorded["std_return"], 5.0)
