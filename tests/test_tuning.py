"""`experiments tune` as a user runs it: a quick study end to end, its continuation, workers sharing
one storage, Ctrl-C in a trial, `train.py --params`, the refusals; the metrics computed by hand."""

import json
import signal
import sqlite3
import subprocess
import sys
import time

import numpy as np
import optuna
import pytest
from helpers import ENV, REPO, assert_refused, call
from PIL import Image

from dqfd_bc_keras.core.methods import METHODS, Method
from dqfd_bc_keras.core.search_space import SHARED, Choice, Span, method_space
from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.seeds import TUNE_SEED
from dqfd_bc_keras.tuning import study
from dqfd_bc_keras.tuning.objective import intermediate, score
from dqfd_bc_keras.tuning.space import read_space, study_space

LAB = "dqfd_bc_keras.experiments"


def tune(tmp_path, *args, name="quick", trials=3):
    """`tune --task cartpole --trials N --quick` on a SQLite file of the test's, in this process."""
    storage = f"sqlite:///{tmp_path / 'shared.db'}"
    return call(
        LAB, "tune", "--task", "cartpole", "--trials", trials, "--quick", "--workers", 1,
        "--storage", storage, "--study-name", name, "--out", tmp_path / "study", *args,
    )  # fmt: skip


def trials_of(tmp_path, name="quick"):
    return optuna.load_study(study_name=name, storage=f"sqlite:///{tmp_path / 'shared.db'}").get_trials()


def drawn(path) -> bool:
    """A PNG with something drawn on it: more than a few colours, not one flat fill."""
    pixels = np.asarray(Image.open(path).convert("RGB"))
    return pixels.shape[0] > 100 and len(np.unique(pixels.reshape(-1, 3), axis=0)) > 20


# --- the metrics, by hand ---


def test_each_metric_scores_a_curve_as_its_definition_says():
    curve = [(0, -500.0), (1000, -200.0), (2000, -90.0), (3000, -80.0)]
    # the area under the curve over the 4,000-step budget, the last value held from 3,000 to 4,000
    area = (1000 * (-500 - 200) / 2 + 1000 * (-200 - 90) / 2 + 1000 * (-90 - 80) / 2 + 1000 * -80) / 4000
    assert score("auc", curve, -70.0, 4000, 1000, None) == pytest.approx(area)
    assert score("final", curve, -70.0, 4000, 1000, None) == -70.0
    assert score("threshold", curve, -70.0, 4000, 1000, -100.0) == 2000.0
    assert score("threshold", curve, -70.0, 4000, 1000, -50.0) == 5000.0  # never: the grid point after the budget
    # while the run goes on: the area so far, the last return, the step it reached it at or "never"
    assert score("auc", curve[:2], None, 4000, 1000, None) == pytest.approx((-500 - 200) / 2)
    assert score("final", curve[:2], None, 4000, 1000, None) == -200.0
    assert score("threshold", curve[:2], None, 4000, 1000, -100.0) == 5000.0
    assert score("threshold", curve[:3], None, 4000, 1000, -100.0) == 2000.0


def test_a_trials_intermediate_value_counts_the_seeds_not_yet_run_as_never_for_the_threshold():
    # seed 0 done at 2,000, seed 1 running and not there yet, seed 2 to come; never = 5,000
    assert intermediate("threshold", [2000.0], 5000.0, 1, 5000.0) == pytest.approx((2000 + 5000 + 5000) / 3)
    assert intermediate("auc", [-100.0], -300.0, 1, 5000.0) == -200.0  # the seeds run so far only


# --- the search space ---


def test_every_method_searches_the_shared_fields_that_apply_and_its_own_reads():
    for method in METHODS.values():
        space = method_space(method)
        own = set(space) - set(SHARED)
        assert own <= set(method.reads), method.name
    assert "lambda_expert" not in method_space(METHODS["none"]) and "priority_eps_demo" not in method_space(
        METHODS["sqil"]
    )
    assert {"sigma0_sq", "prior_scale", "bc_dropout", "temperature"} <= set(method_space(METHODS["bayes"]))
    with pytest.raises(ConfigError, match="'margin', which is not among the fields it reads"):
        Method("mine", "a method of a user's", space=(("margin", Span(0.1, 1.0)),))


def test_a_space_file_ranges_fixes_and_drops_fields(tmp_path):
    path = tmp_path / "space.json"
    path.write_text(
        json.dumps(
            {
                "learning_rate": {"low": 1e-4, "high": 1e-2, "log": True},
                "n_step": 3,
                "margin": None,
                "hidden": {"choices": [[32], [64, 64]]},
            }
        )
    )
    dimensions, fixed, dropped = read_space(path)
    assert dimensions == {"learning_rate": Span(1e-4, 1e-2, True), "hidden": Choice(((32,), (64, 64)))}
    assert (fixed, dropped) == ({"n_step": 3}, {"margin"})
    space, fixed = study_space("margin", {"total_steps": 600}, path)
    assert "margin" not in space and "n_step" not in space and space["learning_rate"] == Span(1e-4, 1e-2, True)
    assert fixed == {"total_steps": 600, "n_step": 3}


# --- the command ---


def test_a_quick_study_runs_end_to_end_and_a_second_invocation_continues_it(tmp_path):
    done = tune(tmp_path, trials=2)
    assert done.returncode == 0, done.stderr
    assert done.stdout.count("\ntrial ") + done.stdout.startswith("trial ") == 2, done.stdout
    first = trials_of(tmp_path)
    assert [t.state.name for t in first] == ["COMPLETE"] * 2  # the median pruner waits for 5 trials
    out = tmp_path / "study"
    best = json.loads((out / "best.json").read_text())
    top = max(first, key=lambda t: t.value)
    assert (best["trial"], best["value"], best["params"]) == (top.number, top.value, top.user_attrs["params"])
    assert best["study"] == "quick" and best["storage"] == f"sqlite:///{tmp_path / 'shared.db'}"
    for trial in first:  # each trial an ordinary, complete run directory, its value the metric of its run
        record = json.loads((out / "trials" / f"trial-{trial.number:04d}" / "trial.json").read_text())
        run = out / "trials" / f"trial-{trial.number:04d}" / f"seed{TUNE_SEED}"
        assert record["state"] == "COMPLETE" and record["value"] == trial.value
        assert (run / "complete.json").is_file() and json.loads((run / "config.json").read_text())["seed"] == TUNE_SEED
        assert {k: json.loads((run / "config.json").read_text())[k] for k in record["params"]} == {
            k: list(v) if isinstance(v, tuple) else v for k, v in record["params"].items()
        }
    for figure in ("history.png", "importances.png", "parallel.png"):
        assert drawn(out / "figures" / figure), figure

    again = tune(tmp_path, trials=3)
    assert again.returncode == 0, again.stderr
    second = trials_of(tmp_path)
    assert len(second) == 3 and [t.params for t in second[:2]] == [t.params for t in first]
    assert "3 complete" in again.stdout
    # the same study for the same question; for another task, refused in one line
    refused = tune(tmp_path, "--steps", 700)
    assert refused.returncode == 2 and refused.stderr.count("\n") == 1
    assert "study 'quick' in sqlite:///" in refused.stderr and "tunes something else" in refused.stderr
    assert "(fixed total_steps: the study's 600, asked 700)" in refused.stderr
    assert len(trials_of(tmp_path)) == 3
    other = tune(tmp_path, name="other")  # its trials would be named as this one's
    assert_refused(
        other, f"error: {tmp_path / 'study'} holds the trials of study 'quick' (storage "
        f"sqlite:///{tmp_path / 'shared.db'}); give this study its own --out",
    )  # fmt: skip


def test_train_takes_the_best_params_and_a_later_set_wins(tmp_path):
    best = tmp_path / "best.json"
    best.write_text(
        json.dumps(
            {"params": {"learning_rate": 0.0005, "n_step": 3, "hidden": [32, 32]}, "tunes": {"task": "cartpole"}}
        )
    )
    done = call("train.py", "--quick", "--quiet", "--params", best, "--set", "n_step=4", "--out", tmp_path / "run")
    assert done.returncode == 0, done.stderr
    config = json.loads((tmp_path / "run" / "config.json").read_text())
    assert (config["learning_rate"], config["n_step"], config["hidden"]) == (0.0005, 4, [32, 32])
    best.write_text(json.dumps({"params": {"learning_rat": 0.1}}))
    assert_refused(
        call("train.py", "--quick", "--params", best, "--out", tmp_path / "other"),
        f"error: {best}: unknown Config field 'learning_rat'; did you mean learning_rate?",
    )
    assert not (tmp_path / "other").exists()


@pytest.mark.parametrize(
    "args, message",
    [
        (("--storage", "nosuchdb://x"), "error: --storage nosuchdb://x: "),
        (("--storage", "study.txt"), "error: --storage study.txt: expected a database URL"),
        (("--storage", "mysql+pymysql://u@localhost/x"), "PyMySQL for mysql+pymysql://"),  # no driver installed
        (("--set", "lerning_rate=0.1"), "unknown Config field 'lerning_rate'; did you mean learning_rate?"),
        (
            ("--metric", "threshold", "--env", "CliffWalking-v1"),
            "CliffWalking-v1 sets no solved return: --metric threshold needs --threshold R",
        ),
        (("--env", "Acrobot-v1"), "Acrobot-v1 has no scripted imperfect expert"),
    ],
)
def test_a_bad_storage_or_field_is_one_line_and_exit_2(tmp_path, args, message):
    done = call(LAB, "tune", "--quick", "--out", tmp_path / "study", *args)
    assert done.returncode == 2 and done.stdout == "" and done.stderr.count("\n") == 1, done.stderr
    assert message in done.stderr
    assert not (tmp_path / "study").exists()  # nothing left behind


def test_a_misspelt_field_of_the_space_file_gets_a_suggestion(tmp_path):
    space = tmp_path / "space.json"
    space.write_text(json.dumps({"sigma0sq": {"low": 0.1, "high": 1.0}}))
    done = call(LAB, "tune", "--quick", "--space", space, "--out", tmp_path / "study")
    assert_refused(done, f"error: --space {space}: unknown Config field 'sigma0sq'; did you mean sigma0_sq?")
    space.write_text(json.dumps({"learning_rate": {"low": -1.0, "high": 1.0}}))
    done = call(LAB, "tune", "--quick", "--space", space, "--out", tmp_path / "study")
    assert done.returncode == 2 and "the space's learning_rate=-1.0: learning_rate" in done.stderr


def test_a_pruned_trial_says_so_in_its_run_directory(tmp_path):
    from dqfd_bc_keras.tuning import study as studies
    from dqfd_bc_keras.tuning.objective import Objective

    class Always(optuna.pruners.BasePruner):
        def prune(self, study, trial):
            return len(trial.intermediate_values) >= 2

    settings = studies.TuneSettings(out=tmp_path, quick=True, workers=1)
    space, fixed = study_space("bayes", settings.run_fields(), None)
    study = optuna.create_study(pruner=Always(), direction="maximize")
    study.optimize(Objective(settings, space, fixed, "test"), n_trials=1)
    [trial] = study.trials
    assert trial.state.name == "PRUNED" and sorted(trial.intermediate_values) == [0, 1]
    pruned = json.loads((tmp_path / "trials" / "trial-0000" / f"seed{TUNE_SEED}" / "pruned.json").read_text())
    assert pruned["step"] == 1 and pruned["value"] == trial.intermediate_values[1]
    assert json.loads((tmp_path / "trials" / "trial-0000" / "trial.json").read_text())["state"] == "PRUNED"
    assert not (tmp_path / "trials" / "trial-0000" / f"seed{TUNE_SEED}" / "complete.json").exists()


# --- processes: workers sharing a study, Ctrl-C ---


def start(tmp_path, *args, trials=4, workers=1):
    return subprocess.Popen(
        [sys.executable, "-m", LAB, "tune", "--task", "cartpole", "--quick", "--trials", str(trials),
         "--workers", str(workers), "--storage", f"sqlite:///{tmp_path / 'shared.db'}", "--study-name", "shared",
         "--out", str(tmp_path / "study"), *args],
        cwd=REPO, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )  # fmt: skip


@pytest.mark.slow
@pytest.mark.parametrize("journal", [False, True])
def test_two_commands_and_a_pool_of_workers_share_one_study(tmp_path, journal):
    storage = ("--storage", str(tmp_path / "journal.log")) if journal else ()
    pool, single = start(tmp_path, *storage, workers=2, trials=3), start(tmp_path, *storage, trials=3)
    for process in (pool, single):
        _, err = process.communicate(timeout=600)
        assert process.returncode == 0, err
    if journal:
        backend = optuna.storages.journal.JournalFileBackend(str(tmp_path / "journal.log"))
        trials = optuna.load_study(study_name="shared", storage=optuna.storages.JournalStorage(backend)).get_trials()
    else:
        trials = trials_of(tmp_path, "shared")
    assert 3 <= len(trials) <= 3 + 2  # a worker that checks the count as another starts may add one
    assert {t.state.name for t in trials} == {"COMPLETE"}
    numbers = sorted(t.number for t in trials)
    assert numbers == list(range(len(trials)))
    # each trial ran once: one directory and one run each, its value the one the storage holds
    for trial in trials:
        record = json.loads((tmp_path / "study" / "trials" / f"trial-{trial.number:04d}" / "trial.json").read_text())
        assert record["value"] == trial.value
    if not journal:
        db = sqlite3.connect(tmp_path / "shared.db")
        assert db.execute("select count(*) from trials where state = 'RUNNING'").fetchone() == (0,)


def test_a_process_that_loses_the_race_to_create_the_tables_opens_them_after_the_winner(tmp_path, monkeypatch):
    """The loser's error, made for real (SQLite refusing a table that exists), on the first attempt:
    open_storage waits and opens the database the winner made, where it used to exit 2."""
    import sqlalchemy

    engine = sqlalchemy.create_engine(f"sqlite:///{tmp_path / 'other.db'}")
    with engine.connect() as connection:
        connection.execute(sqlalchemy.text("create table studies (id integer)"))
        with pytest.raises(sqlalchemy.exc.OperationalError) as lost:
            connection.execute(sqlalchemy.text("create table studies (id integer)"))
    assert "already exists" in str(lost.value)
    opened, attempts = optuna.storages.RDBStorage, []

    def racing(*args, **kwargs):
        attempts.append(args[0])
        if len(attempts) == 1:
            raise lost.value
        return opened(*args, **kwargs)

    monkeypatch.setattr(optuna.storages, "RDBStorage", racing)
    monkeypatch.setattr(time, "sleep", lambda seconds: None)
    url = f"sqlite:///{tmp_path / 'new.db'}"
    storage = study.open_storage(url)
    assert attempts == [url, url]
    monkeypatch.undo()
    assert optuna.create_study(study_name="after", storage=storage).study_name == "after"


def test_processes_opening_one_new_database_at_once_all_open_it(tmp_path):
    """SQLAlchemy checks for Optuna's tables, then creates them: processes that start together on a
    new SQLite file race, and a loser sees "table ... already exists" (10 of 24 opens failed so, in 6 rounds)."""
    url = f"sqlite:///{tmp_path / 'new.db'}"
    at = time.time() + 8  # every process imported and waiting before the first opens
    opener = (
        "import sys, time\n"
        "from dqfd_bc_keras.tuning.study import open_storage\n"
        "while time.time() < float(sys.argv[2]): pass\n"
        "open_storage(sys.argv[1]); print('opened')\n"
    )
    processes = [
        subprocess.Popen(
            [sys.executable, "-c", opener, url, str(at)],
            env=ENV,
            text=True,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
        )
        for _ in range(4)
    ]
    for process in processes:
        out, err = process.communicate(timeout=120)
        assert (process.returncode, out.strip()) == (0, "opened"), err


@pytest.mark.slow
@pytest.mark.parametrize("workers", [1, 2])
def test_ctrl_c_in_a_trial_marks_it_failed_and_exits_130_within_seconds(tmp_path, workers):
    budget = ("--set", "total_steps=3000", "--set", "checkpoint_every=300")
    process = start(tmp_path, *budget, workers=workers)
    deadline = time.time() + 240
    while time.time() < deadline and process.poll() is None:
        latest = list((tmp_path / "study" / "trials").glob("trial-*/seed*/checkpoints/latest.json"))
        if len(latest) >= workers and all(p.read_text().strip() and "ckpt-0" not in p.read_text() for p in latest):
            break
        time.sleep(0.1)
    sent = time.time()
    process.send_signal(signal.SIGINT)
    _, err = process.communicate(timeout=120)
    seconds = time.time() - sent
    assert process.returncode == 130, err
    assert seconds < 30, seconds
    assert err.strip().splitlines()[-1].startswith("interrupted (Ctrl-C)")
    trials = trials_of(tmp_path, "shared")
    assert [t.state.name for t in trials] == ["FAIL"] * workers  # never left RUNNING
    for trial in trials:
        directory = tmp_path / "study" / "trials" / f"trial-{trial.number:04d}"
        assert (directory / f"seed{TUNE_SEED}" / "checkpoints" / "latest.json").is_file()  # resumable
    # the same command goes on: the failed trials stay and do not count towards --trials, a new one runs
    again = start(tmp_path, *budget, trials=1)
    _, err = again.communicate(timeout=600)
    assert again.returncode == 0, err
    assert [t.state.name for t in trials_of(tmp_path, "shared")] == ["FAIL"] * workers + ["COMPLETE"]


@pytest.mark.slow
def test_tune_and_the_params_it_finds_from_a_python_script(tmp_path):
    script = tmp_path / "mine.py"
    script.write_text(
        "import dqfd_bc_keras\n"
        "from dqfd_bc_keras import DQfD\n"
        "from dqfd_bc_keras.core.params import read_params\n"
        "from dqfd_bc_keras.tuning import tune\n"
        "dqfd_bc_keras.configure()\n"
        f"found = tune('cartpole', out={str(tmp_path / 'study')!r}, trials=2, quick=True, workers=1,\n"
        "             sampler='random')\n"
        "params = read_params(found.best_file, 'cartpole')\n"
        "assert params == found.params, (params, found.params)\n"
        "model = DQfD('cartpole', total_steps=300, pretrain_steps=10, bc_epochs=1, demo_episodes=1, **params)\n"
        "assert all(getattr(model.config, k) == (tuple(v) if isinstance(v, list) else v) for k, v in params.items())\n"
        "print(len(found.study.trials), found.trial)\n"
    )
    done = subprocess.run(
        [sys.executable, str(script)], cwd=tmp_path, env=ENV, capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert [line.split(":")[0] for line in lines[:2]] == ["trial 0", "trial 1"]  # a line per trial, as the CLI's
    assert lines[-1].split()[0] == "2"


@pytest.mark.slow
def test_the_fresh_seed_check_runs_both_arms_and_reports_the_rule(tmp_path):
    best = tmp_path / "best.json"
    tunes = {"task": "cartpole", "demos": None, "expert_loss": "bayes", "metric": "threshold", "threshold": 475.0}
    found = {"params": {"n_step": 3}, "value": 1.0, "trial": 0, "study": "s", "storage": "x", "metric": "threshold"}
    best.write_text(json.dumps({**found, "tunes": {**tunes, "seeds": [TUNE_SEED], "fixed": {"total_steps": 600}}}))
    done = call("studies.tuned", best, "--quick", "--out", tmp_path / "runs", "--report", tmp_path / "TUNED.md")
    assert done.returncode == 0, done.stderr
    assert sorted(p.name for p in (tmp_path / "runs").iterdir() if p.is_dir()) == [
        "cartpole-bootstrap-bayes-defaults",
        "cartpole-bootstrap-bayes-tuned",
    ]
    tuned = json.loads((tmp_path / "runs" / "cartpole-bootstrap-bayes-tuned" / "seed1" / "config.json").read_text())
    defaults = json.loads(
        (tmp_path / "runs" / "cartpole-bootstrap-bayes-defaults" / "seed1" / "config.json").read_text()
    )
    assert (tuned["n_step"], defaults["n_step"], tuned["seed"]) == (3, 10, 1)  # fresh seeds, never the tuning ones
    text = (tmp_path / "TUNED.md").read_text()
    assert "| defaults | 2 |" in text and "| tuned | 2 |" in text and "Mann–Whitney p =" in text


@pytest.mark.slow
def test_a_third_party_env_from_pypi_is_tuned_with_a_rule_of_the_users(tmp_path):
    pytest.importorskip("flappy_bird_gymnasium")  # requirements-extras.txt, which the test command installs
    (tmp_path / "my_rules.py").write_text("def flap(obs):\n    return int(obs[9] > obs[2] - 0.1)\n")
    done = call(
        LAB, "tune", "--env", "flappy_bird_gymnasium:FlappyBird-v0", "--env-kwargs", "use_lidar=false",
        "--max-steps", 1000, "--expert", "my_rules:flap", "--metric", "final", "--trials", 2, "--quick",
        "--set", "total_steps=200", "--set", "eval_every=200", "--workers", 1, "--out", tmp_path / "study",
        cwd=tmp_path, path=[tmp_path],
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    for run in sorted((tmp_path / "study" / "trials").glob("trial-*/seed*")):
        config = json.loads((run / "config.json").read_text())
        assert (config["env_kwargs"], config["expert"], config["max_steps"]) == (
            {"use_lidar": False},
            "my_rules:flap",
            1000,
        )
        assert (run / "complete.json").is_file()
    best = json.loads((tmp_path / "study" / "best.json").read_text())
    assert best["tunes"]["task"] == "flappy_bird_gymnasium:FlappyBird-v0" and best["metric"] == "final"


@pytest.mark.slow
def test_ray_workers_take_the_trials_of_one_study(tmp_path):
    pytest.importorskip("ray")  # requirements-ray.txt, which the test command installs
    done = subprocess.run(
        [sys.executable, "-m", LAB, "tune", "--task", "cartpole", "--quick", "--trials", "2", "--workers", "2",
         "--backend", "ray", "--out", str(tmp_path / "study")],
        cwd=REPO, env=ENV, capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    study = optuna.load_study(study_name="cartpole-bayes-auc", storage=f"sqlite:///{tmp_path / 'study' / 'study.db'}")
    assert len(study.trials) in (2, 3) and {t.state.name for t in study.trials} == {"COMPLETE"}
    assert {t.user_attrs["runner"] for t in study.trials} == {study.trials[0].user_attrs["runner"]}
    assert (tmp_path / "study" / "best.json").is_file() and "best" in done.stdout


def test_the_committed_example_regenerates_from_its_data():
    """docs/TUNING.md's fresh-seed table and verdict, as studies.tuned computes them from the committed runs."""
    from studies.tuned import report

    text = report(REPO / "docs" / "data" / "tuning-acrobot-best.json", REPO / "docs" / "data" / "tuned-acrobot.tar.xz")
    table = [line for line in text.splitlines() if line.startswith(("| ", "Tuned against", "Defaults ÷"))]
    assert len(table) == 6
    doc = (REPO / "docs" / "TUNING.md").read_text().splitlines()
    assert [line for line in table if line not in doc] == []
    best = json.loads((REPO / "docs" / "data" / "tuning-acrobot-best.json").read_text())
    study = optuna.load_study(
        study_name=best["study"], storage=f"sqlite:///{REPO / 'docs' / 'data' / 'tuning-acrobot.db'}"
    )
    states = [t.state.name for t in study.trials]
    assert (len(states), states.count("COMPLETE"), states.count("PRUNED")) == (50, 31, 19)
    assert (study.best_trial.number, study.best_value) == (best["trial"], best["value"])


@pytest.mark.slow
@pytest.mark.parametrize("sampler, pruner", [("cmaes", "hyperband"), ("random", "none")])
def test_each_sampler_and_pruner_runs_a_study(tmp_path, sampler, pruner):
    done = tune(tmp_path, "--sampler", sampler, "--pruner", pruner, name=f"{sampler}-{pruner}", trials=1)
    assert done.returncode == 0, done.stderr
    study = optuna.load_study(study_name=f"{sampler}-{pruner}", storage=f"sqlite:///{tmp_path / 'shared.db'}")
    assert len(study.trials) == 1 and {t.state.name for t in study.trials} <= {"COMPLETE", "PRUNED"}
    kind = {"cmaes": "CmaEsSampler", "random": "RandomSampler"}[sampler]
    from dqfd_bc_keras.tuning.study import sampler as made

    assert type(made(sampler)).__name__ == kind
