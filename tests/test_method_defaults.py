"""A preset's defaults for one method (`TaskSpec.method_defaults`): read when that method runs, from the
command line, Python and the lab alike; never for another method; never over what the user sets; and the
lab's committed suites stay what their runs are (PREREGISTRATION §16: Acrobot's `bayes` since 2026-12-07)."""

import json

import pytest
from helpers import call

from dqfd_bc_keras import DQfD
from dqfd_bc_keras.core.config import Config, preset_defaults, shared_defaults
from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.experiments.arm_config import arm
from dqfd_bc_keras.experiments.suites import SUITES
from dqfd_bc_keras.tasks import TaskSpec, register_task
from dqfd_bc_keras.tasks.acrobot import TUNED_BAYES

GENERIC = {"learning_rate": 0.001, "n_step": 10, "batch_size": 64, "target_update_period": 250, "train_freq": 1}
"""Acrobot's shared defaults for five of the tuned fields (ENV_DEFAULTS over Config's): what `ce` still gets."""


def test_the_tuned_set_is_acrobots_bayes_default_and_no_other_methods():
    bayes, ce, none = (Config.for_task("acrobot", expert_loss=m) for m in ("bayes", "ce", "none"))
    assert Config.for_task("acrobot") == bayes  # bayes is the preset's method
    assert {k: getattr(bayes, k) for k in GENERIC} == {k: TUNED_BAYES[k] for k in GENERIC}
    assert (bayes.learning_rate, bayes.n_step, bayes.bc_epochs) == (0.0002002542278540594, 8, 67)
    for other in (ce, none):
        assert {k: getattr(other, k) for k in GENERIC} == GENERIC
    assert Config.for_task("cartpole").learning_rate == 0.001  # no other preset has any


def test_what_the_user_sets_wins_over_the_methods_defaults():
    config = Config.for_task("acrobot", learning_rate=0.01, n_step=3)
    assert (config.learning_rate, config.n_step, config.bc_epochs) == (0.01, 3, TUNED_BAYES["bc_epochs"])
    assert preset_defaults("acrobot")["n_step"] == 8 and shared_defaults("acrobot")["n_step"] == 10


def test_a_saved_config_is_read_as_it_was_written_whatever_the_defaults_now():
    old = {**Config.for_task("acrobot", expert_loss="ce").to_dict(), "expert_loss": "bayes"}  # before the tuning
    assert Config.from_dict(json.loads(json.dumps(old))).learning_rate == 0.001


@pytest.mark.slow
def test_the_command_line_and_python_read_them_as_the_config_does(tmp_path):
    assert DQfD("acrobot").config == Config.for_task("acrobot")
    assert DQfD("acrobot", expert_loss="ce").config.n_step == 10
    done = call("train.py", "--task", "acrobot", "--quick", "--quiet", "--out", tmp_path / "run")
    assert done.returncode == 0, done.stderr
    written = json.loads((tmp_path / "run" / "config.json").read_text())
    assert (written["expert_loss"], written["n_step"], written["learning_rate"]) == ("bayes", 8, 0.0002002542278540594)


def test_a_lab_arm_is_named_against_its_methods_defaults_and_the_efficiency_suite_stays_seven():
    assert arm("acrobot", "bootstrap", "bayes", n_step=8).name == "acrobot-bootstrap-bayes"  # the default
    assert arm("acrobot", "bootstrap", "bayes", n_step=10).name == "acrobot-bootstrap-bayes-n_step10"
    [suite] = [a for a in SUITES["efficiency"] if a.task == "acrobot"]
    assert suite.name == "acrobot-bootstrap-bayes"  # its committed runs' directory
    assert {k: getattr(suite.config(0), k) for k in GENERIC} == GENERIC  # and their settings


def test_the_studies_runs_of_the_defaults_stay_on_the_defaults_they_ran_with():
    """§15's `bayes` arm and §16's defaults are §7's runs (the same names): rerun, they would be those runs again."""
    from studies import past_teacher_vector
    from studies.tuned_presets import PLANS

    defaults, vector = PLANS[0].defaults_arm("bayes"), past_teacher_vector.ours("acrobot", "bayes")
    assert defaults.name == vector.name == "acrobot-bootstrap-bayes"
    for a in (defaults, vector):
        assert {k: getattr(a.config(0), k) for k in GENERIC} == GENERIC
    tuned = PLANS[0].tuned_arm("bayes", TUNED_BAYES).config(0)
    assert {k: getattr(tuned, k) for k in TUNED_BAYES} == TUNED_BAYES  # its params over the pinned values
    assert tuned == Config.for_task("acrobot", seed=0, **dict(PLANS[0].protocol))  # what train.py now runs


def test_a_users_preset_naming_no_config_field_for_a_method_is_one_line():
    register_task(TaskSpec("typo-method-pole", "CartPole-v1", method_defaults={"ce": {"n_stepz": 3}}))
    with pytest.raises(ConfigError, match=r"task 'typo-method-pole': its defaults for 'ce' hold an unknown Config "):
        Config.for_task("typo-method-pole")
