"""The command lines as a user meets them: `--help` and argument errors answer before TensorFlow is
imported, near misses get a suggestion, and the package imports light."""

import os
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import command, importers

import dqfd_bc_keras
from dqfd_bc_keras.core.methods import METHODS
from dqfd_bc_keras.errors import ModelFileError
from dqfd_bc_keras.tasks import TASKS

REPO = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(REPO)}
LAB = ("-m", "dqfd_bc_keras.experiments")


class Done:
    """A command run under `python -X importtime`: its exit code, stdout, its own stderr lines and
    the chain of modules whose import brought TensorFlow in (empty: TensorFlow was not imported)."""

    def __init__(self, *args: object, cwd: Path = REPO, env: dict[str, str] = ENV) -> None:
        done = subprocess.run(
            [sys.executable, "-X", "importtime", *map(str, args)],
            capture_output=True,
            text=True,
            cwd=cwd,
            env=env,
            timeout=300,
        )
        self.code, self.stdout = done.returncode, done.stdout
        timings = [line.split("|")[-1] for line in done.stderr.splitlines() if line.startswith("import time:")]
        self.stderr = [line for line in done.stderr.splitlines() if not line.startswith("import time:")]
        self.tensorflow_importers = importers(timings[1:], "tensorflow")  # [0] is the header


def assert_answered_without_tensorflow(done: Done) -> None:
    assert done.tensorflow_importers == [], f"TensorFlow imported by {done.tensorflow_importers}"


def test_importers_reads_the_import_tree():
    timings = ["    tensorflow", "  keras", "  numpy", "dqfd_bc_keras.core.bc", "other"]
    assert importers(timings, "tensorflow") == ["keras", "dqfd_bc_keras.core.bc"]
    assert importers(timings, "numpy") == ["dqfd_bc_keras.core.bc"] and importers(timings, "scipy") == []


@pytest.mark.parametrize(
    "args, expected",
    [
        (("evaluate.py", "--help"), "--policy {bc,q}"),
        (("train.py", "--help"), "--expert-loss METHOD"),
        ((*LAB, "--help"), "efficiency"),
        ((*LAB, "run", "--help"), "--backend {local,ray}"),
        ((*LAB, "tune", "--help"), "--pruner {median,hyperband,none}"),
    ],
)
def test_help_answers_before_tensorflow_is_imported(args, expected):
    done = Done(*args)
    assert done.code == 0 and expected in done.stdout, done.stderr
    assert_answered_without_tensorflow(done)


@pytest.mark.parametrize(
    "args, message",
    [
        (
            ("evaluate.py", "models/cartpole", "--task", "CartPole-v1"),
            "argument --task: 'CartPole-v1' is a Gymnasium env id, not a task preset: did you mean --env CartPole-v1?",
        ),
        (
            ("evaluate.py", "models/cartpole", "--episodes", "0"),
            "argument --episodes: must be a positive integer, got 0",
        ),
        (("evaluate.py", "models/cartpole", "--policy", "p"), "argument --policy: invalid choice: 'p'"),
        (("train.py", "--task", "CartPole-v1"), "did you mean --env CartPole-v1?"),
        (("train.py", "--task", "cartpol"), "argument --task: invalid choice: 'cartpol'; did you mean cartpole?"),
        (
            ("train.py", "--task", "my_taskz:short-pole"),
            "argument --task: 'my_taskz:short-pole': no module named 'my_taskz' (is its directory on PYTHONPATH?)",
        ),
        (
            ("train.py", "--env", "my_envz:Maze-v0"),
            "argument --env: unknown task 'my_envz:Maze-v0': no module named 'my_envz' (is its directory on "
            "PYTHONPATH?)",
        ),
        (
            ("train.py", "--expert-loss", "my_methodz:HALF_CE", "--quick"),
            "expert_loss='my_methodz:HALF_CE': no module named 'my_methodz' (is its directory on PYTHONPATH?)",
        ),
        (
            ("train.py", "--env", "cartpol"),
            "Environment `cartpol` doesn't exist. Did you mean: `CartPole`?); did you mean --task cartpole?",
        ),
        (("train.py", "--steps", "0"), "argument --steps: must be a positive integer, got 0"),
        ((*LAB, "run", "nope", "--out", "x"), "argument suite: invalid choice: 'nope'"),
        (
            (*LAB, "efficiency", "--tasks", "cartpole,pong"),
            "argument --tasks: unknown task(s) ['pong']; expected among",
        ),
    ],
)
def test_argument_errors_are_one_line_before_tensorflow(args, message):
    done = Done(*args)
    assert done.code == 2 and done.stdout == "" and len(done.stderr) == 1, done.stderr
    assert message in done.stderr[0]
    assert_answered_without_tensorflow(done)


def test_a_task_name_not_a_preset_lists_the_presets():
    done = Done("evaluate.py", "models/cartpole", "--task", "pong")
    presets = ", ".join(repr(name) for name in sorted(TASKS))  # every preset the package registers
    assert done.code == 2 and done.stderr == [
        f"evaluate.py: error: argument --task: invalid choice: 'pong' (choose from {presets}; "
        "any Gymnasium env: --env ID)"
    ]
    assert "'cartpole', 'cartpole-200'" in presets and "'mountaincar-goals'" in presets


@pytest.mark.parametrize(
    "assignment, message",
    [
        ("sigma0=1", "error: --set 'sigma0=1': unknown Config field 'sigma0'; did you mean sigma0_sq?"),
        (
            "zzz=1",
            "error: --set 'zzz=1': unknown Config field 'zzz'; Config's fields are listed in "
            "dqfd_bc_keras/core/config.py",
        ),
    ],
)
def test_an_unknown_set_field_names_its_nearest_field(assignment, message):
    """From config.parse_assignments: TensorFlow-free once config.py no longer imports it."""
    done = Done("train.py", "--set", assignment, "--quick")
    assert (done.code, done.stderr) == (2, [message])
    assert_answered_without_tensorflow(done)


def test_expert_loss_takes_any_name_and_config_refuses_an_unknown_one():
    helped = Done("train.py", "--help")
    assert all(name in " ".join(helped.stdout.split()) for name in (" | ".join(METHODS), "MODULE:NAME"))
    done = Done("train.py", "--expert-loss", "magic", "--quick", "--out", "unused")
    assert done.code == 2 and len(done.stderr) == 1 and "expert_loss='magic'" in done.stderr[0], done.stderr
    assert not (REPO / "unused").exists()
    assert_answered_without_tensorflow(done)


def test_load_model_registers_the_custom_objects_first():
    model = dqfd_bc_keras.load_model(REPO / "models" / "cartpole" / "bc_model.keras")
    assert isinstance(model, dqfd_bc_keras.BCModel)
    with pytest.raises(ModelFileError, match="no such file"):
        dqfd_bc_keras.load_model(REPO / "models" / "nothing.keras")
    with pytest.raises(AttributeError, match="no attribute 'Nope'"):
        dqfd_bc_keras.Nope  # noqa: B018  (the attribute access is what raises)


def test_python_m_experts_still_runs_the_experts_command(tmp_path):
    done = command("-m", "dqfd_bc_keras.demos.experts", "--help", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("usage: python -m dqfd_bc_keras.demos.experts")
    assert "Evaluate the scripted experts on the plain envs." in done.stdout
