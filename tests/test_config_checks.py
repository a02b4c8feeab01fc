"""Every Config field's type and range is checked wherever a Config is made, from any source: a
user's `DQfD(...)` keywords, `train.py --set`/`--env-kwargs`, and a run's config.json and state.json
read back by `train.py --resume`. Each refusal is one line naming the field (and the file), what
it got and what it takes; nothing is written and no run is changed. Seeds lie in [0, 2³¹ − 1] (the
largest trains) and every float is finite, wherever given (`demos record --seed` too); a budget too
small to learn is refused, or warned about."""

import dataclasses
import json
import math
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from helpers import (
    DEMOS,
    REPO,
    assert_refused,
    assert_without_tensorflow,
    call,
    command,
    latest_checkpoint,
    left_in,
    one_line,
    tree,
)

from dqfd_bc_keras import DQfD
from dqfd_bc_keras.commands import cli
from dqfd_bc_keras.commands.evaluate import main as evaluate_main
from dqfd_bc_keras.commands.train import main as train_main
from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.errors import BrokenRunError, ConfigError

WORDS = {
    "int": "an integer",
    "float": "a finite number",
    "bool": "True or False",
    "str": "a string",
    "int | None": "an integer or None",
    "float | None": "a finite number or None",
    "tuple[int, ...]": "a list of integers",
    "dict[str, Any]": (
        "a JSON object of keyword arguments (string keys; values null, true, false, finite numbers, "
        "strings, lists, tuples or objects)"
    ),
}
"""What a field of each annotation takes, as the refusal says it."""
WRONG = {
    "int": ["3", 3.0, 64.7, True, None, [3]],
    "float": ["0.5", True, None, math.nan, -math.inf, [0.5]],
    "bool": [1, 0, "true", None],
    "str": [5, None, [], b"bayes"],
    "int | None": ["3", 3.0, True, "none"],
    "float | None": ["0.5", False, math.nan],
    "tuple[int, ...]": [64, "64", [64.5], (64, True), [64, None]],
    "dict[str, Any]": [[], "{}", {"x": math.nan}, {"x": {"y": math.inf}}, {1: 2}, {"x": {1, 2}}, {"x": object()}],
}
"""Values of the wrong type for a field of each annotation (a bool is no number, 3.0 no integer)."""
FIELDS = {f.name: f.type for f in dataclasses.fields(Config)}


def made(field: str, value: object) -> object:
    """What a user's script makes with `field=value`: `DQfD(env, field=value)`, the task being the
        env argument, `expert_loss=None` DQfD's "the default" and `expert` any demonstrator (a function
    too), so those three through Config."""
    if field == "task":
        return Config.for_task(value)
    if field == "expert":  # DQfD's expert= is a demonstrator of any kind, checked by the API itself
        return Config.for_task("cartpole", expert=value)
    if field == "expert_loss" and value is None:
        return Config.for_task("cartpole", expert_loss=None)
    return DQfD("cartpole", **{field: value})


@pytest.mark.parametrize("field", FIELDS)
def test_every_field_refuses_a_value_of_another_type_in_one_line_naming_it(field):
    for value in WRONG[FIELDS[field]]:
        with pytest.raises(ConfigError) as refused:
            made(field, value)
        assert str(refused.value) == f"{field} must be {WORDS[FIELDS[field]]}, got {value!r}"


def test_a_value_of_the_right_kind_is_held_as_its_field_types_it():
    """numpy integers (a sweep's `np.arange`) are integers, an int is a number and a list a tuple:
    each held as the plain Python value, so the config.json written is JSON and reads back equal."""
    config = DQfD(
        "cartpole", batch_size=np.int64(32), seed=np.int32(3), gamma=1, hidden=[32, 16], learning_rate=np.float32(0.5)
    ).config
    held = (config.batch_size, config.seed, config.gamma, config.hidden, config.learning_rate)
    assert held == (32, 3, 1.0, (32, 16), 0.5)
    assert [type(value) for value in held] == [int, int, float, tuple, float]
    written = json.dumps(config.to_dict(), allow_nan=False)
    assert Config.from_dict(json.loads(written)) == config


@pytest.mark.parametrize(
    "assignment, message",
    [
        ("lambda_n=-1", "lambda_n must be ≥ 0, got -1.0"),
        ("lambda_expert=-0.5", "lambda_expert must be ≥ 0, got -0.5"),
        ("lambda_l2=-1e-5", "lambda_l2 must be ≥ 0, got -1e-05"),
        ("margin=-0.8", "margin must be ≥ 0, got -0.8"),
        ("bc_epochs=-1", "bc_epochs must be ≥ 1 (the first fit of the BC model), got -1"),
        ("bc_epochs=0", "bc_epochs must be ≥ 1 (the first fit of the BC model), got 0"),
        ("early_stop_fraction=5", "early_stop_fraction must be in (0, 1] (of the episode limit), got 5.0"),
        ("early_stop_fraction=0", "early_stop_fraction must be in (0, 1] (of the episode limit), got 0.0"),
        ("beta_anneal_steps=0", "beta_anneal_steps must be ≥ 1, got 0"),
        ("batch_size=64.0", "--set batch_size='64.0': expected int"),
        ("batch_size=true", "--set batch_size='true': expected int"),
        ("hidden=64.5", "--set hidden='64.5': expected tuple[int, ...]"),
    ],
)
def test_set_refuses_values_out_of_range_or_of_another_type_and_writes_nothing(tmp_path, assignment, message):
    out = tmp_path / "run"
    done = call("train.py", "--quick", "--set", assignment, "--out", out)
    assert (done.returncode, done.stderr) == (2, f"error: {message}\n")
    assert not out.exists()


def test_the_ends_of_each_new_range_are_taken():
    config = DQfD(
        "cartpole",
        lambda_n=0.0,
        lambda_expert=0,
        lambda_l2=0.0,
        margin=0.0,
        bc_epochs=1,
        early_stop_fraction=1.0,
        beta_anneal_steps=1,
    ).config
    assert (config.lambda_expert, config.bc_epochs, config.early_stop_fraction, config.beta_anneal_steps) == (
        0.0,
        1,
        1.0,
        1,
    )


@pytest.mark.parametrize(
    "args, value",
    [
        (["--env-kwargs", "success_rate=NaN"], "{'success_rate': nan}"),
        (["--set", 'env_kwargs={"success_rate": Infinity}'], "{'success_rate': inf}"),
    ],
)
def test_env_kwargs_that_json_cannot_hold_are_refused_before_anything_is_written(tmp_path, args, value):
    """FrozenLake takes a float `success_rate`: the env is made with NaN, but no config.json gets
    the non-JSON token `NaN` (until 2026-12-06 it did, and the run trained)."""
    out = tmp_path / "run"
    done = call("train.py", "--env", "FrozenLake-v1", "--expert-loss", "none", "--quick", *args, "--out", out)
    assert (done.returncode, done.stderr) == (2, f"error: env_kwargs must be {WORDS['dict[str, Any]']}, got {value}\n")
    assert not out.exists()


# --- a run's files, edited, then resumed ------------------------------------------------------------


def edit(file: str, key: str | None, value: object) -> object:
    """Set `key` of the run's `file` (config.json, or its checkpoint's state.json) to `value`, written
    as Python's json writes it (NaN as the token NaN); with no key the whole file is `value`."""

    def apply(run: Path) -> Path:
        path = run / file if file == "config.json" else latest_checkpoint(run) / file
        path.write_text(json.dumps(value if key is None else {**json.loads(path.read_text()), key: value}))
        return path

    return apply


RESUMED = {
    "task 5": (edit("config.json", "task", 5), "task must be a string, got 5"),
    "expert_loss null": (edit("config.json", "expert_loss", None), "expert_loss must be a string, got None"),
    "expert_loss []": (edit("config.json", "expert_loss", []), "expert_loss must be a string, got []"),
    "hidden [64.5]": (edit("config.json", "hidden", [64.5]), "hidden must be a list of integers, got [64.5]"),
    "batch_size true": (edit("config.json", "batch_size", True), "batch_size must be an integer, got True"),
    "batch_size 64.0": (edit("config.json", "batch_size", 64.0), "batch_size must be an integer, got 64.0"),
    "gamma '0.9'": (edit("config.json", "gamma", "0.9"), "gamma must be a finite number, got '0.9'"),
    "max_steps 'none'": (edit("config.json", "max_steps", "none"), "max_steps must be an integer or None, got 'none'"),
    "lambda_n -1": (edit("config.json", "lambda_n", -1), "lambda_n must be ≥ 0, got -1.0"),
    "env_kwargs NaN": (
        edit("config.json", "env_kwargs", {"x": math.nan}),
        f"env_kwargs must be {WORDS['dict[str, Any]']}, got {{'x': nan}}",
    ),
    "config.json []": (edit("config.json", None, []), "expected a JSON object of config fields, got []"),
    "episode -5": (edit("state.json", "episode", -5), "episode must be an integer ≥ 0, got -5"),
    "episode 1.5": (edit("state.json", "episode", 1.5), "episode must be an integer ≥ 0, got 1.5"),
    "interactions '600'": (edit("state.json", "interactions", "600"), "interactions must be an integer ≥ 0, got '600'"),
    "returns [null]": (edit("state.json", "returns", [None]), "returns must be a list of finite numbers, got [None]"),
    "best_average NaN": (
        edit("state.json", "best_average", math.nan),
        "best_average must be a number (or -Infinity: no best yet), got nan",
    ),
    "stopped_early 0": (edit("state.json", "stopped_early", 0), "stopped_early must be true or false, got 0"),
    "metrics [{}]": (edit("state.json", "metrics", [{}]), "metrics: a row has no 'episode'"),
    "wall_time -1": (edit("state.json", "wall_time", -1.0), "wall_time must be a finite number ≥ 0, got -1.0"),
    "next_checkpoint null": (
        edit("state.json", "next_checkpoint", None),
        "next_checkpoint must be an integer ≥ 0, got None",
    ),
    "state.json []": (edit("state.json", None, []), "state.json must hold an object, got list"),
}
"""An edit of a finished run (`train.py --quick`) and what the refusal says of it."""


@pytest.mark.slow
@pytest.mark.parametrize("case", RESUMED)
def test_resuming_a_run_whose_files_hold_a_wrong_value_is_one_line_naming_file_and_key(quick_run, tmp_path, case):
    run = tmp_path / "run"
    shutil.copytree(quick_run().out, run)
    apply, problem = RESUMED[case]
    path = apply(run)
    before = tree(run)
    done = call("train.py", "--quiet", "--resume", "--out", run)
    said = (
        f"cannot be resumed (ConfigError: {problem}"
        if path.name == "config.json"
        else f"the checkpoint cannot be resumed (ValueError: {problem}"
    )
    assert done.returncode == 2 and re.fullmatch(
        rf"error: {re.escape(f'{path}: {said}')}.*\); start the run over with --force\n", done.stderr
    ), done.stderr
    assert tree(run) == before


@pytest.mark.slow
def test_loading_a_run_whose_state_json_is_impossible_names_it(quick_run, tmp_path):
    run = tmp_path / "run"
    shutil.copytree(quick_run().out, run)
    path = edit("state.json", "episode", -5)(run)
    with pytest.raises(BrokenRunError, match=re.escape(f"{path}: the checkpoint cannot be resumed (ValueError: ")):
        DQfD.load(run)


@pytest.mark.slow
def test_a_wrong_typed_field_of_a_checkpoints_state_is_one_line(finished, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(finished, run)
    state = latest_checkpoint(run) / "state.json"
    state.write_text(json.dumps({**json.loads(state.read_text()), "episode": "x"}))
    before = tree(run)
    one_line(
        capsys,
        cli.run(train_main, ["--quiet", "--resume", "--out", str(run)]),
        f"error: {state}: the checkpoint cannot be resumed (ValueError: episode must be an integer ≥ 0, got 'x'); "
        "start the run over with --force\n",
    )
    assert tree(run) == before


# --- values out of range, budgets too small -------------------------------------------------------


@pytest.mark.parametrize(
    "main, args, message",
    [
        (train_main, ["--seed", "-1"], "argument --seed: must be in [0, 2147483647], got -1"),
        (train_main, ["--seed", "99999999999999999999"], "got 99999999999999999999"),
        (train_main, ["--set", "seed=-3"], "seed must be in [0, 2147483647], got -3"),
        (train_main, ["--set", "learning_rate=inf"], "learning_rate must be a finite number, got inf"),
        (train_main, ["--set", "sigma0_sq=nan"], "sigma0_sq must be a finite number, got nan"),
        (evaluate_main, ["models/cartpole", "--seed", "-1"], "argument --seed: must be in [0, 2147483647], got -1"),
    ],
)
def test_out_of_range_values_are_one_line_and_write_nothing(tmp_path, capsys, monkeypatch, main, args, message):
    monkeypatch.chdir(REPO)
    out = tmp_path / "run"
    extra = ["--quick", "--out", str(out)] if main is train_main else []
    try:
        code = cli.run(main, [*args, *extra])
    except SystemExit as exit_:  # argparse exits itself
        code = exit_.code
    one_line(capsys, code, message)
    assert not out.exists()


@pytest.mark.parametrize("field", [f for f, v in Config.for_task("cartpole").to_dict().items() if isinstance(v, float)])
def test_every_float_field_must_be_finite(field):
    for value in (float("inf"), float("-inf"), float("nan")):
        with pytest.raises(ConfigError, match=f"{field} must be a finite number"):
            Config.for_task("cartpole", **{field: value})


@pytest.mark.slow
def test_the_largest_seed_runs(tmp_path):
    assert (
        cli.run(
            train_main, ["--quick", "--quiet", "--seed", "2147483647", "--steps", "100", "--out", str(tmp_path / "run")]
        )
        == 0
    )


def test_demos_record_refuses_a_negative_seed_in_one_line(tmp_path):
    done = command(
        *DEMOS, "record", "--task", "cartpole", "--expert", "strong", "--seed", "-1", "--out", tmp_path / "d.npz"
    )
    assert_refused(
        done, "python -m dqfd_bc_keras.demos record: error: argument --seed: must be in [0, 2147483647], got -1"
    )
    assert_without_tensorflow(done)
    assert left_in(tmp_path) == []


def test_budgets_too_small_to_learn_are_refused_or_warned():
    with pytest.raises(ConfigError, match="total_steps=10 is below batch_size=64: without demonstrations"):
        Config.for_task("cartpole", expert_loss="none", total_steps=10)
    with pytest.warns(UserWarning, match="the episode limit 1 is shorter than the n-step window n_step=10"):
        Config.for_task("cartpole", max_steps=1, demo_capacity=500)
