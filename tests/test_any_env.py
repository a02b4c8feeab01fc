"""Any Gymnasium env through `--env ID`: a user's own env trains end to end, unsupported spaces
are refused in one line, demonstrators come from a rule or a saved model. The commands answer in
this process (`run`), as they would in their own."""

import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import python as run

from dqfd_bc_keras import demos
from dqfd_bc_keras.commands import cli
from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.envs.make import get_task, make_plain_env, make_task, task_slug, task_spaces
from dqfd_bc_keras.errors import ConfigError, DqfdError
from dqfd_bc_keras.evaluation import evaluate, load_policy
from dqfd_bc_keras.experiments.suites import SUITES, arm, on_task

REPO = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), str(REPO / "tests")])}
CHAIN = "toy_envs:ToyChain-v0"
NO_LIMIT = "toy_envs:ToyChainNoLimit-v0"
SUPPORTED = "supported: a Discrete action space starting at 0 and an observation of Box"
IMAGES = "observes images (part pixels): Box(84, 84, 3) uint8 inside a Dict or Tuple is not supported"


def process(*args: object) -> subprocess.CompletedProcess:
    """`python ARGS` as a process of its own, for what only a new process shows."""
    return subprocess.run([sys.executable, *map(str, args)], capture_output=True, text=True, cwd=REPO, env=ENV)


def one_line_error(done, message):
    assert done.returncode == 2, done.stdout + done.stderr
    assert message in done.stderr
    lines = [line for line in done.stderr.strip().splitlines() if not line.startswith("warning: ")]
    assert len(lines) == 1, done.stderr  # one line of error (after any one-line warning)


def test_a_user_env_is_a_task_with_its_own_limit_threshold_and_no_shaping():
    spec = get_task(CHAIN)
    assert (spec.env_id, spec.family, spec.max_steps, spec.solved_return) == (CHAIN, None, 20, 1.0)
    assert spec.fall_penalty is None and spec.goal_reward is None
    env = make_task(CHAIN, timeout="naive")
    env.reset(seed=0)
    flags = [env.step(0)[2:4] for _ in range(20)]  # never reaches the end: the limit ends it
    assert flags[-1] == (True, False) and all(f == (False, False) for f in flags[:-1])
    env = make_task(CHAIN, timeout="bootstrap", max_steps=3)
    env.reset(seed=0)
    assert [env.step(1)[1:4] for _ in range(3)] == [(0.0, False, False), (0.0, False, False), (0.0, False, True)]
    assert make_plain_env(CHAIN).spec.max_episode_steps == 20


def test_the_generic_preset_is_written_to_config_json_and_overridable():
    config = Config.for_task(CHAIN, total_steps=123)
    assert (config.task, config.total_steps, config.demo_episodes, config.early_stop_window) == (CHAIN, 123, 10, 0)
    assert Config.from_dict(json.loads(json.dumps(config.to_dict()))) == config
    assert config.with_overrides(["eval_every=7"]).eval_every == 7


@pytest.mark.parametrize(
    "env_id, message",
    [
        ("toy_envs:ToyImage-v0", IMAGES),
        ("Pendulum-v1", SUPPORTED),
        ("toy_envs:ToyTextOnly-v0", "which has no numeric part"),
    ],
)
def test_unsupported_spaces_are_refused_by_name(env_id, message):
    with pytest.raises(ConfigError, match=re.escape(message)):
        task_spaces(env_id)


def test_an_env_without_a_time_limit_needs_max_steps():
    with pytest.raises(ConfigError, match=re.escape("has no time limit of its own: set one with --max-steps N")):
        Config.for_task(NO_LIMIT)
    config = Config.for_task(NO_LIMIT, max_steps=9)
    assert config.limit == 9
    assert make_plain_env(config.task, max_steps=9).spec.max_episode_steps == 9


def test_rule_demonstrator_records_on_any_env():
    data = demos.record(CHAIN, "toy_envs:go_right", episodes=2)
    assert (data.actions == 1).all() and len(data) == 8 and data.meta.episode_returns == [1.0, 1.0]
    assert data.meta.task == data.meta.env_id == CHAIN
    noisy = demos.record(CHAIN, "toy_envs:go_right", episodes=3, epsilon=1.0, seed=0)
    assert set(noisy.actions) == {0, 1}


@pytest.mark.parametrize(
    "spec, message",
    [
        ("imperfect", "has no scripted imperfect expert"),
        (
            "toy_envs:nothing",
            "demonstrator toy_envs:nothing: toy_envs (tests/toy_envs.py) has no function 'nothing'; it has "
            "Chain, LegacyChain, OldApiChain, Unsupported, VectorReward, breakout_rule, dies, go_left, go_right, "
            "legacy_chain, out_of_range",
        ),
        (
            "no_such_module:rule",
            "demonstrator no_such_module:rule: no module named 'no_such_module' (is its directory on PYTHONPATH?)",
        ),
        (
            "toy_envs:NOT_CALLABLE",
            "demonstrator toy_envs:NOT_CALLABLE: NOT_CALLABLE is not a function (it is of type int)",
        ),
        (
            "toy_envs:out_of_range",
            "toy_envs:out_of_range returned 7 (int); a demonstrator returns an int action in "
            "[0, 2) (tests/toy_envs.py:83)",
        ),
        ("best", "expert='best' is none of strong, imperfect, module:function or a .keras model file"),
    ],
)
def test_bad_demonstrators_are_named(spec, message):
    with pytest.raises(ConfigError) as error:
        demos.record(CHAIN, spec, episodes=1)
    assert message in str(error.value)


def test_a_saved_model_demonstrates_its_greedy_policy():
    model = REPO / "models" / "cartpole" / "q_network.keras"
    data = demos.record("cartpole", str(model), episodes=3, seed=50)
    greedy = evaluate(load_policy(model)[0], "cartpole", 3, seed=50)
    assert data.meta.plain_returns == greedy.returns and data.meta.expert == str(model)
    with pytest.raises(DqfdError, match="model expects 4 observation features, task mountaincar gives 2"):
        demos.record("mountaincar", str(model), episodes=1)


def test_suites_move_to_any_env_with_their_settings():
    moved = on_task(SUITES["quick"], CHAIN, ["expert=toy_envs:go_right"])
    assert [a.task for a in moved] == [CHAIN, CHAIN]
    config = moved[0].config(0)
    assert config.total_steps == 600 and config.expert == "toy_envs:go_right"
    assert moved[0].name == "toy_envs-ToyChain-v0-bootstrap-bayes-" + moved[0].label
    assert moved[0].name.endswith("-toy_envs-go_right")  # one path component, whatever the values
    assert "/" not in on_task(SUITES["quick"], None, ["expert=models/cartpole/q_network.keras"])[0].name
    assert "/" not in task_slug("ALE/Pong-v5") and ":" not in task_slug(CHAIN)
    with pytest.raises(ConfigError, match="expert_loss is an arm's own"):
        on_task(SUITES["quick"], CHAIN, ["expert_loss=ce"])
    assert on_task([arm("cartpole", "bootstrap", "ce"), arm("cartpole-200", "bootstrap", "ce")], "acrobot") == [
        arm("acrobot", "bootstrap", "ce")
    ]


@pytest.mark.parametrize(
    "args, message",
    [
        (["train.py", "--env", "toy_envs:ToyImage-v0"], IMAGES),
        (["train.py", "--env", "Pendulum-v1"], SUPPORTED),
        (["train.py", "--env", "toy_envs:ToyTextOnly-v0"], "which has no numeric part"),
        (["train.py", "--env", "NoSuchEnv-v0"], "unknown task 'NoSuchEnv-v0'"),
        (["train.py", "--env", CHAIN, "--task", "cartpole"], "not allowed with argument"),
        (["train.py", "--env", CHAIN], "has no scripted imperfect expert"),
        (
            ["train.py", "--env", "Acrobot-v1"],
            "; the preset acrobot plays Acrobot-v1 with scripted experts (--task acrobot; from Python: "
            "DQfD('acrobot'))",
        ),
        (
            ["-m", "dqfd_bc_keras.demos", "record", "--env", "Pendulum-v1", "--expert", "strong", "--out", "x.npz"],
            SUPPORTED,
        ),
        (["evaluate.py", "models/cartpole", "--env", "Pendulum-v1"], SUPPORTED),
        (["-m", "dqfd_bc_keras.experiments", "run", "quick", "--env", "Pendulum-v1", "--out", "x"], SUPPORTED),
    ],
)
def test_unsupported_envs_are_refused_in_one_line_with_exit_2(args, message, tmp_path):
    one_line_error(
        run(*args[:1], *args[1:], *(["--quick", "--out", tmp_path / "r"] if args[0] == "train.py" else [])), message
    )


# --- an env without a time limit, env kwargs, observations to flatten: all through the commands ------------

DICT_NO_LIMIT = "toy_envs:ToyDictChainNoLimit-v0"
DROPPED = (
    "warning: toy_envs:ToyDictChainNoLimit-v0: dropping non-numeric observation part(s) mission "
    "(of Dict(cell: Discrete(7), mission: Text, visits: MultiBinary(7)))"
)


def warnings_of(done):
    return [line for line in done.stderr.splitlines() if line.startswith("warning:")]


@pytest.mark.slow
def test_a_user_env_without_a_limit_with_kwargs_and_a_dict_observation_end_to_end(tmp_path):
    """One user's path through every entry point: a Dict observation with a text part, no time
    limit, a constructor kwarg that changes the spaces (size=7: 7 states, 6 steps to the goal)."""
    refused = run("train.py", "--env", NO_LIMIT, "--expert", "toy_envs:go_right", "--quick", "--out", tmp_path / "x")
    one_line_error(refused, "time limit of its own: set one with --max-steps N (from Python: DQfD(env, max_steps=N))")

    demos_file = tmp_path / "seven.npz"
    done = run(
        "-m",
        "dqfd_bc_keras.demos",
        "record",
        "--env",
        DICT_NO_LIMIT,
        "--env-kwargs",
        "size=7",
        "--max-steps",
        12,
        "--policy",
        "toy_envs:go_right",
        "--episodes",
        20,
        "--out",
        demos_file,
    )
    assert done.returncode == 0, done.stderr
    assert warnings_of(done) == [DROPPED]
    assert 'env kwargs   {"size": 7}' in done.stdout
    assert (
        "observation  Dict(cell: Discrete(7), mission: Text, visits: MultiBinary(7)) flattened to 14 features; "
        "dropped mission"
    ) in done.stdout
    data = demos.load(demos_file)
    np.testing.assert_array_equal(data.obs[1], [0, 1, 0, 0, 0, 0, 0, 1, 1, 0, 0, 0, 0, 0])  # cell 1, visits 0 and 1

    one_line_error(
        run(
            "train.py",
            "--env",
            DICT_NO_LIMIT,
            "--demos",
            demos_file,
            "--set",
            "max_steps=12",
            "--quick",
            "--out",
            tmp_path / "y",
        ),
        'was recorded with env kwargs {"size": 7}, not the requested {}',
    )

    out = tmp_path / "run"
    done = run(
        "train.py",
        "--env",
        DICT_NO_LIMIT,
        "--env-kwargs",
        "size=7",
        "--set",
        "max_steps=12",
        "--demos",
        demos_file,
        "--quick",
        "--quiet",
        "--set",
        "checkpoint_every=50",
        "--out",
        out,
    )
    assert done.returncode == 0, done.stderr
    assert warnings_of(done) == [DROPPED]  # once, however many envs the run makes
    config = json.loads((out / "config.json").read_text())
    assert (config["env_kwargs"], config["max_steps"]) == ({"size": 7}, 12)
    assert config["observation"] == {
        "space": "Dict(cell: Discrete(7), mission: Text, visits: MultiBinary(7))",
        "shape": None,
        "features": 14,
        "flattened": True,
        "dropped": ["mission"],
        "frames": None,
    }
    result = json.loads((out / "eval.json").read_text())
    assert (result["env_kwargs"], result["lengths"], result["mean_return"]) == ({"size": 7}, [6, 6], 1.0)

    evaluated = run("evaluate.py", out, "--episodes", 2, "--json")  # kwargs and limit from config.json
    assert evaluated.returncode == 0, evaluated.stderr
    assert json.loads(evaluated.stdout)["lengths"] == [6, 6]
    with pytest.raises(DqfdError, match="model expects 14 observation features, task .* gives 10"):
        load_policy(out, env_kwargs={"size": 5})
    bare = tmp_path / "model.keras"
    bare.write_bytes((out / "q_network.keras").read_bytes())  # no config.json beside it: everything is given
    evaluated = run(
        "evaluate.py",
        bare,
        "--env",
        DICT_NO_LIMIT,
        "--env-kwargs",
        "size=7",
        "--max-steps",
        3,
        "--episodes",
        1,
        "--json",
    )
    assert evaluated.returncode == 0, evaluated.stderr
    assert json.loads(evaluated.stdout)["lengths"] == [3]  # the given limit cuts the 6-step walk

    resumed = run("train.py", "--out", out, "--resume", "--quiet")  # no --env, no kwargs, no limit: the run's own
    assert resumed.returncode == 0, resumed.stderr
    assert json.loads((out / "config.json").read_text())["env_kwargs"] == {"size": 7}

    sweep = tmp_path / "sweep"
    done = run(
        "-m",
        "dqfd_bc_keras.experiments",
        "run",
        "quick",
        "--env",
        DICT_NO_LIMIT,
        "--max-steps",
        9,
        "--env-kwargs",
        "size=6",
        "--seeds",
        1,
        "--workers",
        2,
        "--set",
        "expert=toy_envs:go_right",
        "--out",
        sweep,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    runs = sorted(sweep.glob("*/seed0"))
    assert len(runs) == 2 and all(r.parent.name.endswith("-size=6-toy_envs-go_right") for r in runs), runs
    for run_dir in runs:
        config = json.loads((run_dir / "config.json").read_text())
        assert (config["env_kwargs"], config["max_steps"]) == ({"size": 6}, 9)
        assert all(1 <= n <= 9 for n in json.loads((run_dir / "eval.json").read_text())["lengths"])


@pytest.mark.slow
def test_a_grid_observation_is_flattened_in_c_order(tmp_path):
    out = tmp_path / "grid"
    done = run(
        "train.py",
        "--env",
        "toy_envs:ToyGridChain-v0",
        "--expert",
        "toy_envs:go_right",
        "--demo-episodes",
        20,
        "--quick",
        "--quiet",
        "--out",
        out,
    )
    assert done.returncode == 0, done.stderr
    assert json.loads((out / "config.json").read_text())["observation"] == {
        "space": "Box(5, 2) float32",
        "shape": [5, 2],
        "features": 10,
        "flattened": True,
        "dropped": [],
        "frames": None,
    }
    assert json.loads((out / "eval.json").read_text())["mean_return"] == 1.0
    data = demos.load(out / "demos.npz")
    assert data.meta.observation == "Box(5, 2) float32 flattened to 10 features"
    np.testing.assert_array_equal(data.obs[0], [1, 0, 0, 1, 0, 1, 0, 1, 0, 1])  # rows (1, 0), then (0, 1) × 4


def test_a_bad_env_kwarg_is_one_line_naming_it_and_the_env(tmp_path):
    out = tmp_path / "r"
    one_line_error(
        run("train.py", "--env", CHAIN, "--env-kwargs", "sise=7", "--quick", "--out", out),
        "--env-kwargs sise: toy_envs:ToyChain-v0 takes no keyword argument 'sise' (did you mean 'size'? "
        "it takes: size, observe)",
    )
    for argv, message in [
        (["--env", CHAIN, "--env-kwargs", "render_mode=human"], "--env-kwargs render_mode: not an env kwarg here"),
        (["--env", CHAIN, "--env-kwargs", "7"], "argument --env-kwargs: expected KEY=VALUE"),
        (["--env", CHAIN, "--set", "env_kwargs=7"], "--set env_kwargs='7': expected a JSON object"),
        (["--task", "cartpole", "--env-kwargs", "gravity=1"], "CartPole-v1 takes no keyword argument 'gravity'"),
    ]:
        one_line_error(run("train.py", *argv, "--quick", "--out", out), message)
    assert not out.exists()


def test_env_kwargs_values_are_json_else_strings():
    assert cli.env_kwarg("use_lidar=false") == ("use_lidar", False)
    assert cli.env_kwarg('obs_type="ram"') == ("obs_type", "ram")
    assert cli.env_kwarg("obs_type=ram") == ("obs_type", "ram")
    assert cli.env_kwarg('config={"lanes_count": 3}') == ("config", {"lanes_count": 3})
    assert cli.env_kwarg("size=7") == ("size", 7) and cli.env_kwarg("x=1.5") == ("x", 1.5)


def test_old_demonstration_files_without_kwargs_are_refused_in_one_line(tmp_path):
    """A file that has no env_kwargs or observation in its meta was written by an older version:
    what its env was made with is not known, so it is not guessed."""
    data = demos.record(CHAIN, "toy_envs:go_right", episodes=1)
    demos.save(data, tmp_path / "new.npz")
    with np.load(tmp_path / "new.npz") as contents:
        arrays = {key: contents[key] for key in contents.files}
    meta = json.loads(str(arrays["meta"]))
    del meta["env_kwargs"], meta["observation"]
    np.savez(tmp_path / "old.npz", **{**arrays, "meta": np.array(json.dumps(meta))})
    with pytest.raises(DqfdError, match=re.escape("meta lacks ['env_kwargs', 'observation']: written by an older")):
        demos.load(tmp_path / "old.npz", task=CHAIN, timeout="bootstrap")


def readme_any_env_block() -> str:
    """The first bash block of the README's "Any Gymnasium env" section: what a user copies."""
    section = (REPO / "README.md").read_text().split("### Any Gymnasium env", 1)[1]
    return section.split("```bash\n", 1)[1].split("```", 1)[0]


@pytest.mark.slow
def test_the_readme_third_party_env_commands_train_and_evaluate(tmp_path):
    """Each `train.py` line of the README block, as written, plus a budget of seconds; the rules
    module is the block's own heredoc. The three runs go at once (one per core, and a third)."""
    for module in ("flappy_bird_gymnasium", "highway_env", "minigrid"):
        pytest.importorskip(module)  # requirements-extras.txt, which the test command installs
    block = readme_any_env_block()
    rules = block.split("<<'EOF'\n", 1)[1].split("\nEOF\n", 1)[0]
    (tmp_path / "my_rules.py").write_text(rules + "\n")
    commands = [
        line.split("train.py", 1)[1] for line in block.splitlines() if line.startswith(".venv/bin/python train.py")
    ]
    assert len(commands) == 3
    quick = ["--quick", "--quiet", "--set", "total_steps=200", "--set", "eval_every=200"]
    for i, args in enumerate(commands):
        done = run("train.py", *shlex.split(args), *quick, "--out", tmp_path / f"run{i}", cwd=tmp_path, path=[tmp_path])
        assert done.returncode == 0, f"{args}\n{done.stderr}"
    configs = [json.loads((tmp_path / f"run{i}" / "config.json").read_text()) for i in range(3)]
    assert configs[0]["env_kwargs"] == {"use_lidar": False} and configs[0]["observation"]["features"] == 12
    assert configs[1]["observation"]["shape"] == [5, 5] and configs[1]["observation"]["features"] == 25
    assert configs[2]["observation"]["dropped"] == ["mission"] and configs[2]["observation"]["features"] == 151
    assert [c["max_steps"] for c in configs] == [1000, 40, 100]
    for i in range(3):
        result = json.loads((tmp_path / f"run{i}" / "eval.json").read_text())
        assert len(result["returns"]) == 2 and all(n <= configs[i]["max_steps"] for n in result["lengths"])
    # MiniGrid in a new process, which imports minigrid again as config.json's env id says
    evaluated = process("evaluate.py", tmp_path / "run2", "--episodes", 1, "--json")
    assert evaluated.returncode == 0, evaluated.stderr
