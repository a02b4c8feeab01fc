"""A `learn` stopped by an exception or Ctrl-C, as a user's callback (or the user) stops it: the model
keeps the step it reached, predicts from there, and the next `learn` goes on from it (into the same
run directory with `out=`, as `train.py --resume` would, never asking for command-line flags). Gone
on to the same budget, it is the run that was never stopped: the same episodes and evaluations."""

import json

import numpy as np
import pytest
from helpers import call
from test_python_api import TINY

from dqfd_bc_keras import DQfD
from dqfd_bc_keras.training.records import EpisodeRow, EvalRow

pytestmark = pytest.mark.slow

TINY = {**TINY, "checkpoint_every": 100}
BUDGET = 400


class MyBug(Exception):
    """A user's callback failing."""


STOPS = {
    "a callback's exception after its third episode": (EpisodeRow, 3, MyBug("my callback failed")),
    "Ctrl-C at the evaluation at 200 interactions, mid-episode": (EvalRow, 3, KeyboardInterrupt()),
}


def stopping(kind: type, n: int, error: BaseException):
    """A callback that raises `error` at the n-th row of `kind` it is given."""
    seen = []

    def callback(row):
        seen.append(row)
        if sum(isinstance(r, kind) for r in seen) == n:
            raise error

    return callback


def episodes(model: DQfD) -> list[dict]:
    """The model's episode rows as metrics.csv writes them, wall time aside."""
    return [
        {k: "" if v is None else str(v) for k, v in row.to_row().items() if k != "wall_time"}
        for row in model.state.metrics
    ]


@pytest.fixture(scope="module")
def whole() -> DQfD:
    """The run never stopped."""
    return DQfD("cartpole", seed=0, **TINY).learn(BUDGET)


def stop(model: DQfD, name: str) -> int:
    """`model.learn(BUDGET)` stopped as `name` says; the step it reached, checked to be usable."""
    kind, n, error = STOPS[name]
    with pytest.raises(type(error)):
        model.learn(BUDGET, callback=stopping(kind, n, error))
    reached = model.num_timesteps
    assert 0 < reached < BUDGET and model.state.metrics
    if kind is EvalRow:  # steps were taken after the last episode's row: it stopped in an episode
        assert model.state.metrics[-1].env_step < reached == model.state.evals[-1].env_step
    assert model.predict(np.zeros(4, np.float32))[0] in (0, 1)
    return reached


@pytest.mark.parametrize("name", STOPS)
def test_a_learn_stopped_goes_on_where_it_stopped(whole, name):
    model = DQfD("cartpole", seed=0, **TINY)
    reached = stop(model, name)
    assert model.config.total_steps == BUDGET
    model.learn()  # the rest of the budget
    assert model.num_timesteps == BUDGET > reached
    assert episodes(model) == episodes(whole) and model.state.evals == whole.state.evals


@pytest.mark.parametrize("name, saved", [(name, name == next(iter(STOPS))) for name in STOPS])
def test_a_learn_into_a_run_directory_stopped_goes_on_into_it(whole, name, saved, tmp_path):
    """With `saved`, the stopped model is saved into its own directory first: the run is complete
    at the step it reached (evaluate.py reads it), and still goes on to the budget."""
    run = tmp_path / "run"
    model = DQfD("cartpole", seed=0, out=run, **TINY)
    reached = stop(model, name)
    assert not (run / "complete.json").exists() and (run / "checkpoints" / "latest.json").is_file()
    if saved:
        assert model.save(run) == run
        assert json.loads((run / "complete.json").read_text())["env_steps"] == reached
        done = call("evaluate.py", run, "--episodes", "1", "--json")
        assert done.returncode == 0, done.stderr
        assert json.loads(done.stdout)["lengths"] == model.evaluate(1).lengths
    model.learn()  # into the same directory, not "pass --resume … or --force"
    assert model.num_timesteps == BUDGET and episodes(model) == episodes(whole)
    with open(run / "metrics.csv") as file:
        header, *lines = file.read().splitlines()
    columns = header.split(",")
    written = [{k: v for k, v in zip(columns, line.split(","), strict=True) if k != "wall_time"} for line in lines]
    assert written == episodes(whole)
    assert json.loads((run / "complete.json").read_text())["env_steps"] == BUDGET
    assert json.loads((run / "config.json").read_text())["total_steps"] == BUDGET
