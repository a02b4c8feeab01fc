"""The reliability probe of issue O: each test is a defect a user met, driven through the command the
user typed (`train.py`, `evaluate.py`, `python -m ...`), and checks what they see: the exit code, one
line naming what to change, and nothing written or damaged. A command runs as its own process
(`command`) where the process is what the test checks: its imports (an answer before TensorFlow), a
kill, two runners, a fresh process without a user's module; elsewhere it answers in this process
(`helpers.call`). The plug-in modules are docs/EXTENDING.md's, read by tests/test_extending.py.

Issue O's list, one section each: run directories and --force; the lab's sweeps and reports; Atari and
env ids; values and sizes checked before TensorFlow loads; users' plug-ins. A later round adds its own
section at the end, and uses the helpers below to run its commands.
"""

import ast
import errno
import io
import json
import os
import re
import shutil
import signal
import struct
import subprocess
import sys
import tarfile
import tempfile
import zipfile
from argparse import ArgumentTypeError
from collections.abc import Sequence
from pathlib import Path

import keras
import numpy as np
import pytest
import tensorflow as tf
from helpers import TINY_SWEEP, Answer, call
from test_cli import importers
from test_extending import recipe, write
from test_reliability import ENV, REPO, evaluate_main, one_line, train_main, tree

from dqfd_bc_keras.commands import cli
from dqfd_bc_keras.commands.cli import env_kwarg
from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.core.memory import machine_memory, memory_needed
from dqfd_bc_keras.demos import record, save
from dqfd_bc_keras.envs.make import checked_spaces, make_task
from dqfd_bc_keras.files import temporary_of
from dqfd_bc_keras.runs import directory as runs

NO_TENSORFLOW = 'raise ImportError("tensorflow is blocked by the test")\n'
"""A `tensorflow` package first on the path: a command that imports TensorFlow fails with this."""


def command(*args: object, cwd: Path = REPO, path: Sequence[str | Path] = (), block_tensorflow: bool = False) -> Answer:
    """`python -X importtime ARGS` run in `cwd` as a user types it: a first argument `NAME.py` is the
    repository's script; `path`, then the repository, on PYTHONPATH; with `block_tensorflow`, a
    `tensorflow` first on the path that cannot be imported (written to `cwd`/no_tensorflow)."""
    if block_tensorflow:
        blocker = cwd / "no_tensorflow"
        (blocker / "tensorflow").mkdir(parents=True, exist_ok=True)
        (blocker / "tensorflow" / "__init__.py").write_text(NO_TENSORFLOW)
        path = [blocker, *path]
    first, *rest = map(str, args)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(map(str, [*path, REPO]))}
    done = subprocess.run(
        [sys.executable, "-X", "importtime", str(REPO / first) if first.endswith(".py") else first, *rest],
        capture_output=True,
        text=True,
        cwd=cwd,
        env=env,
        timeout=600,
    )
    lines = done.stderr.splitlines(keepends=True)
    timed = [line.split("|")[-1].rstrip("\n") for line in lines if line.startswith("import time:")]
    own = [
        line for line in lines if not line.startswith("import time:") and "A.L.E" not in line and "Stella" not in line
    ]
    return Answer(done.returncode, done.stdout, "".join(own), timed[1:])  # timed[0] is importtime's header


def assert_refused(done: Answer, message: str) -> None:
    """Exit code 2, nothing on stdout, and `message` as the one line on stderr."""
    assert (done.returncode, done.stdout, done.stderr) == (2, "", message + "\n"), done.stderr


def assert_without_tensorflow(done: Answer) -> None:
    """The command answered before TensorFlow: importtime timed its imports, and none was TensorFlow."""
    assert done.imports, "importtime timed no import"
    assert "tensorflow" not in [name.strip() for name in done.imports], (
        f"TensorFlow imported by {importers(done.imports, 'tensorflow')}"
    )


def left_in(directory: Path) -> list[str]:
    """What `directory` holds, by name, besides the test's TensorFlow blocker and Python's bytecode cache."""
    return sorted({p.name for p in directory.iterdir()} - {"no_tensorflow", "__pycache__"})


# --- run directories ---
# What --force may replace, a run stopped before its first checkpoint, full disks while writing
# TensorBoard events and the final files, and --out values that cannot work.

TINY_RUN = ["--quick", "--quiet", "--set", "total_steps=300", "--set", "pretrain_steps=10"]
"""A run of a few seconds: one checkpoint after ckpt-0, one evaluation."""


@pytest.fixture
def finished(quick_run) -> Path:
    """The session's finished quick run (read-only: a test copies it before it changes it)."""
    return quick_run().out


def _checkpoint(run: Path) -> Path:
    return run / "checkpoints" / json.loads((run / "checkpoints" / "latest.json").read_text())["dir"]


# item 1: --force replaces only a run, and only what the run wrote


@pytest.mark.parametrize("force", [True, False], ids=["force", "plain"])
def test_force_refuses_a_directory_that_is_not_a_run(tmp_path, capsys, force):
    out = tmp_path / "x"
    (out / "photos").mkdir(parents=True)
    (out / "photos" / "a.jpg").write_bytes(b"jpeg")
    (out / "thesis.tex").write_text("t")
    before = tree(out)
    err = one_line(
        capsys,
        cli.run(train_main, [*TINY_RUN, *(["--force"] if force else []), "--out", str(out)]),
        f"error: {out} is not a run directory (it holds photos, thesis.tex), and only a run is ever "
        "replaced; choose a new or empty --out",
    )
    assert "--force" not in err
    assert tree(out) == before and left_in(out) == ["photos", "thesis.tex"]


def test_force_replaces_a_run_but_keeps_a_file_the_user_put_in_it(finished, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(finished, run)
    (run / "notes.txt").write_text("my notes")
    (run / ".dqfd-tmp-4242-abcd1234-eval.json").write_text("{")  # a temporary a killed run left
    one_line(
        capsys,
        cli.run(train_main, [*TINY_RUN, "--out", str(run)]),
        f"error: {run} already holds a run; pass --resume to continue it or --force to replace it",
    )
    old_metrics = (run / "metrics.csv").read_bytes()
    assert cli.run(train_main, [*TINY_RUN, "--set", "seed=1", "--force", "--out", str(run)]) == 0
    assert (run / "notes.txt").read_text() == "my notes"
    assert not (run / ".dqfd-tmp-4242-abcd1234-eval.json").exists()
    assert json.loads((run / "config.json").read_text())["seed"] == 1 and (run / runs.COMPLETE).is_file()
    assert (run / "metrics.csv").read_bytes() != old_metrics


def test_an_empty_existing_directory_is_trained_into(tmp_path, capsys):
    out = tmp_path / "empty"
    out.mkdir()
    (out / ".lock").write_text("")  # what a released lock leaves: still empty
    assert cli.run(train_main, [*TINY_RUN, "--out", str(out)]) == 0
    assert capsys.readouterr().err == "" and (out / runs.COMPLETE).is_file()


# item 9: a run stopped between its config.json and its first checkpoint

KILL_AT_FIRST_CHECKPOINT = """
import os, signal, sys
from dqfd_bc_keras.commands import cli
from dqfd_bc_keras.commands.train import main
from dqfd_bc_keras.runs import directory as runs
runs.RunDirectory.save_checkpoint = lambda self: os.kill(os.getpid(), signal.SIGKILL)
sys.exit(cli.run(main, sys.argv[1:]))
"""


@pytest.fixture(scope="module")
def killed(tmp_path_factory) -> Path:
    """A run killed (SIGKILL) at its first checkpoint, given its demonstrations as a file."""
    root = tmp_path_factory.mktemp("killed")
    save(record("cartpole", "strong", 2), root / "demos.npz")
    out = root / "run"
    done = command(
        "-c",
        KILL_AT_FIRST_CHECKPOINT,
        *TINY_RUN,
        "--set",
        "learning_rate=0.002",
        "--demos",
        root / "demos.npz",
        "--out",
        out,
    )
    assert done.returncode == -signal.SIGKILL, done.stderr
    assert (out / "config.json").is_file() and not (out / "checkpoints" / "latest.json").exists()
    assert (out / "checkpoints" / runs.GIVEN_DEMOS).is_file()
    return out


@pytest.mark.parametrize("resume", [True, False], ids=["resume", "rerun"])
def test_a_run_killed_before_its_first_checkpoint_is_started_over(killed, tmp_path, capsys, resume):
    run = tmp_path / "run"
    shutil.copytree(killed, run)
    pid = (run / ".lock").read_text().strip()
    args = ["--quiet", "--resume"] if resume else [*TINY_RUN, "--set", "learning_rate=0.003"]
    assert cli.run(train_main, [*args, "--out", str(run)]) == 0
    assert capsys.readouterr().err.splitlines() == [
        f"warning: {run}: taking over the lock left by process {pid}, which is no longer running",
        f"warning: {run}: no checkpoint yet (the run was stopped before its first); starting it over",
    ]
    config = json.loads((run / "config.json").read_text())
    source = json.loads((run / "demonstrations.json").read_text())["source"]
    if resume:  # the run's own config and demonstrations
        assert (config["learning_rate"], config["total_steps"], source) == (0.002, 300, "file")
    else:  # a new run, as this command says
        assert (config["learning_rate"], source) == (0.003, "recorded")
    assert (run / runs.COMPLETE).is_file()


@pytest.mark.parametrize(
    "interrupt, name, code", [(KeyboardInterrupt, "Ctrl-C", 130), (cli.Terminated, "SIGTERM", 143)]
)
def test_an_interrupt_before_the_first_checkpoint_says_nothing_was_kept(
    tmp_path, capsys, monkeypatch, interrupt, name, code
):
    def interrupted(self):
        raise interrupt

    monkeypatch.setattr(runs.RunDirectory, "save_checkpoint", interrupted)
    out = tmp_path / "run"
    err = one_line(capsys, cli.run(train_main, [*TINY_RUN, "--out", str(out)]), "", expected_code=code)
    assert err == f"interrupted ({name}); {out}: nothing was kept (the run had not reached its first checkpoint)\n"
    assert not out.exists()


# item 5: a full disk while TensorBoard writes


def test_a_full_disk_writing_tensorboard_events_is_one_line_and_the_run_resumes(tmp_path, capsys, monkeypatch):
    out = tmp_path / "run"
    events = out / "tb" / "events.out.tfevents.1.vm.1.0.v2"
    real = tf.summary.scalar

    def full(name, data, step=None, description=None):
        if name.startswith("eval/"):  # the first evaluation, after the first checkpoint
            raise tf.errors.ResourceExhaustedError(
                None,
                None,
                f"{{{{function_node __wrapped__FlushSummaryWriter}}}} {events}; No space left on device"
                "\n\tFailed to flush 1 events [Op:FlushSummaryWriter]",
            )
        return real(name, data, step=step, description=description)

    monkeypatch.setattr(tf.summary, "scalar", full)
    one_line(
        capsys,
        cli.run(train_main, [*TINY_RUN, "--out", str(out)]),
        f"error: {out}/tb: cannot write the TensorBoard events (ResourceExhaustedError: {events}; No space left "
        "on device)\n",
    )
    monkeypatch.undo()
    assert (_checkpoint(out) / "state.json").is_file() and not (out / runs.COMPLETE).exists()
    assert cli.run(train_main, ["--quiet", "--resume", "--out", str(out)]) == 0
    assert (out / runs.COMPLETE).is_file()


# item 12: errors name the file the user knows


@pytest.mark.parametrize("name", ["q_network.keras", "eval.json", "provenance.json", runs.COMPLETE])
def test_a_full_disk_in_the_final_phase_names_the_file(finished, tmp_path, capsys, monkeypatch, name):
    """What `write` raises on a full disk names no file, and the writer writes a temporary one."""
    run = tmp_path / "run"
    shutil.copytree(finished, run)
    (run / runs.COMPLETE).unlink()  # cut off in its final phase: a resume finishes it
    real_text, real_save = Path.write_text, keras.Model.save

    def full(path):
        if temporary_of(Path(path).name) == name:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(Path, "write_text", lambda self, *a, **k: full(self) or real_text(self, *a, **k))
    monkeypatch.setattr(keras.Model, "save", lambda self, path, *a, **k: full(path) or real_save(self, path, *a, **k))
    one_line(
        capsys,
        cli.run(train_main, ["--quiet", "--resume", "--out", str(run)]),
        f"error: {run / name}: No space left on device\n",
    )
    assert not (run / runs.COMPLETE).exists()
    assert not [p for p in run.rglob(".*") if p.name != ".lock"]  # no temporary left


def test_evaluate_out_on_a_read_only_place_names_the_file_asked_for(tmp_path, capsys, monkeypatch):
    place = tmp_path / "ro"
    place.mkdir()
    mounted = not subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "ro,size=100k", "tmpfs", str(place)], capture_output=True
    ).returncode
    if not mounted:  # a real read-only mount needs root: what mkstemp raises there

        def read_only(prefix, suffix, dir):
            raise OSError(errno.EROFS, os.strerror(errno.EROFS), f"{dir}/{prefix}abcd1234{suffix}")

        monkeypatch.setattr(tempfile, "mkstemp", read_only)
    try:
        one_line(
            capsys,
            cli.run(
                evaluate_main, [str(REPO / "models" / "cartpole"), "--episodes", "1", "--out", str(place / "eval.json")]
            ),
            f"error: {place / 'eval.json'}: Read-only file system\n",
        )
    finally:
        if mounted:
            subprocess.run(["umount", str(place)], check=True)


# item 11: --out values that cannot work, a checkpoint's state of the wrong type


@pytest.mark.parametrize(
    "script, args, message",
    [
        ("train.py", ["--quick", "--out", ""], "error: --out must not be empty"),
        (
            "train.py",
            ["--quick", "--out", os.fsdecode(b"run\xff")],
            "error: --out b'run\\xff' is not a UTF-8 path, and TensorFlow writes only to those; choose another name",
        ),
        ("evaluate.py", ["models/cartpole", "--out", ""], "error: --out must not be empty"),
    ],
)
def test_an_out_that_cannot_work_is_refused_in_one_line_before_anything_is_written(tmp_path, script, args, message):
    work = tmp_path / "work"
    shutil.copytree(REPO / "models" / "cartpole", work / "models" / "cartpole")
    assert_refused(command(script, *args, cwd=work), message)
    assert left_in(work) == ["models"]  # no runs/, no run\xff


def test_a_checkpoint_without_a_variable_the_learner_has_is_one_line(finished, tmp_path, capsys):
    """As a checkpoint of an earlier version is (e.g. before the replay counted its unsettled rows):
    here one that holds only the Q-network."""
    import keras
    import tensorflow as tf

    run = tmp_path / "run"
    shutil.copytree(finished, run)
    prefix = _checkpoint(run) / "tf"
    for old in prefix.parent.glob("tf.*"):
        old.unlink()
    q_network = keras.saving.load_model(run / "q_network.keras")
    tf.train.Checkpoint(q_network=q_network).write(str(prefix))
    before = tree(run)
    code = cli.run(train_main, ["--quiet", "--resume", "--out", str(run)])
    error = capsys.readouterr().err
    assert code == 2 and error.count("\n") == 1, error
    assert error.startswith(f"error: {_checkpoint(run)}: the checkpoint cannot be resumed (")
    assert error.endswith("; start the run over with --force\n")
    assert tree(run) == before


def test_a_wrong_typed_field_of_a_checkpoints_state_is_one_line(finished, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(finished, run)
    state = _checkpoint(run) / "state.json"
    state.write_text(json.dumps({**json.loads(state.read_text()), "episode": "x"}))
    before = tree(run)
    one_line(
        capsys,
        cli.run(train_main, ["--quiet", "--resume", "--out", str(run)]),
        f"error: {state}: the checkpoint cannot be resumed (ValueError: episode must be an integer ≥ 0, got 'x'); "
        "start the run over with --force\n",
    )
    assert tree(run) == before


# --- the lab ---
# The lab's command line where it met its users: two runners on one `--out`, a report on arms of one
# seed, and a suite of one's own (`module:NAME`).

LAB = ("-m", "dqfd_bc_keras.experiments")
"""A run of seconds: what a test of the sweep needs is runs, not learning."""
DONE = re.compile(r"\[\d+/\d+\] (\S+) seed0: \d+ episodes, \d+ steps, eval ")


def test_two_runners_on_one_out_finish_each_run_once(tmp_path):
    """The second runner lists both runs as to do, then is held (SIGSTOP) while the first finishes
    them: when it goes on, it finds them complete and skips them, instead of resuming each and
    finishing it a second time (a second checkpoint, event file and complete.json)."""
    out = tmp_path / "suite"
    args = [sys.executable, *LAB, "run", "quick", "--seeds", "1", "--workers", "1", *TINY_SWEEP, "--out", str(out)]
    first = subprocess.Popen(args, cwd=REPO, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    second = subprocess.Popen(
        args, cwd=REPO, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True
    )  # its own process group: its workers stop with it
    try:
        listed = second.stdout.readline()
        os.killpg(second.pid, signal.SIGSTOP)
        first_out, first_err = first.communicate(timeout=300)
        written = {
            path: (path.read_bytes(), path.stat().st_ino)
            for path in out.glob("*/seed0/**/*")
            if path.is_file() and path.name != ".lock"
        }
    finally:
        os.killpg(second.pid, signal.SIGCONT)
    second_out, second_err = second.communicate(timeout=300)
    assert listed == "quick: 2 runs, 0 already complete, 2 to run on 1 local worker(s)\n", (listed, first_out)
    assert first.returncode == 0 and second.returncode == 0, (first_err, second_err)
    seeds = sorted(out.glob("*/seed0"))
    assert len(seeds) == 2 and all((run / "complete.json").is_file() for run in seeds)
    assert sorted(DONE.match(line)[1] for line in first_out.splitlines() if DONE.match(line)) == sorted(
        run.parent.name for run in seeds
    )
    skipped = [line for line in second_out.splitlines() if line.startswith("[")]
    assert len(skipped) == 2 and all(
        line.split(": ", 1)[1].startswith("skipped: another runner completed it (") for line in skipped
    ), second_out
    for run in seeds:
        assert len([p for p in (run / "checkpoints").iterdir() if p.is_dir()]) == 1
        assert len(list((run / "tb").glob("events.out.tfevents.*"))) == 1
    assert {
        path: (path.read_bytes(), path.stat().st_ino)
        for path in out.glob("*/seed0/**/*")
        if path.is_file() and path.name != ".lock"
    } == written  # not a file rewritten, even to the same bytes
    assert [json.loads(line)["runs"] for line in (out / "sweeps.jsonl").read_text().splitlines()] == [2, 2]


ONE_SEED = ("cartpole-bootstrap-bayes", "cartpole-bootstrap-ce", "cartpole-bootstrap-bayes-priorFalse")
"""C3's pair and an ablation of it: arms whose comparisons need two seeds."""


def test_a_report_on_arms_of_one_seed_says_they_have_too_few_and_is_written(tmp_path):
    suite = tmp_path / "suite"
    with tarfile.open(REPO / "docs" / "data" / "results.tar.xz") as archive:
        archive.extractall(
            suite, [m for m in archive if m.name.split("/")[0] in ONE_SEED and "/seed0/" in m.name], filter="data"
        )
    before = tree(suite)
    results = tmp_path / "report" / "RESULTS.md"
    done = call("dqfd_bc_keras.experiments", "report", suite, "--results", results)
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
    assert done.stdout.startswith(f"wrote {results}, ")
    text = results.read_text()
    assert "- C3 on cartpole/bootstrap: **inconclusive**: n = 1: too few seeds for a comparison.\n" in text
    assert (
        "| C3 | cartpole/bootstrap | with the time-limit bootstrap fix bayes and ce give the same average reward | "
        "n = 1: too few seeds for a comparison | — | — | 1, 1 · — | **inconclusive (n < 2)** |"
    ) in text
    assert (
        "| cartpole/bootstrap bayes | bayes_prior = False | 1, 1 | n = 1: too few seeds for a comparison | — | — | "
        "— | **inconclusive (n < 2)** |"
    ) in text
    assert tree(suite) == before


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


# --- Atari and env ids ---
# Atari through train.py and evaluate.py: evaluation's step limit counts the agent's steps as training's
# does, the RAM observation, plain DQN's missing D_demo, and `--env` given a class.

PONG = "ale_py:ALE/Pong-v5"
TINY_PONG = [
    "--quick",
    "--max-steps",
    "50",
    "--set",
    "total_steps=60",
    "--set",
    "eval_every=60",
    "--set",
    "eval_episodes=1",
    "--set",
    "final_eval_episodes=1",
    "--set",
    "pretrain_steps=4",
    "--set",
    "batch_size=4",
    "--set",
    "bc_epochs=1",
    "--set",
    "demo_episodes=1",
]
"""A run of a few seconds whose greedy episodes end at 50 agent steps: Pong cannot end a game in 50."""


def test_atari_evaluation_plays_max_steps_agent_steps_and_plain_dqn_needs_no_demo_capacity(tmp_path):
    # demo_capacity=10 is below the limit 50: sized D_demo only for a method with demonstrations.
    done = call(
        "train.py",
        "--env",
        PONG,
        "--expert-loss",
        "none",
        *TINY_PONG,
        "--set",
        "demo_capacity=10",
        "--out",
        tmp_path / "a",
    )
    assert done.returncode == 0, done.stderr
    result = json.loads((tmp_path / "a" / "eval.json").read_text())
    assert result["lengths"] == [50]  # not 50 emulator frames (about 12 agent steps)
    done = call("evaluate.py", tmp_path / "a", "--episodes", "2", "--max-steps", "30")
    assert done.returncode == 0, done.stderr
    assert "length 30.0 steps on average" in done.stdout


def test_a_method_with_demonstrations_still_needs_demo_capacity_for_an_episode(tmp_path):
    done = command("train.py", "--env", PONG, *TINY_PONG, "--set", "demo_capacity=10", "--out", tmp_path / "a")
    assert_refused(done, "error: demo_capacity must be ≥ the episode limit 50, got 10")
    assert not (tmp_path / "a").exists()


def test_atari_ram_trains_on_a_128_byte_vector_with_the_step_limit_in_agent_steps(tmp_path):
    (tmp_path / "ram_rules.py").write_text("def fire(obs):\n    return 1\n")
    done = call(
        "train.py",
        "--env",
        PONG,
        "--env-kwargs",
        'obs_type="ram"',
        "--expert",
        "ram_rules:fire",
        *TINY_PONG,
        "--out",
        tmp_path / "a",
        path=[tmp_path],
    )
    assert done.returncode == 0, done.stderr
    config = json.loads((tmp_path / "a" / "config.json").read_text())
    assert config["env_kwargs"] == {"obs_type": "ram"}
    assert config["observation"] == {
        "space": "Box(128,) uint8",
        "shape": [128],
        "features": 128,
        "flattened": False,
        "dropped": [],
        "frames": None,
    }
    assert json.loads((tmp_path / "a" / "eval.json").read_text())["lengths"] == [50]


def test_atari_ram_keeps_the_no_op_starts_and_the_frame_skip():
    env = make_task(PONG, max_steps=10, env_kwargs={"obs_type": "ram"})
    obs, info = env.reset(seed=0)
    assert obs.shape == (128,) and 1 <= info["noops"] <= 30
    for _ in range(10):
        obs, _, terminated, truncated, step_info = env.step(0)
    assert truncated and not terminated and obs.shape == (128,)
    assert step_info["episode_frame_number"] == info["noops"] + 4 * 10


@pytest.mark.parametrize(
    "kwargs, says",
    [
        (
            ['obs_type="ram"', "frame_stack=2"],
            "error: --env-kwargs frame_stack: not with obs_type='ram', which observes the console's 128 bytes, "
            "not frames",
        ),
        (
            ['obs_type="rgb"'],
            "error: --env-kwargs obs_type: expected 'grayscale' (the screen as frames) or 'ram' (the console's "
            "128 bytes), got 'rgb'",
        ),
    ],
)
def test_an_atari_observation_that_is_not_taken_is_one_line(tmp_path, kwargs, says):
    assert_refused(
        command("train.py", "--env", PONG, "--env-kwargs", *kwargs, "--quick", "--out", tmp_path / "a"), says
    )
    assert not (tmp_path / "a").exists()


@pytest.mark.parametrize(
    "registers, says",
    [
        (
            "",
            'register the class in myenv with gymnasium.register(id="MyEnvClass-v0", entry_point="myenv:MyEnvClass") '
            "and pass --env myenv:MyEnvClass-v0",
        ),
        (
            'gymnasium.register(id="MyEnv-v0", entry_point="myenv:MyEnvClass")\n',
            "myenv registers MyEnv-v0: pass --env myenv:MyEnv-v0",
        ),
    ],
)
def test_env_given_a_class_says_how_to_register_it_before_tensorflow_loads(tmp_path, registers, says):
    (tmp_path / "myenv.py").write_text(
        f"import gymnasium\n\n\nclass MyEnvClass(gymnasium.Env):\n    pass\n\n\n{registers}"
    )
    done = command("train.py", "--env", "myenv:MyEnvClass", "--quick", "--out", tmp_path / "a", path=[tmp_path])
    assert_refused(
        done,
        "train.py: error: argument --env: myenv:MyEnvClass is a class, not an env id: --env takes a "
        f"registered Gymnasium id; {says}",
    )
    assert_without_tensorflow(done)
    assert not (tmp_path / "a").exists()


# --- values and sizes ---
# Values and sizes a user gives, checked before TensorFlow loads: `--env-kwargs` values parsed as JSON,
# a Python literal or a word (never a silently truthy string), sizes that cannot fit in this machine's
# memory, demonstration files whose .npy headers lie, out-of-range seeds.

DEMOS = ("-m", "dqfd_bc_keras.demos")
GIB = 2**30


@pytest.mark.parametrize(
    "text, value",
    [
        ("is_slippery=False", False),
        ("is_slippery=false", False),
        ("flag=True", True),
        ("flag=true", True),
        ("seed=None", None),
        ("seed=null", None),
        ("n=3", 3),
        ("x=-1.5", -1.5),
        ("x=1e5", 100000.0),
        ("obs_type='ram'", "ram"),
        ('obs_type="ram"', "ram"),
        ("shape=(3, 4)", {"__tuple__": [3, 4]}),  # a tuple, as config.json records it (JSON has none)
        ("shape=[3, 4]", [3, 4]),
        ('config={"lanes_count": 3}', {"lanes_count": 3}),
        ("config={'size': (2, 2)}", {"size": {"__tuple__": [2, 2]}}),
        ("render_mode=rgb_array", "rgb_array"),
        ("obs_type=ram", "ram"),
        ("map_name=8x8", "8x8"),
        ("mode=human-ish", "human-ish"),
        ("path=maps/a.txt", "maps/a.txt"),
        (" key =ram", "ram"),
    ],
)
def test_env_kwargs_values_are_json_then_python_literals_then_words(text, value):
    key, parsed = env_kwarg(text)
    assert key == text.partition("=")[0].strip() and parsed == value and type(parsed) is type(value)


@pytest.mark.parametrize(
    "text, message",
    [
        (
            "config={bad json",
            "config={bad json is not valid JSON (Expecting property name enclosed in double quotes: "
            "line 1 column 2 (char 1))",
        ),
        ("lanes=[1, 2", "lanes=[1, 2 is not valid JSON (Expecting ',' delimiter"),
        ("shape=(3, 4", "shape=(3, 4 is not a valid Python literal (SyntaxError: '(' was never closed"),
        ("name='ram", "name='ram is not a valid Python literal (SyntaxError: unterminated string literal"),
        (
            "is_slippery=FALSE",
            "is_slippery=FALSE is neither JSON nor Python: write is_slippery=false or "
            "is_slippery=False, or is_slippery='\"FALSE\"' for the string",
        ),
        ("seed=none", "seed=none is neither JSON nor Python: write seed=null or seed=None"),
        ("mission=go to the door", "mission=go to the door is neither JSON, a Python literal nor a word"),
        ("x=-fast", "x=-fast is neither JSON, a Python literal nor a word"),
        ("version=1.2.3", "version=1.2.3 is neither JSON, a Python literal nor a word"),
        ("x=", "x= is neither JSON, a Python literal nor a word"),
        ("ids={1, 2}", "ids={1, 2}: a Python set, which JSON cannot hold"),
        ("=3", "expected KEY=VALUE with KEY a Python identifier, got '=3'"),
    ],
)
def test_env_kwargs_refuses_a_value_it_would_otherwise_pass_on_as_a_string(text, message):
    with pytest.raises(ArgumentTypeError) as refused:
        env_kwarg(text)
    assert str(refused.value).startswith(message) and "\n" not in str(refused.value)


def test_is_slippery_false_reaches_the_env_and_config_json_as_false(tmp_path):
    out = tmp_path / "run"
    done = call(
        "train.py",
        "--env",
        "FrozenLake-v1",
        "--env-kwargs",
        "is_slippery=False",
        "--expert-loss",
        "none",
        "--quick",
        "--quiet",
        "--set",
        "total_steps=100",
        "--set",
        "eval_every=100",
        "--set",
        "batch_size=16",
        "--out",
        out,
    )
    assert done.returncode == 0, done.stderr
    assert json.loads((out / "config.json").read_text())["env_kwargs"] == {"is_slippery": False}
    assert '"is_slippery": false' in (out / "config.json").read_text()


def test_malformed_env_kwargs_json_is_one_line_before_tensorflow(tmp_path):
    done = command("train.py", "--env", "FrozenLake-v1", "--env-kwargs", "config={bad json", "--out", tmp_path / "run")
    assert_refused(
        done,
        "train.py: error: argument --env-kwargs: config={bad json is not valid JSON (Expecting "
        "property name enclosed in double quotes: line 1 column 2 (char 1)); a string that is not a "
        "word is written as JSON: config='\"...\"'",
    )
    assert_without_tensorflow(done)
    assert left_in(tmp_path) == []


def test_the_default_configs_need_far_less_memory_than_any_machine_has():
    for task in ("cartpole", "mountaincar"):
        config = Config.for_task(task)
        net_input = checked_spaces(config).network_input(config.torso, config.timeout)
        needed = sum(memory_needed(config, net_input, 3).values())
        assert 1 * 2**20 < needed < min(1 * 2**30, machine_memory() / 10)


@pytest.mark.parametrize(
    "setting, subject, lower, at_least",
    [
        # at_least: one part alone, from first principles. The replay's table: rows × (2·4 + 5 + 2) float32;
        (
            "replay_capacity=10000000000",
            r"the replay \(replay_capacity=10000000000, demo_capacity=5000\) and networks",
            r"replay_capacity \(or demo_capacity\)",
            (10**10 + 5000) * 15 * 4,
        ),
        # the Q-network's 10^10 weights, its target's and Adam's two moments;
        (
            "hidden=100000,100000",
            r"the networks \(hidden=100000,100000, bc_hidden=64,64\) and replay",
            r"hidden \(or bc_hidden\)",
            4 * 10**10 * 4,
        ),
        # one forward pass of 10^9 states through 4 + 64 + 64 + 2 units.
        (
            "batch_size=1000000000",
            r"the batches \(batch_size=1000000000\), replay and networks",
            "batch_size",
            10**9 * 134 * 4,
        ),
    ],
)
def test_sizes_that_cannot_fit_are_refused_before_tensorflow_with_what_they_need(
    tmp_path, setting, subject, lower, at_least
):
    done = command("train.py", "--quick", "--set", setting, "--out", tmp_path / "run")
    assert (done.returncode, done.stdout) == (2, ""), done.stderr
    said = re.fullmatch(
        rf"error: {subject} need ~([\d,.]+) GiB, more than the ([\d,.]+) GiB this machine has; "
        rf"lower {lower}\n",
        done.stderr,
    )  # one line
    assert said, done.stderr
    needed, has = (float(n.replace(",", "")) for n in said.groups())
    assert at_least / GIB <= needed <= 10 * at_least / GIB  # an honest order of magnitude
    assert abs(has - machine_memory() / GIB) <= 0.5
    assert_without_tensorflow(done)
    assert left_in(tmp_path) == []


@pytest.fixture(scope="module")
def demos_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("demos") / "demos.npz"
    save(record("cartpole", "strong", episodes=1, seed=0), path)
    return path


def forge(source, target, member: str, shape: tuple[int, ...], data: bytes):
    """`source` with `member`'s .npy header claiming `shape` over `data`."""
    with zipfile.ZipFile(source) as zin, zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as zout:
        for info in zin.infolist():
            content = zin.read(info)
            if info.filename == member:
                header = io.BytesIO()
                np.lib.format.write_array_header_1_0(header, {"descr": "<f4", "fortran_order": False, "shape": shape})
                content = header.getvalue() + data
            zout.writestr(info.filename, content)
    return target


@pytest.mark.parametrize("rows", [10**12, 10**7])
def test_a_header_claiming_rows_its_member_does_not_hold_is_named_not_allocated(demos_file, tmp_path, rows):
    forged = forge(demos_file, tmp_path / "forged.npz", "obs.npy", (rows, 4), bytes(64))
    assert forged.stat().st_size < 20_000
    expected = (
        f"error: {forged}: member obs.npy claims shape ({rows}, 4) of float32 ({rows * 16} bytes), "
        "but holds 64 bytes of data"
    )
    assert_refused(command(*DEMOS, "inspect", forged), expected)
    if rows == 10**12:  # train.py reads the file through the same load
        assert_refused(command("train.py", "--quick", "--demos", forged, "--out", tmp_path / "run"), expected)
        assert not (tmp_path / "run").exists()


def test_a_member_claiming_more_than_its_compression_can_give_is_refused(demos_file, tmp_path):
    """A zip whose central directory claims 160 MB of obs from 64 stored bytes (a zip bomb's shape)."""
    forged = forge(demos_file, tmp_path / "forged.npz", "obs.npy", (10**7, 4), bytes(64))
    content = bytearray(forged.read_bytes())
    with zipfile.ZipFile(forged) as archive:
        info = archive.getinfo("obs.npy")
    entry = content.index(b"PK\x01\x02")  # the central directory's entries, until obs.npy's
    while content[entry + 46 : entry + 46 + len(b"obs.npy")] != b"obs.npy":
        entry = content.index(b"PK\x01\x02", entry + 4)
    header_size = info.file_size - 64
    struct.pack_into("<I", content, entry + 24, 10**7 * 16 + header_size)  # its uncompressed size
    forged.write_bytes(bytes(content))
    assert_refused(
        command(*DEMOS, "inspect", forged),
        f"error: {forged}: member obs.npy claims {10**7 * 16 + header_size} bytes from "
        f"{info.compress_size} compressed, which its compression cannot give (a damaged file)",
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


# --- users' plug-ins ---
# A user's plug-ins (a demonstrator rule, a preset, a method) checked where the user meets them: a
# rule's failure is one line naming it and its file:line, before TensorFlow loads; a preset uses an
# expert it has; a run of a user's method evaluates without the method's module. And the package has
# no import cycle.

PACKAGE = REPO / "dqfd_bc_keras"

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


def import_graph() -> dict[str, set[str]]:
    """Each module of the package and the package modules it imports anywhere in its source
    (function bodies and `if __name__ == "__main__":` blocks included)."""
    modules = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(REPO).with_suffix("").parts
        modules[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    graph = {}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        edges = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                edges |= {alias.name for alias in node.names}
            elif isinstance(node, ast.ImportFrom):
                base = package.split(".")[: len(package.split(".")) - node.level + 1] if node.level else []
                source = ".".join([*base, *([node.module] if node.module else [])])
                for alias in node.names:
                    edges.add(f"{source}.{alias.name}" if f"{source}.{alias.name}" in modules else source)
        graph[name] = {edge for edge in edges if edge in modules} - {name}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Every cycle found by a depth-first search, each as the path that closes it."""
    found, state = [], {}

    def visit(module: str, path: list[str]) -> None:
        state[module] = "open"
        for child in sorted(graph[module]):
            if state.get(child) == "open":
                found.append([*path[path.index(child) :], child])
            elif child not in state:
                visit(child, [*path, child])
        state[module] = "done"

    for module in sorted(graph):
        if module not in state:
            visit(module, [module])
    return found


def test_the_import_graph_check_finds_a_cycle():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c", "a"]]
    graph = import_graph()
    assert "dqfd_bc_keras.demos.recording" in graph["dqfd_bc_keras.demos.experts"]  # relative imports are resolved
    assert "dqfd_bc_keras.commands.experts" in graph["dqfd_bc_keras.demos.experts"]  # the __main__ block counts


def test_the_package_has_no_import_cycle():
    assert cycles(import_graph()) == []


def test_python_m_experts_still_runs_the_experts_command(tmp_path):
    done = command("-m", "dqfd_bc_keras.demos.experts", "--help", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith("usage: python -m dqfd_bc_keras.demos.experts")
    assert "Evaluate the scripted experts on the plain envs." in done.stdout
