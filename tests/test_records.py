"""Files of today's format only: a record's every column, a run's every config field, a demonstration
file's every meta key. What an older version's file lacks is named in one line, with the way on."""

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from dqfd_bc_keras import demos
from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.errors import BrokenRunError, DemoFileError
from dqfd_bc_keras.runs import directory, resume
from dqfd_bc_keras.runs.writers import write_config
from dqfd_bc_keras.training.records import EpisodeRow, EvalRow, Losses

ROW = EpisodeRow(
    episode=3,
    env_step=60,
    interactions=75,
    return_=20.0,
    plain_return=19.5,
    length=20,
    goals=0,
    epsilon=0.5,
    losses=Losses(1.0, 0.5, 0.25, 0.125, 0.0625),
    demo_size=100,
    wall_time=1.5,
    imitation_weight_demo=2.0,
)


def as_csv_row(record: EpisodeRow) -> dict[str, str]:
    return {column: "" if value is None else str(value) for column, value in record.to_row().items()}


def test_a_row_round_trips_and_an_empty_cell_is_none_only_where_the_field_may_be_none():
    row = as_csv_row(ROW)
    assert row["imitation_weight_agent"] == "" and EpisodeRow.from_row(row) == ROW
    with pytest.raises(ValueError, match="^interactions has no value$"):
        EpisodeRow.from_row({**row, "interactions": ""})


def test_a_column_is_read_by_the_name_the_file_spells_it_nested_records_included():
    assert {column: ROW[column] for column in EpisodeRow.columns()} == ROW.to_row()
    assert ROW["return"] == 20.0 and ROW["td"] == 0.5 and ROW["imitation_weight_agent"] is None
    with pytest.raises(KeyError, match="^'return_'$"):  # the field's name is not a column
        ROW["return_"]


@pytest.mark.parametrize("column", EpisodeRow.columns())
def test_every_column_is_required(column):
    with pytest.raises(KeyError, match=f"^'{column}'$"):
        EpisodeRow.from_row({k: v for k, v in as_csv_row(ROW).items() if k != column})


def test_an_evaluation_row_has_no_optional_counts():
    assert EvalRow.columns() == ("env_step", "interactions", "episode", "mean_return", "std_return", "mean_goals")
    with pytest.raises(KeyError, match="std_return"):
        EvalRow.from_row({"env_step": 0, "interactions": 0, "episode": 0, "mean_return": 1.0, "mean_goals": None})


# --- a run directory to resume --------------------------------------------------------------------


def stopped_run(root: Path, config: Config) -> Path:
    """The files `saved_config` and a resume read before any training: config.json, its copy in
    the latest checkpoint, and latest.json naming it."""
    out = root / "run"
    (out / "checkpoints" / "ckpt-100").mkdir(parents=True)
    write_config(config, out)
    shutil.copy(out / "config.json", out / "checkpoints" / "ckpt-100" / "config.json")
    (out / "checkpoints" / "latest.json").write_text(json.dumps({"dir": "ckpt-100"}))
    return out


def test_a_run_of_today_resumes_with_its_own_config(tmp_path):
    config = Config.for_task("cartpole", expert_loss="ce", seed=4)
    assert resume.saved_config(stopped_run(tmp_path, config)) == config


def test_a_config_json_without_todays_fields_is_not_resumed(tmp_path):
    out = stopped_run(tmp_path, Config.for_task("cartpole"))
    fields = json.loads((out / "config.json").read_text())
    del fields["torso"], fields["uncertainty"]
    (out / "config.json").write_text(json.dumps(fields))
    message = (
        f"{out / 'config.json'}: cannot be resumed (ConfigError: no ['uncertainty', 'torso']: written by an "
        "older version? Read the run with that version, or train it again); start the run over with --force"
    )
    with pytest.raises(BrokenRunError, match=f"^{re.escape(message)}$"):
        resume.saved_config(out)


def test_a_checkpoint_without_its_config_copy_is_not_resumed(tmp_path):
    out = stopped_run(tmp_path, Config.for_task("cartpole"))
    (out / "checkpoints" / "ckpt-100" / "config.json").unlink()
    with pytest.raises(
        BrokenRunError, match=r"ckpt-100/config.json: cannot be resumed \(FileNotFoundError: .*--force$"
    ):
        resume.saved_config(out)


def test_a_run_with_demonstrations_but_no_kept_d_demo_is_not_resumed(tmp_path):
    """A resume starts from the demonstrations the run kept (checkpoints/demos_given.npz), never
    from a new recording: without them it is refused, the run left as it was."""
    out = stopped_run(tmp_path, Config.for_task("cartpole", expert_loss="bayes"))
    before = sorted(p.relative_to(out) for p in out.rglob("*"))
    with pytest.raises(BrokenRunError, match=r"demos_given.npz: no such file; the run cannot be resumed: .*--force$"):
        directory.train(Config.for_task("cartpole"), out, resume=True, quiet=True)
    assert sorted(p.relative_to(out) for p in out.rglob("*") if p.name != ".lock") == before


# --- demonstration files --------------------------------------------------------------------------


@pytest.mark.parametrize("keys", [("env_kwargs", "observation"), ("obs_shape",)])
def test_a_demonstration_file_without_todays_meta_keys_is_refused(tmp_path, keys):
    data = demos.record("cartpole", "imperfect", episodes=1, seed=0)
    demos.save(data, tmp_path / "today.npz")
    assert demos.load(tmp_path / "today.npz", task="cartpole").meta == data.meta
    with np.load(tmp_path / "today.npz") as contents:
        arrays = {key: contents[key] for key in contents.files}
    meta = {k: v for k, v in json.loads(str(arrays["meta"])).items() if k not in keys}
    np.savez(tmp_path / "old.npz", **{**arrays, "meta": np.array(json.dumps(meta))})
    message = (
        f"{tmp_path / 'old.npz'}: meta lacks {list(keys)}: written by an older version? Record the demonstrations "
        "again with this one"
    )
    with pytest.raises(DemoFileError, match=f"^{re.escape(message)}$"):
        demos.load(tmp_path / "old.npz")
