"""The registries of methods and tasks: what they declare, what derives from them, and a user's own
method and preset, defined in their own module outside the package, trained and evaluated through
the command line."""

import csv
import dataclasses
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from dqfd_bc_keras.config import Config
from dqfd_bc_keras.demos import record
from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.experiments.arms import BAYES_ONLY
from dqfd_bc_keras.experiments.efficiency import TEACHER
from dqfd_bc_keras.experiments.suites import EFFICIENCY_TASKS
from dqfd_bc_keras.methods import BAYES_FIELDS, METHODS, Method, get_method
from dqfd_bc_keras.tasks import TASKS, family_preset

REPO = Path(__file__).resolve().parents[1]

MY_METHOD = '''
import os
from pathlib import Path

from dqfd_bc_keras import losses
from dqfd_bc_keras.methods import Method


def half_ce(agent, q, batch):
    """Half of DQfD-BC's cross-entropy; leaves a mark when the learning graph is traced with it."""
    Path(os.environ["TRACED"]).write_text(type(agent).__name__)
    j_e = losses.cross_entropy_loss(q, batch.pi_bc, agent.config.temperature)
    return 0.5 * losses.weighted_mean(j_e, batch.weights)


HALF_CE = Method("half_ce", "half the ce loss", bc_fit="mle", term=half_ce, reads=("temperature",))
'''

MY_TASK = '''
from dqfd_bc_keras.tasks import LabSettings, TaskSpec, register_task


def lean(obs):
    """Push towards the side the pole leans and falls to."""
    return int(obs[2] + obs[3] > 0)


register_task(TaskSpec("short-pole", "CartPole-v1", family="short-pole", max_steps=60, fall_penalty=-10.0,
                       solved_return=55.0, defaults={"target_update_period": 77, "demo_episodes": 3},
                       experts={"lean": lean}, lab=LabSettings(target_ratio=3.0)))
'''


@pytest.fixture
def user_code(tmp_path: Path) -> tuple[Path, dict]:
    """A directory outside the package with the user's own method and preset modules on the path."""
    code = tmp_path / "user"
    code.mkdir()
    (code / "my_methods.py").write_text(MY_METHOD)
    (code / "my_tasks.py").write_text(MY_TASK)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), str(code)]), "TRACED": str(tmp_path / "traced")}
    return code, env


def script(name: str, *args: object, env: dict, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(REPO / name), *map(str, args)], capture_output=True, text=True,
                          env=env, cwd=cwd, timeout=600)


def test_the_registry_holds_every_builtin_method_and_config_derives_from_it():
    assert list(METHODS) == ["margin", "bc_margin", "ce", "bayes", "none", "sqil", "bc-alone"]
    fields = {f.name for f in dataclasses.fields(Config)}
    for method in METHODS.values():
        assert set(method.reads) <= fields, method.name  # every declared field is a Config field
        if not method.q_learning:
            continue
        config = Config.for_task("cartpole", expert_loss=method.name)
        assert (config.uses_demos, config.uses_bc, config.bayesian_bc) == \
            (method.needs_demos, method.bc_fit != "none", method.bc_fit == "map"), method.name
        assert (method.term is None) == (method.expert_term() is None)
    assert [m for m, d in METHODS.items() if d.bc_fit == "map"] == ["bayes"]
    assert set(BAYES_ONLY) == set(BAYES_FIELDS)  # what a bayes arm may differ from its ce pair in


def test_an_unknown_method_and_behavioural_cloning_alone_are_refused_by_validation():
    with pytest.raises(ConfigError, match=r"expert_loss='bayse' is not one of \('margin', 'bc_margin'"):
        Config.for_task("cartpole", expert_loss="bayse")
    with pytest.raises(ConfigError, match="expert_loss='no_such_module:X': cannot import it"):
        Config.for_task("cartpole", expert_loss="no_such_module:X")
    with pytest.raises(ConfigError, match="expert_loss='json:dumps': dumps is a function, not a dqfd_bc_keras"):
        get_method("json:dumps")
    with pytest.raises(ConfigError, match="'bc-alone' trains no Q-network"):
        Config.for_task("cartpole", expert_loss="bc-alone")
    with pytest.raises(ConfigError, match="bc_fit='exact' is not one of"):
        Method("x", "x", bc_fit="exact")


def test_the_lab_tables_derive_from_the_task_registry():
    assert EFFICIENCY_TASKS == {"cartpole": 5, "mountaincar": 10, "acrobot": 10, "lunarlander": 10}
    assert TEACHER == {"acrobot": -112.68, "lunarlander": 129.03}
    assert [TASKS[t].lab.target_ratio for t in EFFICIENCY_TASKS] == [10.0, 10.0, 5.0, 5.0]
    assert {t: s.lab.ablation_metric for t, s in TASKS.items() if s.lab.ablation_metric} == {
        "cartpole": "mean_train_return", "mountaincar-goals": "goals_first30"}
    assert family_preset("mountaincar").name == "mountaincar"  # the variant shares its family's experts
    assert TASKS["mountaincar-goals"].experts is TASKS["mountaincar"].experts


def test_a_users_method_from_their_module_trains_and_evaluates_end_to_end(user_code, tmp_path):
    code, env = user_code
    out = tmp_path / "run"
    done = script("train.py", "--expert-loss", "my_methods:HALF_CE", "--quick", "--quiet", "--out", out,
                  env=env, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "traced").read_text() == "DQfDAgent"  # the learning graph was built with the user's J_E
    assert json.loads((out / "config.json").read_text())["expert_loss"] == "my_methods:HALF_CE"
    assert (out / "bc_model.keras").is_file()  # bc_fit="mle": a BC model is fitted, saved and used
    evaluated = script("evaluate.py", out, "--episodes", "2", "--json", env=env, cwd=tmp_path)
    assert evaluated.returncode == 0, evaluated.stderr
    assert json.loads(evaluated.stdout)["episodes"] == 2


def test_a_users_preset_from_their_module_trains_with_its_defaults_limit_and_expert(user_code, tmp_path):
    code, env = user_code
    out = tmp_path / "run"
    done = script("train.py", "--task", "my_tasks:short-pole", "--expert", "lean", "--quick", "--quiet",
                  "--out", out, env=env, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    config = json.loads((out / "config.json").read_text())
    assert (config["task"], config["target_update_period"], config["expert"]) == ("my_tasks:short-pole", 77, "lean")
    with open(out / "metrics.csv") as rows:
        lengths = [int(row["length"]) for row in csv.DictReader(rows)]
    assert lengths and max(lengths) <= 60  # the preset's own step limit
    evaluated = script("evaluate.py", out, "--episodes", "2", "--json", env=env, cwd=tmp_path)
    assert evaluated.returncode == 0, evaluated.stderr
    assert max(json.loads(evaluated.stdout)["lengths"]) <= 500  # scored on the plain CartPole-v1


def test_a_users_preset_is_a_config_and_a_family_in_process(user_code, monkeypatch):
    code, _ = user_code
    monkeypatch.syspath_prepend(str(code))
    config = Config.for_task("my_tasks:short-pole")
    assert (config.limit, config.target_update_period, config.demo_episodes) == (60, 77, 3)
    assert config.eval_every == Config.for_task("cartpole").eval_every * 5  # the shared default, 5,000
    assert family_preset("short-pole").lab.target_ratio == 3.0
    with pytest.raises(ConfigError, match="unknown expert name 'strong'; valid choices: lean"):
        record("my_tasks:short-pole", "strong", episodes=1)
    assert record("my_tasks:short-pole", "lean", episodes=1).meta.expert == "lean"


@pytest.fixture(autouse=True)
def _forget_user_presets():
    yield
    TASKS.pop("short-pole", None)
    sys.modules.pop("my_tasks", None)
