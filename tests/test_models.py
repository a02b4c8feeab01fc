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
from dqfd_bc_keras.seeds import demo_seed

MODELS = Path(__file__).resolve().parents[1] / "models"


STUDY_ARM = "ce_decay"
"""The MinAtar models' method: the best arm of W's study across the five games (docs/PAST_TEACHER.md)."""
SHIPPED = sorted(folder.name for folder in MODELS.iterdir() if (folder / "q_network.keras").is_file())


@pytest.mark.parametrize("game", [name for name in SHIPPED if name.startswith("minatar-")])
def test_models_readme_says_whether_each_minatar_model_reaches_its_teachers_mean(game):
    from studies.minatar_study import ANCHORS

    recorded = json.loads((MODELS / game / "eval.json").read_text())
    [row] = [line for line in (MODELS / "README.md").read_text().splitlines() if line.startswith(f"| `{game}/` |")]
    assert f"{recorded['mean_return']:.2f} ± {recorded['std_return']:.2f}" in row and recorded["episodes"] == 100
    reaches = recorded["mean_return"] >= ANCHORS[game][1]
    assert ("at least its teacher's mean" in row, "below its teacher's mean" in row) == (reaches, not reaches)


@pytest.mark.parametrize("name", SHIPPED)
def test_the_front_pages_table_gives_each_models_eval_json(name):
    recorded = json.loads((MODELS / name / "eval.json").read_text())
    said = f"{recorded['mean_return']:.2f} ± {recorded['std_return']:.2f}".replace("-", "−")
    readme = (MODELS.parent / "README.md").read_text()
    table = readme[readme.index("| model | plain env | the teacher | the agent |") : readme.index("## Results")]
    [row] = [line for line in table.splitlines() if line.startswith(f"| `{name}` |")]
    assert said in row, (said, row)


def test_every_shipped_model_is_in_the_table_of_models_readme():
    table = (MODELS / "README.md").read_text()
    assert len(SHIPPED) >= 8 and all(f"| `{name}/` |" in table for name in SHIPPED)


@pytest.mark.slow
@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_model_plays_as_its_eval_json_says(name):
    folder = MODELS / name
    config = Config.from_dict(json.loads((folder / "config.json").read_text()))
    recorded = json.loads((folder / "eval.json").read_text())
    # The MinAtar models are W's study's best arm (models/README.md); the others the paper's method.
    assert config.expert_loss == (STUDY_ARM if name.startswith("minatar-") else "bayes")
    assert config.expert == "imperfect"
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


@pytest.mark.slow
def test_teacher_agreement_reconstructs_the_demonstrations_a_shipped_model_was_fitted_on():
    """docs/teacher_agreement.py --quick: its BC model takes the teacher's action on (nearly) every state
    of the episodes its run demonstrated, which only holds if the script records those very episodes;
    and a network that takes the teacher's action on every state of its own play, on the seed the
    teacher is played at with its ε of 0, scores what the teacher scores (one policy, one seed)."""
    import subprocess
    import sys

    script = Path(__file__).resolve().parents[1] / "docs" / "teacher_agreement.py"
    done = subprocess.run([sys.executable, script, "--quick"], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    rows = [line.split(" | ") for line in done.stdout.splitlines() if line.startswith("| minatar-breakout")]
    agreements, teachers = rows[:4], rows[4:]
    assert [row[1].split(" (")[0] for row in agreements] == [
        "demonstrated",
        "held out",
        "its Q-network's own play",
        "its BC model's own play",
    ]
    config = json.loads((MODELS / "minatar-breakout" / "config.json").read_text())
    first = demo_seed(config["seed"])  # the run's own demonstrations, episode i at demo_seed + i
    assert agreements[0][1] == f"demonstrated (seeds {first}–{first + config['demo_episodes'] - 1})"
    assert agreements[1][1] == "held out (seeds 900000–900000)"
    shares = [[float(cell.strip(" |%")) for cell in row[3:5] if cell.strip(" |")] for row in agreements]
    assert shares[0][1] >= 99.0 and all(0.0 <= share <= 100.0 for row in shares for share in row)
    assert [len(row) for row in shares] == [2, 2, 1, 1]
    assert [row[1] for row in teachers] == ["Q-network", "BC model"]
    for network in teachers:  # ε = disagreement · A / (A − 1), Breakout's A = 3
        assert float(network[3]) == pytest.approx(min(1.0, float(network[2].rstrip("%")) / 100 * 3 / 2), abs=1e-3)
    # The BC model agrees on the held-out episode (ε = 0) and on every state of its own play on that seed.
    assert (teachers[1][2], teachers[1][3], shares[3]) == ("0.0%", "0.000", [100.0])
    own_return = agreements[3][1].split("return ")[1].rstrip(")")
    assert teachers[1][4].split(" ± ")[0] == own_return


@pytest.mark.slow
def test_the_expert_loss_tables_in_models_readme_are_what_the_committed_runs_give():
    """docs/expert_losses.py reads the study's archive and the probe's archive; its tables are the
    ones models/README.md quotes, row for row, and their per-seed columns are the runs' last evaluations
    (a median and a count above the teacher computed by hand from them)."""
    import statistics
    import subprocess
    import sys

    from studies.minatar_study import ANCHORS

    script = Path(__file__).resolve().parents[1] / "docs" / "expert_losses.py"
    done = subprocess.run([sys.executable, script], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    readme = (MODELS / "README.md").read_text()
    tables = done.stdout.split("\n\nthe probe runs' code")[0].split("\n\nminatar-")
    assert [t.split(" (")[0].removeprefix("minatar-") for t in tables] == ["breakout", "freeway"]
    for text in tables:
        game = "minatar-" + text.split(" (")[0].removeprefix("minatar-")
        table = [line for line in text.splitlines() if line.startswith("|")]
        assert all(line in readme for line in table)
        losses = [line.split(" | ")[0].strip("| `") for line in table[2:]]
        assert losses[0] == "bayes" and {"margin", "none"} <= set(losses) and losses[-1] == "SB3 DQN (rl-zoo3)"
        for line in table[2:]:
            cells = line.split(" | ")
            median, per_seed = cells[4].split(" (")
            finals = [float(x) for x in per_seed.rstrip(")").split(", ")]
            assert len(finals) == int(cells[2]) >= 3
            assert float(median) == pytest.approx(statistics.median(finals), abs=0.005)
            assert int(cells[7].split(" of ")[0]) == sum(x > ANCHORS[game][1] for x in finals)
