"""Suites as the lab reads them: run files parsed, the archive deterministic, bad input named."""

import csv
import io
import json
import re
import shutil
import tarfile
from pathlib import Path

import pytest

from dqfd_bc_keras.commands.cli import run
from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.experiments.__main__ import main
from dqfd_bc_keras.experiments.data import export_archive, lab_files, load_runs, open_suite

FIXTURE = Path(__file__).with_name("data") / "suite.tar.xz"
"""12 synthetic runs in 5 arms, built by tests/data/make_suite.py."""


@pytest.fixture
def suite(tmp_path) -> Path:
    """The fixture suite as a directory, with what a real suite holds besides: models, TensorBoard
    events, checkpoints, an incomplete run, the sample-efficiency benchmark's files."""
    with open_suite(FIXTURE) as directory:
        shutil.copytree(directory, tmp_path / "suite")
    root = tmp_path / "suite"
    run_dir = root / "cartpole-naive-bayes" / "seed0"
    for junk in ("q_network.keras", "tb/events.out", "checkpoints/latest.json", "demos.npz", "complete.json"):
        (run_dir / junk).parent.mkdir(parents=True, exist_ok=True)
        (run_dir / junk).write_text("not read by the report")
    (root / "cartpole-naive-bayes" / "seed9").mkdir()
    (root / "cartpole-naive-bayes" / "seed9" / "config.json").write_text("{}")  # running: no eval.json yet
    (root / "efficiency.json").write_text("{}")
    (root / "sb3-dqn" / "cartpole").mkdir(parents=True)
    (root / "sb3-dqn" / "cartpole" / "seed0.json").write_text("{}")
    return root


def test_runs_carry_their_demonstrations_updates_and_provenance(suite):
    runs = {(r.config.task, r.config.expert_loss, r.config.seed): r for r in load_runs(suite)}
    assert len(runs) == 12
    bayes = runs["cartpole", "bayes", 0]
    assert bayes.demonstrations.source == "recorded" and bayes.demonstrations.episodes == 5
    assert bayes.demo_transitions == bayes.demonstrations.transitions == sum(bayes.demonstrations.plain_returns)
    assert bayes.demonstrator_return == pytest.approx(bayes.demo_transitions / 5)  # a CartPole return is its length
    assert [(u.episode, u.new_transitions, u.mode) for u in bayes.dynamic_demos] == [
        (12, 1500, "episodes"),
        (20, 2500, "episodes"),
    ]
    assert bayes.provenance.code_commit.startswith("1f0c2a9") and not bayes.provenance.dirty
    assert runs["cartpole", "ce", 2].provenance.dirty
    plain = runs["cartpole", "none", 1]
    assert (plain.demonstrations, plain.demo_transitions, plain.demonstrator_return) == (None, 0, None)
    assert (plain.provenance.code_commit, plain.provenance.dirty, plain.dynamic_demos) == (None, None, [])
    first = bayes.metrics[0]
    assert (first.episode, first.interactions, first.return_, first["return"]) == (1, first.env_step, 54.0, 54.0)
    assert bayes.column("return")[0] == 54.0 and bayes.evals[0].mean_goals is None  # an empty cell


def test_eval_json_parses_into_the_evaluation_that_wrote_it(suite):
    run_dir = suite / "mountaincar-goals-bootstrap-bayes" / "seed1"
    [run] = load_runs(run_dir)
    assert run.final.to_dict() == json.loads((run_dir / "eval.json").read_text())
    assert (run.final.mean_return, run.final.goals) == (-120.0, [1, 1, 1, 1])


def drop_csv_columns(path: Path, *columns: str) -> None:
    rows = list(csv.DictReader(io.StringIO(path.read_text())))
    with path.open("w", newline="") as file:
        writer = csv.DictWriter(file, [c for c in rows[0] if c not in columns], lineterminator="\n")
        writer.writeheader()
        writer.writerows({k: v for k, v in row.items() if k not in columns} for row in rows)


def drop_json_keys(path: Path, *keys: str) -> None:
    value = json.loads(path.read_text())
    strip = lambda fields: {k: v for k, v in fields.items() if k not in keys}
    path.write_text(json.dumps([strip(v) for v in value] if isinstance(value, list) else strip(value)))


OLDER = "written by an older version? Read the run with that version, or train it again"


@pytest.mark.parametrize(
    "name, older, lacks",
    [
        (
            "metrics.csv",
            lambda p: drop_csv_columns(p, "imitation_weight_demo", "imitation_weight_agent"),
            r"no column\(s\) \['imitation_weight_demo', 'imitation_weight_agent'\] in the header",
        ),
        (
            "metrics.csv",
            lambda p: drop_csv_columns(p, "interactions"),
            r"no column\(s\) \['interactions'\] in the header",
        ),
        (
            "evals.csv",
            lambda p: drop_csv_columns(p, "episode", "std_return"),
            r"no column\(s\) \['episode', 'std_return'\] in the header",
        ),
        ("demonstrations.json", lambda p: drop_json_keys(p, "source"), r"no \['source'\]"),
        (
            "dynamic_demos.json",
            lambda p: drop_json_keys(p, "interactions", "mode", "new_transitions"),
            r"no \['interactions', 'mode', 'new_transitions'\]",
        ),
        ("config.json", lambda p: drop_json_keys(p, "torso", "uncertainty"), r"no \['uncertainty', 'torso'\]"),
        ("provenance.json", lambda p: drop_json_keys(p, "dirty"), r"no \['dirty'\]"),
        ("demonstrations.json", Path.unlink, r"missing \(the run learns from demonstrations\)"),
    ],
    ids=["weights", "interactions", "eval-episode", "source", "update-counts", "config", "dirty", "no-summary"],
)
def test_a_run_file_of_an_older_format_is_refused_in_one_line(suite, name, older, lacks):
    """What a file of an older version lacks is not filled in: the run is named and left out, and
    export refuses it, in one line that says what is missing and what to do."""
    run_dir = suite / "cartpole-naive-bayes" / "seed0"
    older(run_dir / name)
    message = f"{run_dir / name}: {lacks}: {re.escape(OLDER)}$"
    with pytest.raises(ConfigError, match=message):
        load_runs(suite)
    skipped = []
    assert len(load_runs(suite, skipped)) == 11 and [str(e.file) for e in skipped] == [
        f"cartpole-naive-bayes/seed0/{name}"
    ]
    assert run(main, ["export", str(suite), "--out", str(suite / "x.tar.xz")]) == 2


def test_an_archive_reads_as_its_directory(suite, tmp_path):
    archive = tmp_path / "suite.tar.xz"
    export_archive(suite, archive)
    from_dir, from_archive = load_runs(suite), load_runs(archive)
    assert [r.path.relative_to(suite) for r in from_dir] == [r.path.relative_to(archive) for r in from_archive]
    for a, b in zip(from_dir, from_archive, strict=True):
        assert (a.config, a.metrics, a.evals, a.final, a.demonstrations, a.dynamic_demos, a.provenance) == (
            b.config,
            b.metrics,
            b.evals,
            b.final,
            b.demonstrations,
            b.dynamic_demos,
            b.provenance,
        )


def test_the_archive_holds_exactly_what_the_report_reads_and_is_deterministic(suite, tmp_path):
    first, second = tmp_path / "a.tar.xz", tmp_path / "b.tar.xz"
    names = export_archive(suite, first)
    (suite / "sweeps.jsonl").touch()  # a newer mtime changes nothing
    assert export_archive(suite, second) == names
    assert first.read_bytes() == second.read_bytes()
    assert names == sorted(names) == lab_files(suite)
    assert {"sweeps.jsonl", "efficiency.json", "sb3-dqn/cartpole/seed0.json"} <= set(names)
    run_files = {n.rsplit("/", 1)[1] for n in names if n.count("/") == 2 and not n.startswith("sb3-dqn")}
    assert run_files == {
        "config.json",
        "metrics.csv",
        "evals.csv",
        "eval.json",
        "demonstrations.json",
        "dynamic_demos.json",
        "provenance.json",
    }
    assert not any("seed9" in n or "tb/" in n or "checkpoints" in n or n.endswith((".keras", ".npz")) for n in names)
    with tarfile.open(first) as tar:
        members = tar.getmembers()
    assert [m.name for m in members] == names
    assert {(m.mtime, m.uid, m.gid, m.uname, m.gname, m.mode) for m in members} == {(0, 0, 0, "", "", 0o644)}


def test_a_run_still_finishing_is_left_out_until_it_is_complete(suite, tmp_path):
    """A sweep in progress is read and exported as it runs (the MinAtar study exports after every run):
    a run that has written eval.json but not yet its last files (complete.json comes last) is not
    read, named as unfinished, and left out of the archive; once complete, it is in."""
    run_dir = suite / "cartpole-naive-bayes" / "seed0"
    (run_dir / "complete.json").unlink()
    (run_dir / "provenance.json").unlink()  # not written yet
    skipped = []
    assert len(load_runs(suite, skipped)) == 11
    assert [str(e.file) for e in skipped] == ["cartpole-naive-bayes/seed0/eval.json"]
    assert "has not finished" in skipped[0].problem
    assert not any(n.startswith("cartpole-naive-bayes/seed0/") for n in export_archive(suite, tmp_path / "a.tar.xz"))
    (run_dir / "provenance.json").write_text((suite / "cartpole-naive-bayes" / "seed1" / "provenance.json").read_text())
    (run_dir / "complete.json").write_text("{}")
    assert len(load_runs(suite)) == 12
    assert "cartpole-naive-bayes/seed0/provenance.json" in export_archive(suite, tmp_path / "b.tar.xz")


def test_export_on_the_command_line(suite, tmp_path, capsys):
    assert run(main, ["export", str(suite), "--out", str(tmp_path / "out.tar.xz")]) == 0
    assert capsys.readouterr().out == f"wrote {tmp_path / 'out.tar.xz'}: {len(lab_files(suite))} files\n"
    (suite / "cartpole-naive-ce" / "seed1" / "evals.csv").unlink()
    assert run(main, ["export", str(suite), "--out", str(tmp_path / "bad.tar.xz")]) == 2
    assert capsys.readouterr().err == (
        f"error: {suite}/cartpole-naive-ce/seed1/evals.csv: missing (the run has eval.json, so it should be complete)\n"
    )
    assert not (tmp_path / "bad.tar.xz").exists()
    assert run(main, ["export", str(tmp_path / "nothing"), "--out", str(tmp_path / "x.tar.xz")]) == 2
    assert "nothing: no such suite directory or archive" in capsys.readouterr().err


def truncate(path: Path, keep: int) -> None:
    path.write_bytes(path.read_bytes()[:keep])


@pytest.mark.parametrize(
    "damage, problem",
    [
        (lambda p: truncate(p, len(p.read_bytes()) - 7), r"ends in the middle of a line \(truncated\?\)"),
        (
            lambda p: p.write_text(p.read_text().rsplit(",", 3)[0] + "\n"),
            r"line 46 has 14 of 17 fields \(truncated\?\)",
        ),
        (lambda p: p.write_text(p.read_text().replace("\n2,", "\n2x,", 1)), "line 3: could not convert string .* '2x'"),
        (
            lambda p: p.write_text("episode,return\n1,2\n"),
            r"no column\(s\) \['env_step', 'interactions', 'plain_return'",
        ),
        (lambda p: p.write_text(""), r"no column\(s\)"),
        (lambda p: p.write_text(p.read_text().splitlines()[0] + "\n"), "no episodes"),
        (lambda p: p.write_bytes(b"\xff\xfe\x00garbage"), "not UTF-8 text"),
    ],
)
def test_a_damaged_metrics_csv_is_named(suite, damage, problem):
    metrics = suite / "cartpole-naive-ce" / "seed1" / "metrics.csv"
    damage(metrics)
    with pytest.raises(ConfigError, match=rf"^{re.escape(str(metrics))}: {problem}"):
        load_runs(suite)
    skipped = []
    assert len(load_runs(suite, skipped)) == 11
    assert [str(e.file) for e in skipped] == ["cartpole-naive-ce/seed1/metrics.csv"]


@pytest.mark.parametrize(
    "name, content, problem",
    [
        ("config.json", '{"task": "cartpole", "colour": "red"}', r"unknown config field\(s\) \['colour'\]"),
        ("config.json", "[1, 2]", "expected a JSON object"),
        ("eval.json", '{"task": "cartpole"', "not valid JSON"),
        ("eval.json", '{"task": "cartpole"}', r"no \['policy', 'seed', 'returns', 'lengths', 'timeout'\]"),
        ("demonstrations.json", '{"episodes": 5}', r"no \['transitions', 'expert', 'episode_returns'"),
        ("dynamic_demos.json", "{}", "expected a JSON array"),
    ],
)
def test_a_damaged_json_file_is_named(suite, name, content, problem):
    (suite / "cartpole-naive-ce" / "seed1" / name).write_text(content)
    with pytest.raises(ConfigError, match=rf"cartpole-naive-ce/seed1/{name}: {problem}"):
        load_runs(suite)


def test_what_is_not_a_suite_is_named(tmp_path):
    with pytest.raises(ConfigError, match="missing: no such suite directory or archive"):
        load_runs(tmp_path / "missing")
    (tmp_path / "notes.txt").write_text("hello")
    with pytest.raises(ConfigError, match=r"notes.txt: not a suite directory or a readable .tar.xz archive"):
        load_runs(tmp_path / "notes.txt")
    cut = tmp_path / "cut.tar.xz"
    cut.write_bytes(FIXTURE.read_bytes()[:2000])
    with pytest.raises(ConfigError, match=r"cut.tar.xz: not a suite directory or a readable"):
        load_runs(cut)


def test_an_archive_member_outside_the_suite_is_refused(tmp_path):
    with tarfile.open(tmp_path / "evil.tar.xz", "w:xz") as tar:
        info = tarfile.TarInfo("../outside.json")
        info.size = 2
        tar.addfile(info, io.BytesIO(b"{}"))
    with pytest.raises(ConfigError, match=r"member '../outside.json' points outside the suite"):
        load_runs(tmp_path / "evil.tar.xz")
    assert not (tmp_path / "outside.json").exists()


def test_a_run_directory_is_a_suite_of_one(suite):
    [run_] = load_runs(suite / "mountaincar-goals-bootstrap-ce" / "seed1")
    assert (run_.config.task, run_.config.seed, run_.final.task) == ("mountaincar-goals", 1, "mountaincar-goals")
