"""The registries of methods and tasks: what they declare, what derives from them, and a user's own
preset, defined in their own module outside the package, as a config and a family. (A user's own method
and preset trained and evaluated through the command line: test_extending.py, which runs
docs/EXTENDING.md's recipes as written.)

The checks below read the registries, so a method or a family added to the package passes them with its
own tests only; the package's entries of today are named where their own declarations are checked."""

import dataclasses
import sys
from pathlib import Path

import pytest
from helpers import call

from dqfd_bc_keras import DQfD
from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.core.methods import BAYES_FIELDS, METHODS, Method, get_method, register
from dqfd_bc_keras.demos import record
from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.experiments.arms import BAYES_ONLY
from dqfd_bc_keras.experiments.efficiency import teachers
from dqfd_bc_keras.experiments.estimators import calibrated_tasks
from dqfd_bc_keras.experiments.lab_settings import LAB_SETTINGS, LabSettings, lab_settings, register_lab_settings
from dqfd_bc_keras.experiments.suites import efficiency_tasks
from dqfd_bc_keras.plugins import ImportFailed, ModuleMissing, NameMissing, NotAReference, WrongKind, load, parse
from dqfd_bc_keras.tasks import TASKS, family_preset

BC_FIT = {
    "margin": "none",
    "bc_margin": "mle",
    "ce": "mle",
    "bayes": "map",
    "none": "none",
    "sqil": "none",
    "bc-alone": "mle",
}
"""The paper's methods and the baselines, in the order registered, with how each fits π_bc."""
FAMILIES = ("cartpole", "mountaincar", "acrobot", "lunarlander", "minatar-breakout", "minatar-freeway")
"""The package's families whose lab settings are checked by hand below."""

MY_TASK = '''
from dqfd_bc_keras.experiments.lab_settings import LabSettings, register_lab_settings
from dqfd_bc_keras.tasks import TaskSpec, register_task


def lean(obs):
    """Push towards the side the pole leans and falls to."""
    return int(obs[2] + obs[3] > 0)


register_task(TaskSpec("short-pole", "CartPole-v1", family="short-pole", max_steps=60, fall_penalty=-10.0,
                       solved_return=55.0, defaults={"target_update_period": 77, "demo_episodes": 3},
                       experts={"lean": lean}))
register_lab_settings("short-pole", LabSettings(target_ratio=3.0))
'''


@pytest.fixture
def user_code(tmp_path: Path) -> Path:
    """A directory outside the package with the user's own preset module."""
    code = tmp_path / "user"
    code.mkdir()
    (code / "my_tasks.py").write_text(MY_TASK)
    return code


def test_the_registry_holds_every_builtin_method_and_config_derives_from_it():
    assert [m for m in METHODS if m in BC_FIT] == list(BC_FIT)  # each still there, in its order
    assert {m: METHODS[m].bc_fit for m in BC_FIT} == BC_FIT
    fields = {f.name for f in dataclasses.fields(Config)}
    for method in METHODS.values():
        assert set(method.reads) <= fields, method.name  # every declared field is a Config field
        if not method.q_learning:
            continue
        config = Config.for_task("cartpole", expert_loss=method.name)
        assert (config.uses_demos, config.uses_bc, config.bayesian_bc) == (
            method.needs_demos,
            method.bc_fit != "none",
            method.bc_fit == "map",
        ), method.name
        assert (method.term is None) == (method.expert_term() is None)
    assert set(BAYES_ONLY) == set(BAYES_FIELDS)  # what a bayes arm may differ from its ce pair in


def test_an_unknown_method_and_behavioural_cloning_alone_are_refused_by_validation():
    with pytest.raises(ConfigError, match=r"expert_loss='bayse' is not one of \('margin', 'bc_margin'"):
        Config.for_task("cartpole", expert_loss="bayse")
    with pytest.raises(ConfigError, match="expert_loss='no_such_module:X': no module named 'no_such_module'"):
        Config.for_task("cartpole", expert_loss="no_such_module:X")
    with pytest.raises(ConfigError, match=r"expert_loss='json:X': json \(.*json/__init__.py\) has no dqfd_bc_"):
        get_method("json:X")
    with pytest.raises(ConfigError, match=r"'json:dumps': dumps is not a dqfd_bc_keras.core.methods.Method \(it is"):
        get_method("json:dumps")
    with pytest.raises(ConfigError, match="'bc-alone' trains no Q-network"):
        Config.for_task("cartpole", expert_loss="bc-alone")
    with pytest.raises(ConfigError, match="bc_fit='exact' is not one of"):
        Method("x", "x", bc_fit="exact")
    with pytest.raises(ConfigError, match="method 'x': a reference without a term"):
        Method("x", "x", reference="dqfd_bc_keras.core.reference:margin")


def test_a_method_of_a_scripts_own_under_a_built_in_name_is_refused():
    """config.json records the name: a run of another loss called `bayes` would be read as bayes'."""
    impostor = dataclasses.replace(METHODS["bayes"], doc="another loss under bayes' name")
    match = r"register\(\): 'bayes' is the name of a built-in method \(margin, bc_margin, ce, bayes"
    with pytest.raises(ConfigError, match=match):
        register(impostor)
    with pytest.raises(ConfigError, match=match):
        DQfD("cartpole", expert_loss=impostor)  # a script's Method is registered under its name
    assert register(METHODS["bayes"]) is METHODS["bayes"] and get_method("bayes").doc != impostor.doc


def package(table: dict) -> dict:
    """`table` (task → value) restricted to the presets of FAMILIES."""
    return {t: v for t, v in table.items() if t in TASKS and TASKS[t].family in FAMILIES}


def test_the_lab_tables_derive_from_the_lab_settings():
    assert package(efficiency_tasks()) == {"cartpole": 5, "mountaincar": 10, "acrobot": 10, "lunarlander": 10}
    assert package(teachers()) == {"acrobot": -112.68, "lunarlander": 129.03}
    assert [t for t in calibrated_tasks() if t in package(LAB_SETTINGS)] == ["cartpole", "mountaincar"]
    assert [lab_settings(t).target_ratio for t in package(efficiency_tasks())] == [10.0, 10.0, 5.0, 5.0]
    assert package({t: s.ablation_metric for t, s in LAB_SETTINGS.items() if s.ablation_metric}) == {
        "cartpole": "mean_train_return",
        "mountaincar-goals": "goals_first30",
    }
    assert family_preset("mountaincar").name == "mountaincar"  # the variant shares its family's experts
    assert TASKS["mountaincar-goals"].experts is TASKS["mountaincar"].experts


def test_a_users_preset_is_a_config_and_a_family_in_process(user_code, monkeypatch):
    monkeypatch.syspath_prepend(str(user_code))
    config = Config.for_task("my_tasks:short-pole")
    assert (config.limit, config.target_update_period, config.demo_episodes) == (60, 77, 3)
    assert config.eval_every == Config.for_task("cartpole").eval_every * 5  # the shared default, 5,000
    assert family_preset("short-pole").name == "short-pole" and lab_settings("short-pole").target_ratio == 3.0
    with pytest.raises(ConfigError, match="unknown expert name 'strong'; valid choices: lean"):
        record("my_tasks:short-pole", "strong", episodes=1)
    assert record("my_tasks:short-pole", "lean", episodes=1).meta.expert == "lean"


def test_a_preset_whose_defaults_name_no_config_field_is_one_line_on_the_command_line(tmp_path):
    (tmp_path / "my_typo_tasks.py").write_text(
        "from dqfd_bc_keras.tasks import TaskSpec, register_task\n\n"
        "register_task(TaskSpec('typo-pole', 'CartPole-v1', defaults={'total_step': 1000}))\n"
    )
    answer = call("train.py", "--task", "my_typo_tasks:typo-pole", "--out", tmp_path / "run", path=[tmp_path])
    assert (answer.returncode, answer.stderr) == (
        2,
        "error: task 'my_typo_tasks:typo-pole': its defaults hold an unknown Config field 'total_step'; "
        "did you mean total_steps?\n",
    )
    assert not (tmp_path / "run").exists()


def test_lab_settings_registered_later_reach_the_lab_tables(user_code, monkeypatch):
    """The tables are read when asked: a user's module registers its settings after the lab is imported."""
    monkeypatch.syspath_prepend(str(user_code))
    Config.for_task("my_tasks:short-pole")  # imports the module, which registers its lab settings
    assert "short-pole" not in efficiency_tasks() and "short-pole" not in teachers()
    register_lab_settings("short-pole", LabSettings(efficiency_demos=4, teacher_return=41.5, calibrate=True))
    assert (efficiency_tasks()["short-pole"], teachers()["short-pole"]) == (4, 41.5)
    assert calibrated_tasks()[-1] == "short-pole"


@pytest.fixture(autouse=True)
def _forget_user_presets():
    yield
    TASKS.pop("short-pole", None)
    LAB_SETTINGS.pop("short-pole", None)
    sys.modules.pop("my_tasks", None)


PLUGIN = """
import json


def go_left(obs):
    return 0


def _private(obs):
    return 1


WIDTH = 3
"""


@pytest.mark.parametrize(
    "source, reference, error, message",
    [
        (PLUGIN, "my_plugin", NotAReference, "expected module:NAME"),
        (PLUGIN, "my_plugn:go_left", ModuleMissing, "no module named 'my_plugn' (is its directory on PYTHONPATH?)"),
        (
            "import numpy\nimport not_installed_pkg\n",
            "my_plugin:go_left",
            ImportFailed,
            "importing my_plugin raised ModuleNotFoundError: No module named 'not_installed_pkg' (my_plugin.py:2)",
        ),
        (
            "x = 1 / 0\n",
            "my_plugin:x",
            ImportFailed,
            "importing my_plugin raised ZeroDivisionError: division by zero (my_plugin.py:1)",
        ),
        (
            PLUGIN,
            "my_plugin:go_right",
            NameMissing,
            "my_plugin (my_plugin.py) has no function 'go_right'; it has go_left",
        ),
        (PLUGIN, "my_plugin:WIDTH", WrongKind, "WIDTH is not a function (it is of type int)"),
    ],
    ids=["no-colon", "module-missing", "import-error-inside", "raises-inside", "name-missing", "wrong-kind"],
)
def test_a_module_name_reference_fails_in_one_typed_line(tmp_path, monkeypatch, source, reference, error, message):
    """Every caller of plugins.load (methods, rules, suites) and plugins.import_module (presets, env ids)
    reads these: the module missing told apart from an ImportError its own code raises."""
    (tmp_path / "my_plugin.py").write_text(source)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.chdir(tmp_path)
    monkeypatch.delitem(sys.modules, "my_plugin", raising=False)
    with pytest.raises(error) as raised:
        load(reference, f"rule {reference!r}", callable, "function")
    assert str(raised.value) == f"rule {reference!r}: {message}"
    assert "\n" not in str(raised.value) and isinstance(raised.value, ConfigError)


def test_a_module_name_reference_gives_what_it_names(tmp_path, monkeypatch):
    (tmp_path / "my_plugin.py").write_text(PLUGIN)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "my_plugin", raising=False)
    assert load("my_plugin:go_left", "rule", callable, "function")(None) == 0
    assert load("my_plugin:WIDTH", "width") == 3
    assert parse("pkg.mod:Env-v0") == ("pkg.mod", "Env-v0") and parse("ALE/Pong-v5") is None and parse(":x") is None
