"""A user's plug-ins (a demonstrator rule, a task preset, a method, a suite, each in a module of their
own) checked where the user meets them: a rule that fails, or a module that cannot give it, is one
line naming it and its file:line, before TensorFlow loads, and leaves nothing; a preset offers only
the experts it has; a run of a user's method evaluates without the method's module, and its resume
says the module is missing; a suite named `module:NAME` that is not there is one line. The preset,
method and suite are docs/EXTENDING.md's recipes (tests/test_extending.py runs them as written)."""

from pathlib import Path

import pytest
from helpers import LAB, assert_refused, assert_without_tensorflow, call, command, left_in, tree
from test_extending import recipe, write

# --- a demonstrator rule ---


MY_RULES = """import numpy as np
def bad(obs):
    return 1 / 0
"""
"""my_rules.py: `bad` raises at line 3; the cases below replace its body."""


@pytest.mark.parametrize(
    "body, message",
    [
        ("    return 1 / 0", "my_rules:bad raised ZeroDivisionError: division by zero (my_rules.py:3)"),
        (
            "    return 1.0",
            "my_rules:bad returned 1.0 (float); a demonstrator returns an int action in [0, 2) (my_rules.py:2)",
        ),
        (
            "    return np.float64(1)",
            "my_rules:bad returned np.float64(1.0) (float64); a demonstrator returns an int "
            "action in [0, 2) (my_rules.py:2)",
        ),
        (
            "    return '1'",
            "my_rules:bad returned '1' (str); a demonstrator returns an int action in [0, 2) (my_rules.py:2)",
        ),
        (
            "    return obs[3] > 0",
            "my_rules:bad returned np.False_ (bool); a demonstrator returns an int action in [0, 2) (my_rules.py:2)",
        ),
        (
            "    return 7",
            "my_rules:bad returned 7 (int); a demonstrator returns an int action in [0, 2) (my_rules.py:2)",
        ),
    ],
    ids=["raises", "float", "numpy-float", "string", "bool", "out-of-range"],
)
def test_a_demonstrator_rule_that_fails_is_one_line_before_tensorflow_and_leaves_nothing(tmp_path, body, message):
    (tmp_path / "my_rules.py").write_text(MY_RULES.replace("    return 1 / 0", body))
    done = command(
        "train.py",
        "--env",
        "CartPole-v1",
        "--expert",
        "my_rules:bad",
        "--quick",
        cwd=tmp_path,
        path=[tmp_path],
        block_tensorflow=True,
    )
    assert_refused(done, f"error: {message}")  # no banner either
    assert left_in(tmp_path) == ["my_rules.py"]  # no runs/ directory


@pytest.mark.parametrize(
    "rules, expert, message",
    [
        (
            MY_RULES,
            "my_rules:flap",
            "demonstrator my_rules:flap: my_rules (my_rules.py) has no function 'flap'; it has bad",
        ),
        (
            "import numpy\nimport not_installed_pkg\n" + MY_RULES,
            "my_rules:bad",
            "demonstrator my_rules:bad: importing my_rules raised ModuleNotFoundError: No module named "
            "'not_installed_pkg' (my_rules.py:2)",
        ),
        (
            "def bad(obs)\n    return 0\n",
            "my_rules:bad",
            "demonstrator my_rules:bad: importing my_rules raised SyntaxError: expected ':' (my_rules.py:1)",
        ),
        (
            MY_RULES,
            "my_rulez:bad",
            "demonstrator my_rulez:bad: no module named 'my_rulez' (is its directory on PYTHONPATH?)",
        ),
    ],
    ids=["missing-function", "import-error", "syntax-error", "missing-module"],
)
def test_a_demonstrator_module_that_cannot_give_its_rule_is_one_line_before_tensorflow(
    tmp_path, rules, expert, message
):
    (tmp_path / "my_rules.py").write_text(rules)
    done = command(
        "train.py",
        "--env",
        "CartPole-v1",
        "--expert",
        expert,
        "--quick",
        cwd=tmp_path,
        path=[tmp_path],
        block_tensorflow=True,
    )
    assert_refused(done, f"error: {message}")
    assert left_in(tmp_path) == ["my_rules.py"]


@pytest.mark.slow
@pytest.mark.parametrize("body", ["    return np.int64(obs[3] > 0)", "    return np.array(1)", "    return 1"])
def test_a_rule_answering_an_integer_passes_the_check_and_training_goes_on(tmp_path, body):
    """A numpy integer or a 0-d integer array is an action: the command goes on to load TensorFlow
    (blocked here), which shows that the failures above come before it."""
    (tmp_path / "my_rules.py").write_text(MY_RULES.replace("    return 1 / 0", body))
    done = command(
        "train.py",
        "--env",
        "CartPole-v1",
        "--expert",
        "my_rules:bad",
        "--quick",
        cwd=tmp_path,
        path=[tmp_path],
        block_tensorflow=True,
    )
    assert done.returncode != 0 and "ImportError: tensorflow is blocked by the test" in done.stderr
    assert "my_rules" not in done.stderr


@pytest.mark.slow
def test_a_rule_that_raises_while_demonstrations_are_recorded_is_one_line_and_leaves_no_run(tmp_path):
    (tmp_path / "my_rules.py").write_text(
        "calls = 0\n\n\ndef bad(obs):\n    global calls\n    calls += 1\n"
        "    if calls > 5:\n        raise RuntimeError(f'call {calls}')\n    return 0\n"
    )
    done = call(
        "train.py",
        "--env",
        "CartPole-v1",
        "--expert",
        "my_rules:bad",
        "--quick",
        "--quiet",
        "--out",
        tmp_path / "run",
        cwd=tmp_path,
        path=[tmp_path],
    )
    assert_refused(done, "error: my_rules:bad raised RuntimeError: call 6 (my_rules.py:8)")
    assert left_in(tmp_path) == ["my_rules.py"]  # the new run's directory is removed


# --- a preset, a method, a suite ---


def test_a_users_preset_refuses_an_expert_it_does_not_have_before_tensorflow(tmp_path):
    write(recipe("A task preset, or a task family")[0], tmp_path)
    done = command(
        "train.py",
        "--task",
        "my_tasks:short-pole",
        "--expert",
        "imperfect",
        "--quick",
        cwd=tmp_path,
        path=[tmp_path],
        block_tensorflow=True,
    )
    assert_refused(
        done,
        "error: unknown expert name 'imperfect'; valid choices: lean (the scripted experts of "
        "short-pole: choose one with --expert)",
    )
    assert left_in(tmp_path) == ["my_tasks.py"]


def unlocked_tree(run: Path) -> dict:
    """`tree(run)` without the lock file, which each command that opens the run takes."""
    return {name: data for name, data in tree(run).items() if Path(name).name != ".lock"}


@pytest.mark.slow
def test_a_run_of_a_users_method_evaluates_without_its_module_and_resume_says_it_is_missing(tmp_path):
    code = tmp_path / "code"
    code.mkdir()
    write(recipe("A method (an expert loss)")[0], code)
    out = tmp_path / "run"
    trained = call(
        "train.py",
        "--expert-loss",
        "my_methods:HALF_CE",
        "--quick",
        "--quiet",
        "--set",
        "total_steps=60",
        "--set",
        "pretrain_steps=5",
        "--out",
        out,
        cwd=tmp_path,
        path=[code],
    )
    assert trained.returncode == 0, trained.stderr
    before = unlocked_tree(out)
    evaluated = command("evaluate.py", out, "--episodes", "1", cwd=tmp_path)
    assert (evaluated.returncode, evaluated.stderr) == (0, "")
    assert "1 greedy episodes" in evaluated.stdout
    resumed = command("train.py", "--out", out, "--resume", "--quiet", cwd=tmp_path)
    assert (resumed.returncode, resumed.stderr) == (
        2,
        "error: expert_loss='my_methods:HALF_CE': no module named 'my_methods' (is its directory on PYTHONPATH?)\n",
    )
    assert unlocked_tree(out) == before


def test_a_module_name_suite_that_is_not_there_is_refused_in_one_line(tmp_path):
    write(recipe("A suite of runs")[0], tmp_path)
    for suite, message in (
        (
            "my_suites:SIGMA",
            "error: suite 'my_suites:SIGMA': my_suites (my_suites.py) has no non-empty list of "
            "experiments.suites.Arm 'SIGMA'; it has SIGMAS",
        ),
        (
            "my_suite:SIGMAS",
            "error: suite 'my_suite:SIGMAS': no module named 'my_suite' (is its directory on PYTHONPATH?)",
        ),
    ):
        done = command(*LAB, "run", suite, "--out", "results", cwd=tmp_path, path=["."])
        assert_refused(done, message)
        assert_without_tensorflow(done)
    assert left_in(tmp_path) == ["my_suites.py"]
