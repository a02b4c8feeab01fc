"""The Python API, `from dqfd_bc_keras import DQfD`, used as a user's script would use it: a preset,
env objects (a class of our own, a third party's made by gym.make), a callable expert, callbacks,
save → load → learn more, predict, and the same metrics as train.py."""

import csv
import json
import os
import re
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from helpers import call
from toy_envs import Chain

from dqfd_bc_keras import DQfD, demos
from dqfd_bc_keras.errors import ConfigError, DqfdWarning, OutputExistsError
from dqfd_bc_keras.evaluation import EvalResult, evaluate, load_policy
from dqfd_bc_keras.seeds import EVAL_SEED
from dqfd_bc_keras.training.records import EpisodeRow, EvalRow

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[1]
TINY = {
    "pretrain_steps": 10,
    "bc_epochs": 2,
    "bc_refit_epochs": 1,
    "demo_episodes": 2,
    "eval_every": 100,
    "eval_episodes": 2,
    "final_eval_episodes": 2,
    "replay_capacity": 2000,
    "demo_capacity": 5000,
}


def walk_right(obs):
    return 1


SAME_AS_TRAIN_PY = """
import json
import dqfd_bc_keras

dqfd_bc_keras.configure()  # docs/PYTHON.md: first, for train.py's numbers
from dqfd_bc_keras import DQfD
from dqfd_bc_keras.core.config import QUICK

model = DQfD("cartpole", seed=0, **{k: v for k, v in QUICK.items() if k != "total_steps"}).learn(QUICK["total_steps"])
rows = [row.to_row() for row in model.state.metrics]
print(json.dumps([{k: "" if v is None else str(v) for k, v in row.items() if k != "wall_time"} for row in rows]))
print(model.config.expert)
"""


def test_the_same_metrics_as_train_py(quick_run):
    """A user's script that calls `configure()` first, then DQfD(preset, seed, QUICK's fields).learn(N), in a
    process of its own with none of the settings made for it, gives train.py --quick's metrics.csv (seed 0,
    the default loss), wall time aside."""
    clean = {k: v for k, v in os.environ.items() if not k.startswith(("TF_", "DQFD_", "KERAS_"))}
    done = subprocess.run(
        [sys.executable, "-c", SAME_AS_TRAIN_PY],
        capture_output=True,
        text=True,
        cwd=REPO,
        env={**clean, "PYTHONPATH": str(REPO)},
        timeout=600,
    )
    assert done.returncode == 0, done.stderr
    printed, expert = done.stdout.splitlines()[-2:]
    run = quick_run().out
    with open(run / "metrics.csv") as file:
        expected = [{k: v for k, v in row.items() if k != "wall_time"} for row in csv.DictReader(file)]
    ours = json.loads(printed)
    assert ours == expected and len(ours) > 1
    assert json.loads((run / "config.json").read_text())["expert"] == expert == "imperfect"


def test_an_env_object_a_callable_expert_callbacks_save_load(tmp_path):
    """An env with no registered id, demonstrated by a Python function; a callback stops training;
    save warns once, evaluate.py's loader reads the run, load(env=...) learns more."""
    events = []

    def stop_at_second_episode(row):
        events.append(row)
        return sum(isinstance(r, EpisodeRow) for r in events) < 2

    model = DQfD(Chain(), walk_right, max_steps=20, seed=1, **TINY)
    model.learn(300, callback=stop_at_second_episode)
    assert [type(r) for r in events].count(EpisodeRow) == 2 and isinstance(events[0], EvalRow)
    assert model.learner.interactions < 300
    assert model.config.expert == "python callable walk_right"
    assert model.predict(np.eye(5, dtype=np.float32)[0])[0] in (0, 1)
    assert model.predict(np.eye(5, dtype=np.float32))[0].shape == (5,)

    with pytest.warns(DqfdWarning) as warned:
        model.save(tmp_path / "chain")
    ours = [w.message for w in warned if isinstance(w.message, DqfdWarning)]
    assert len(ours) == 1 and "python-Chain" in str(ours[0]) and "python callable walk_right" in str(ours[0])
    config = json.loads((tmp_path / "chain" / "config.json").read_text())
    summary = json.loads((tmp_path / "chain" / "demonstrations.json").read_text())
    assert config["expert"] == summary["expert"] == "python callable walk_right" and summary["source"] == "recorded"
    assert (tmp_path / "chain" / "complete.json").is_file()
    policy, settings = load_policy(tmp_path / "chain")  # what evaluate.py plays
    expected = evaluate(policy, settings.task, 3, EVAL_SEED, settings.timeout, settings.max_steps, settings.env_kwargs)
    assert model.evaluate(3) == expected

    again = DQfD.load(tmp_path / "chain", env=Chain())
    steps = int(again.learner.interaction.env_steps.numpy())
    again.learn(100)
    assert again.state.metrics[-1].env_step >= steps + 100 - 20
    assert isinstance(again.evaluate(2), EvalResult)


def test_a_third_party_env_instance_and_predict_on_what_it_gives():
    """gym.make's instance keeps its id and kwargs; predict takes its raw observations (Discrete states)."""
    env = gym.make("FrozenLake-v1", is_slippery=False)
    model = DQfD(env, lambda obs: 2, expert_loss="margin", **TINY).learn(200)
    assert model.config.task == "FrozenLake-v1" and model.config.env_kwargs == {"is_slippery": False}
    obs, _ = env.reset(seed=0)
    assert isinstance(model.predict(obs)[0], int)
    assert model.predict(np.array([0, 5, 14]))[0].shape == (3,)
    assert model.evaluate(2).task == "FrozenLake-v1"


def test_learn_goes_on_and_out_writes_a_run(tmp_path):
    """With out=, learn trains into a run directory as train.py does; a second learn goes on from it."""
    model = DQfD("cartpole", seed=0, out=tmp_path / "run", **TINY).learn(200)
    first = len(model.state.metrics)
    model.learn(200)
    assert model.config.total_steps == 400 and len(model.state.metrics) > first
    with open(tmp_path / "run" / "metrics.csv") as file:
        assert len(list(csv.DictReader(file))) == len(model.state.metrics)
    assert json.loads((tmp_path / "run" / "config.json").read_text())["total_steps"] == 400
    assert json.loads((tmp_path / "run" / "complete.json").read_text())["env_steps"] == 400


def test_nothing_is_written_unless_asked(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    DQfD("cartpole", **TINY).learn(100)
    assert list(tmp_path.iterdir()) == []


def test_a_bad_keyword_is_a_did_you_mean():
    with pytest.raises(ConfigError, match="unknown Config field 'sigma_sq'; did you mean sigma0_sq"):
        DQfD("cartpole", sigma_sq=1.0)


def test_an_env_without_a_demonstrator_is_refused_when_made_not_at_learn(tmp_path):
    """As train.py asks its demonstrator for one action before training: an env object with no
    scripted expert and no demos is refused by DQfD(...) itself, saying how to give them from
    Python (and which preset plays that env with scripted experts, if one does); demos of a type
    DQfD cannot read are refused by name, not ignored."""
    with pytest.raises(ConfigError, match=re.escape("has no scripted imperfect expert")) as refused:
        DQfD(Chain(), max_steps=20, out=tmp_path / "run", **TINY)
    assert "from Python: DQfD(env, demos)" in str(refused.value) and "preset" not in str(refused.value)
    with pytest.raises(ConfigError, match=re.escape("the presets cartpole, cartpole-200 play CartPole-v1 with")):
        DQfD(gym.make("CartPole-v1"), **TINY)  # a preset's own env, given as an object: the preset is named
    assert not (tmp_path / "run").exists()
    assert DQfD(Chain(), max_steps=20, expert_loss="none", **TINY).config.expert_loss == "none"  # DQN needs none
    with pytest.raises(ConfigError, match="demos is a DemoDataset, a .npz file, .* not list"):
        DQfD("cartpole", [np.zeros(4)], **TINY)


# --- demonstrations given every way the CLI takes them, and the same provenance ----------------------


def test_demonstrations_as_a_dataset_a_file_and_a_minari_id(tmp_path, monkeypatch):
    """A DemoDataset, its .npz and its Minari copy give the same D_demo; config.json names where it
    came from, as train.py --demos writes it, and demonstrations.json says which kind of source."""
    pytest.importorskip("minari")
    from dqfd_bc_keras.demos.minari_export import to_minari

    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "minari"))
    dataset = demos.record("CartPole-v1", "toy_envs:pole_rule", 2, seed=0)
    demos.save(dataset, tmp_path / "d.npz")
    to_minari(dataset, "cartpole/mine-v0")
    kinds = {"python": dataset, "file": str(tmp_path / "d.npz"), "minari": "minari:cartpole/mine-v0"}
    for source, given in kinds.items():
        model = DQfD("CartPole-v1", given, **TINY)
        assert np.array_equal(model.dataset.actions, dataset.actions), source
        model.learn(60).save(tmp_path / "runs" / source)
        summary = json.loads((tmp_path / "runs" / source / "demonstrations.json").read_text())
        config = json.loads((tmp_path / "runs" / source / "config.json").read_text())
        assert summary["source"] == source and config["expert"] == model.config.expert
    assert (
        DQfD("CartPole-v1", kinds["python"]).config.expert
        == "demonstrations from a Python DemoDataset (toy_envs:pole_rule)"
    )
    assert DQfD("CartPole-v1", kinds["minari"]).config.expert == "demonstrations from minari:cartpole/mine-v0"

    done = call(
        "train.py",
        "--env",
        "CartPole-v1",
        "--demos",
        tmp_path / "d.npz",
        "--quick",
        "--quiet",
        "--out",
        tmp_path / "cli",
    )
    assert done.returncode == 0, done.stderr
    cli = json.loads((tmp_path / "cli" / "config.json").read_text())["expert"]
    assert (
        cli
        == json.loads((tmp_path / "runs" / "file" / "config.json").read_text())["expert"]
        == f"demonstrations from {tmp_path / 'd.npz'} (toy_envs:pole_rule)"
    )


def test_train_py_refuses_demos_and_an_expert_together(tmp_path):
    done = subprocess.run(
        [sys.executable, "train.py", "--demos", tmp_path / "d.npz", "--expert", "strong", "--out", tmp_path / "run"],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2 and done.stderr.strip().splitlines() == [
        f"error: --demos {tmp_path / 'd.npz'} gives the demonstrations and --expert strong would record them: give one"
    ]
    assert not (tmp_path / "run").exists()


def test_demonstrators_by_name_and_by_saved_model():
    """A preset expert's name and a shipped .keras Q-network record demo_episodes episodes at learn."""
    for expert in ("strong", str(REPO / "models" / "cartpole" / "q_network.keras")):
        model = DQfD("cartpole", expert, **{**TINY, "demo_episodes": 1}).learn(50)
        assert model.config.expert == expert and int(model.learner.agent.replay.demo_size.numpy()) > 0


# --- envs: a factory, a gym.make with its own limit ----------------------------------------------------


def test_a_factory_env_and_a_gym_make_limit():
    no_limit = "no time limit of its own: set one with --max-steps N (from Python: DQfD(env, max_steps=N))"
    with pytest.raises(ConfigError, match=re.escape(no_limit)):
        DQfD(lambda: Chain(), walk_right, **TINY)
    model = DQfD(lambda: Chain(), walk_right, max_steps=15, **TINY).learn(100)
    assert model.config.task.startswith("dqfd_bc_keras/python-") and model.config.max_steps == 15
    assert max(model.evaluate(2).lengths) <= 15
    short = DQfD(gym.make("CartPole-v1", max_episode_steps=30), lambda obs: int(obs[3] > 0), **TINY)
    assert (short.config.task, short.config.max_steps) == ("CartPole-v1", 30)
    assert max(row.length for row in short.learn(100).state.metrics) <= 30  # training's limit; evaluation
    assert short.evaluate(1).lengths[0] > 30  # plays the plain CartPole-v1, 500 steps, as evaluate.py does


def test_progress_bar_and_the_default_budget(capsys, tmp_path):
    """tqdm.auto's bar (a widget in Jupyter, else text on stderr, a terminal or not), in memory and
    into a run directory, at every learn that asks for it, counting the budget of the run."""
    model = DQfD("cartpole", total_steps=120, **TINY).learn(progress_bar=True)
    assert model.num_timesteps == 120 and "120/120" in capsys.readouterr().err
    model.learn(60, progress_bar=True)
    assert "180/180" in capsys.readouterr().err
    into = DQfD("cartpole", out=tmp_path / "run", **TINY).learn(100, progress_bar=True)
    assert "100/100" in capsys.readouterr().err
    into.learn(50, progress_bar=True)
    assert "150/150" in capsys.readouterr().err
    into.learn(50)
    assert "200/200" not in capsys.readouterr().err
    with pytest.raises(ConfigError, match="total_timesteps=0"):
        model.learn(0)


def test_a_users_calls_show_no_numpy_deprecation_warning(tmp_path):
    """Keras 3 converts its variables with np.array(x), and NumPy 2 warns about the copy keyword at
    each conversion: silenced where the package makes Keras convert, so a user's learn, predict,
    evaluate, save and load show none, whatever their warning filters."""
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        model = DQfD("cartpole", out=tmp_path / "run", **TINY).learn(100)
        model.predict(np.zeros(4, np.float32))
        model.save(tmp_path / "copy")
        again = DQfD.load(tmp_path / "copy")
        again.predict(np.zeros(4, np.float32))
        again.learn(20).evaluate(1)
    assert [str(w.message) for w in seen if "copy keyword" in str(w.message)] == []


# --- a user's Method object -----------------------------------------------------------------------------

METHOD_MODULE = """
from dqfd_bc_keras.core import losses
from dqfd_bc_keras.core.methods import Method


def half_ce(agent, q, batch):
    j_e = losses.cross_entropy_loss(q, batch.pi_bc, agent.config.temperature)
    return 0.5 * losses.weighted_mean(j_e, batch.weights)


HALF_CE = Method("half_ce", "half of DQfD-BC's cross-entropy", bc_fit="mle", term=half_ce, reads=("temperature",))
"""


def test_a_method_object_from_a_users_module_is_saved_as_module_name(tmp_path, monkeypatch):
    (tmp_path / "my_api_methods.py").write_text(METHOD_MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    import my_api_methods

    model = DQfD("cartpole", expert_loss=my_api_methods.HALF_CE, **TINY).learn(60)
    assert model.config.expert_loss == "my_api_methods:HALF_CE"
    with warnings.catch_warnings():
        warnings.simplefilter("error", DqfdWarning)  # nothing is lost: the module can be imported again
        model.save(tmp_path / "run")
    assert DQfD.load(tmp_path / "run").learn(20).config.expert_loss == "my_api_methods:HALF_CE"


def test_a_method_made_in_the_script_is_registered_and_said_at_save(tmp_path):
    from dqfd_bc_keras.core.methods import Method

    method = Method(
        "script_margin", "a margin of our own", term="dqfd_bc_keras.core.expert_terms:margin", reads=("margin",)
    )
    model = DQfD("cartpole", expert_loss=method, **TINY).learn(60)
    assert model.config.expert_loss == "script_margin"
    with pytest.warns(DqfdWarning, match="the method 'script_margin' \\(registered in this process"):
        model.save(tmp_path / "run")
    script = (  # a new process, where the method is not registered: learning more, then dqfd-evaluate
        f"import sys\n"
        f"from dqfd_bc_keras import DQfD\n"
        f"from dqfd_bc_keras.commands import cli, evaluate\n"
        f"try:\n    DQfD.load({str(tmp_path / 'run')!r}).learn(10)\n"
        f"except Exception as error:\n    print(type(error).__name__, error, flush=True)\n"
        f"sys.exit(cli.run(evaluate.main, [{str(tmp_path / 'run')!r}, '--episodes', '2']))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script],
        capture_output=True,
        text=True,
        timeout=300,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )
    assert "ConfigError expert_loss='script_margin' is not one of" in done.stdout, done.stderr
    assert "registered again with dqfd_bc_keras.core.methods.register" in done.stdout
    assert done.returncode == 0 and "2 greedy episodes" in done.stdout, done.stderr  # evaluating needs no method


# --- load, and a learn-more stopped halfway ----------------------------------------------------------


class ThreeActions(Chain):
    """Chain with a third action (it stays where it is)."""

    def __init__(self) -> None:
        super().__init__()
        self.action_space = gym.spaces.Discrete(3)


def test_load_refuses_an_env_that_does_not_fit_the_run(tmp_path):
    """Another observation size, another number of actions: one line naming both, the run untouched;
    the env it was trained on loads."""
    model = DQfD(Chain(), walk_right, max_steps=20, **TINY).learn(100)
    with pytest.warns(DqfdWarning):
        model.save(tmp_path / "chain")
    files = {p: p.read_bytes() for p in (tmp_path / "chain").rglob("*") if p.is_file()}
    loading = f"DQfD.load({str(tmp_path / 'chain')!r}, env=...): "
    with pytest.raises(ConfigError) as refused:
        DQfD.load(tmp_path / "chain", env=Chain(size=7))
    assert str(refused.value) == (
        loading + "the run was trained on observations Box(5,) float32 (5 features), and the env given "
        "observes Box(7,) float32 (7 features): give the env it was trained on"
    )
    with pytest.raises(
        ConfigError,
        match="^"
        + re.escape(loading + "the env given (Box(5,) float32, 3 actions) does not fit the networks the run trained ("),
    ):
        DQfD.load(tmp_path / "chain", env=ThreeActions())
    assert files == {p: p.read_bytes() for p in (tmp_path / "chain").rglob("*") if p.is_file()}
    again = DQfD.load(tmp_path / "chain", env=Chain())
    assert again.predict(np.eye(5, dtype=np.float32)[0]) == model.predict(np.eye(5, dtype=np.float32)[0])


def test_load_with_resume_goes_on_into_the_directory_as_train_py_resume(tmp_path):
    """A run stopped halfway (Ctrl-C): DQfD.load(run, resume=True).learn() finishes it in place, as
    train.py --resume does a copy of it; DQfD.load(run) without resume never writes to it."""
    run = tmp_path / "run"

    def ctrl_c_at_the_third_episode(row):
        if isinstance(row, EpisodeRow) and row.episode == 3:
            raise KeyboardInterrupt

    stopped = DQfD("cartpole", seed=0, out=run, **{**TINY, "checkpoint_every": 100})
    with pytest.raises(KeyboardInterrupt):
        stopped.learn(400, callback=ctrl_c_at_the_third_episode)
    shutil.copytree(run, tmp_path / "cli")
    files = {p: p.read_bytes() for p in run.rglob("*") if p.is_file()}
    with pytest.raises(OutputExistsError) as refused:  # a new model into it: the way to continue it is named
        DQfD("cartpole", seed=0, out=run, **TINY).learn(10)
    assert str(refused.value) == (
        f"{run} already holds a run: DQfD.load({str(run)!r}, resume=True) continues it; "
        "choose another out= for a new one"
    )
    DQfD.load(run).learn(50)
    assert files == {p: p.read_bytes() for p in run.rglob("*") if p.is_file()}

    resumed = DQfD.load(run, resume=True)
    assert resumed.num_timesteps < 400 and resumed.config.total_steps == 400
    resumed.learn()  # the rest of the run's budget, as --resume
    done = call("train.py", "--resume", "--quiet", "--out", tmp_path / "cli")
    assert done.returncode == 0, done.stderr

    def metrics(directory):
        with open(directory / "metrics.csv") as file:
            return [{k: v for k, v in row.items() if k != "wall_time"} for row in csv.DictReader(file)]

    assert metrics(run) == metrics(tmp_path / "cli") and len(metrics(run)) == len(resumed.state.metrics)
    for directory in (run, tmp_path / "cli"):
        assert json.loads((directory / "complete.json").read_text())["env_steps"] == 400


def test_load_refuses_what_is_not_a_run(tmp_path):
    from dqfd_bc_keras.errors import RunDirectoryError

    (tmp_path / "notes.txt").write_text("mine")
    for path, why in (
        (tmp_path, "is not a run directory"),
        (tmp_path / "missing", "does not exist"),
        (tmp_path / "notes.txt", "is not a directory"),
    ):
        with pytest.raises(RunDirectoryError, match=f"^{path} {why}: DQfD.load reads a run directory"):
            DQfD.load(path)
    assert (tmp_path / "notes.txt").read_text() == "mine"


def test_a_learn_more_stopped_before_config_json_resumes_with_train_py(tmp_path, monkeypatch):
    """continue_run checkpoints the new budget, then rewrites config.json: stopped between the two,
    train.py --resume takes the checkpoint's budget (it refused the run before)."""
    from dqfd_bc_keras.runs import directory as runs

    model = DQfD("cartpole", seed=0, out=tmp_path / "run", **TINY).learn(150)

    def stopped(*args):
        raise KeyboardInterrupt

    monkeypatch.setattr(runs, "write_config", stopped)
    with pytest.raises(KeyboardInterrupt):
        model.learn(150)
    assert json.loads((tmp_path / "run" / "config.json").read_text())["total_steps"] == 150
    monkeypatch.undo()  # the resume is a new command: nothing stops it
    done = call("train.py", "--resume", "--quiet", "--out", tmp_path / "run")
    assert done.returncode == 0, done.stderr
    assert json.loads((tmp_path / "run" / "config.json").read_text())["total_steps"] == 300
    assert json.loads((tmp_path / "run" / "complete.json").read_text())["env_steps"] == 300


def test_a_third_party_env_from_pypi_made_by_gym_make(tmp_path):
    """MiniGrid (requirements-extras), as a user makes it: the id keeps its package, so evaluate.py
    in a new process registers it again; predict takes the env's raw Dict observation."""
    pytest.importorskip("minigrid")
    import minigrid  # noqa: F401  (registers MiniGrid's ids)

    env = gym.make("MiniGrid-Empty-5x5-v0")
    model = DQfD(env, lambda obs: 1 if obs[4 + (3 * 7 + 5) * 3] == 2 else 2, max_steps=100, **TINY).learn(200)
    assert model.config.task == "minigrid:MiniGrid-Empty-5x5-v0" and model.config.max_steps == 100
    obs, _ = env.reset(seed=0)
    assert isinstance(obs, dict) and isinstance(model.predict(obs)[0], int)
    model.save(tmp_path / "run")
    done = subprocess.run(
        [sys.executable, "evaluate.py", tmp_path / "run", "--episodes", "2", "--json"],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["lengths"] == model.evaluate(2).lengths
