"""Greedy evaluation: the NumPy policy against Keras, episodes played (`episodes.play`) on the plain
env, loading errors, and `evaluate.py` end to end."""

import json
from pathlib import Path
from types import SimpleNamespace

import keras
import numpy as np
import pytest
from helpers import Answer, call

import dqfd_bc_keras  # noqa: F401  (first: TF settings, BCModel registered)
from dqfd_bc_keras.core.bc import BCModel, BCNetwork
from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.core.networks import build_q_network
from dqfd_bc_keras.envs.episodes import play
from dqfd_bc_keras.envs.make import make_plain_env
from dqfd_bc_keras.errors import ConfigError, ModelFileError
from dqfd_bc_keras.evaluation import EvalResult, GreedyPolicy, evaluate, load_model, load_policy

REPO = Path(__file__).resolve().parents[1]
MEAN, STD = np.array([0.1, -0.2, 0.05, 0.3]), np.array([0.5, 1.5, 0.1, 2.0])
KEYS = {
    "task",
    "policy",
    "episodes",
    "seed",
    "returns",
    "mean_return",
    "std_return",
    "min_return",
    "max_return",
    "lengths",
}


def balance(obs):
    """Keeps CartPole up for 500 steps: push right iff θ + 0.5·θ̇ > 0."""
    return int(obs[2] + 0.5 * obs[3] > 0)


def follow_velocity(obs):
    """MountainCar's imperfect expert: push in the direction of motion."""
    return 2 if obs[1] >= 0 else 0


def make_run(path: Path, expert_loss: str = "bayes", bc: bool = True) -> Path:
    """A run directory with a small Q-network, a BC model and the cartpole config."""
    path.mkdir(parents=True)
    keras.utils.set_random_seed(0)
    build_q_network(4, 2, (16, 16), obs_scale=(MEAN, STD)).save(path / "q_network.keras")
    if bc:
        BCModel(4, 2, BCNetwork(hidden=(16,), dropout=0.2), obs_scale=(MEAN, STD)).save(path / "bc_model.keras")
    config = Config.for_task("cartpole", expert_loss=expert_loss)
    (path / "config.json").write_text(json.dumps(config.to_dict()))
    return path


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    return make_run(tmp_path_factory.mktemp("eval") / "run")


@pytest.mark.parametrize("policy", ["q", "bc"])
def test_greedy_policy_matches_the_saved_keras_model(run_dir, policy):
    model = load_model(run_dir / f"{'q_network' if policy == 'q' else 'bc_model'}.keras")
    greedy = GreedyPolicy.from_model(model)
    obs = np.random.default_rng(0).normal(MEAN, 3 * STD, size=(200, 4)).astype(np.float32)
    expected = keras.ops.convert_to_numpy(model(obs, training=False))
    np.testing.assert_allclose(greedy.values(obs), expected, atol=1e-5, rtol=1e-5)
    assert [greedy(o) for o in obs] == list(expected.argmax(axis=1))
    assert greedy.kind == policy and isinstance(greedy(obs[0]), int)


def test_greedy_policy_rejects_layers_it_cannot_compute():
    obs = keras.Input(shape=(4,))
    model = keras.Model(obs, keras.layers.Dense(2, name="out")(keras.layers.BatchNormalization(name="bn")(obs)))
    with pytest.raises(ModelFileError, match="'bn'.*BatchNormalization"):
        GreedyPolicy.from_model(model)
    model = keras.Model(obs, keras.layers.Dense(2, activation="tanh", name="squash")(obs))
    with pytest.raises(ModelFileError, match="'tanh'.*'squash'"):
        GreedyPolicy.from_model(model)


def test_cartpole_returns_are_the_plain_envs():
    result = evaluate(balance, "cartpole", episodes=3, seed=0)
    assert result.returns == [500.0] * 3 and result.lengths == [500] * 3 and result.goals is None
    falls = evaluate(lambda obs: 1, "cartpole-200", episodes=3, seed=0)
    assert all(5 < r < 50 for r in falls.returns) and falls.returns == [float(n) for n in falls.lengths]


def test_play_gives_each_seed_one_watched_episode_and_leaves_the_env_open():
    starts, steps, done = [], [], []
    watcher = SimpleNamespace(reset=lambda *start: starts.append(start), step=lambda *step: steps.append(step))
    env = make_plain_env("cartpole-200")
    played = play(env, lambda obs: 1, [3, 3, 4], watcher, progress=done.append)
    assert done == [1, 2, 3] and played.goals == [0, 0, 0] and [seed for _, seed in starts] == [3, 3, 4]
    assert played.returns[:2] == [float(played.lengths[0])] * 2  # the same seed, the same episode
    assert len(steps) == sum(played.lengths) and steps[-1][3]  # ends terminated
    np.testing.assert_array_equal(env.reset(seed=3)[0], starts[0][0])


def test_goal_count_task_counts_goals_and_scores_the_plain_env():
    result = evaluate(follow_velocity, "mountaincar-goals", episodes=3, seed=7)
    assert all(-200 < r < -80 for r in result.returns)
    assert result.returns == [-float(n) for n in result.lengths]  # MountainCar-v0: −1 a step, ends at the flag
    assert len(result.goals) == 3 and min(result.goals) >= 1
    again = evaluate(follow_velocity, "mountaincar-goals", episodes=3, seed=7)
    assert (again.returns, again.goals) == (result.returns, result.goals)
    assert evaluate(follow_velocity, "mountaincar", episodes=1, seed=7).goals is None


@pytest.mark.parametrize("task, rule, features", [("cartpole", balance, 5), ("mountaincar-goals", follow_velocity, 3)])
def test_time_aware_agents_see_the_time_feature(task, rule, features):
    def policy(obs):
        assert len(obs) == features and 0.0 <= obs[-1] <= 1.0
        return rule(obs)

    result = evaluate(policy, task, episodes=1, seed=0, timeout="time-aware")
    assert result.timeout == "time-aware" and result.returns[0] > -200  # goals: the task env too
    assert result.goals is None or result.goals[0] >= 1


def test_bad_arguments_are_config_errors():
    with pytest.raises(ConfigError, match="episodes"):
        evaluate(balance, "cartpole", episodes=0, seed=0)
    with pytest.raises(ConfigError, match="timeout"):
        evaluate(balance, "cartpole", episodes=1, seed=0, timeout="late")
    with pytest.raises(ConfigError, match="unknown task"):
        evaluate(balance, "pong", episodes=1, seed=0)


def test_result_dict_and_summary():
    result = EvalResult("mountaincar-goals", "q", 5, returns=[-100.0, -120.0], lengths=[100, 120], goals=[2, 3])
    out = json.loads(json.dumps(result.to_dict()))
    assert KEYS | {"goals", "mean_goals"} <= set(out)
    assert (out["episodes"], out["mean_return"], out["std_return"], out["mean_goals"]) == (2, -110.0, 10.0, 2.5)
    assert (out["min_return"], out["max_return"]) == (-120.0, -100.0)
    assert "-110.00 ± 10.00" in result.summary() and "[2, 3]" in result.summary()
    assert "goals" not in EvalResult("cartpole", "bc", 0, [500.0], [500]).to_dict()


def test_load_policy_reads_the_run(run_dir, tmp_path):
    greedy, settings = load_policy(run_dir)
    assert (greedy.kind, settings.task, settings.timeout, settings.max_steps) == ("q", "cartpole", "bootstrap", None)
    assert load_policy(run_dir, "bc")[0].kind == "bc"
    assert load_policy(run_dir / "bc_model.keras", task="cartpole-200")[1].task == "cartpole-200"
    with pytest.raises(ModelFileError, match="a 'bc' model, not a 'q' one"):
        load_policy(run_dir / "bc_model.keras", "q")
    with pytest.raises(ModelFileError, match="without bc_model.keras.*'margin' fits no BC model"):
        load_policy(make_run(tmp_path / "margin", expert_loss="margin", bc=False), "bc")


@pytest.mark.parametrize(
    "text, problem",
    [
        ("{not json", "not valid JSON"),
        ('{"task": "cartpole", "colour": 1}', "unknown config field"),
        (json.dumps({**Config.for_task("cartpole").to_dict(), "task": "chess"}), "unknown task"),
        ('{"task": "cartpole"}', r"no \['env_kwargs', .*written by an older version"),
        ("[1]", "JSON object"),
    ],
)
def test_a_broken_config_json_is_named(run_dir, tmp_path, text, problem):
    (tmp_path / "q_network.keras").write_bytes((run_dir / "q_network.keras").read_bytes())
    (tmp_path / "config.json").write_text(text)
    with pytest.raises(ConfigError, match=f"config.json: .*{problem}"):
        load_policy(tmp_path)


PLUG_IN_WITH_A_SIDE_EFFECT = """from pathlib import Path

Path(__file__).with_name("imported.txt").write_text("my_evil_module's top-level code ran")


def term(agent, q, batch):
    return 0.0
"""


def test_evaluate_never_imports_the_module_of_a_runs_expert_loss(tmp_path):
    """Playing a run needs its network and its env: the module its config.json names for the expert
    loss is never imported (its top-level code would run), whichever model is played."""
    code = tmp_path / "code"
    code.mkdir()
    (code / "my_evil_module.py").write_text(PLUG_IN_WITH_A_SIDE_EFFECT)
    run = make_run(tmp_path / "run")
    fields = json.loads((run / "config.json").read_text())
    (run / "config.json").write_text(json.dumps({**fields, "expert_loss": "my_evil_module:term"}))
    for policy in ("q", "bc"):
        done = call("evaluate.py", run, "--episodes", "2", "--policy", policy, path=[code])
        assert (done.returncode, done.stderr) == (0, ""), done.stderr
        assert f"{policy} policy, 2 greedy episodes" in done.stdout
    assert not (code / "imported.txt").exists()


def test_a_model_for_another_action_count_does_not_fit(tmp_path):
    build_q_network(4, 3, (8,)).save(tmp_path / "three.keras")
    with pytest.raises(ModelFileError, match="has 3 outputs, task cartpole has 2 actions"):
        load_policy(tmp_path / "three.keras", task="cartpole")


# --- evaluate.py --------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def cases(run_dir, tmp_path_factory) -> dict[str, list[str]]:
    """{case: evaluate.py's arguments}: two good runs and one of each user error."""
    tmp = tmp_path_factory.mktemp("cli")
    (tmp / "empty").mkdir()
    (tmp / "model.h5").write_bytes(b"not a model")
    (tmp / "corrupt.keras").write_bytes(np.random.default_rng(0).bytes(2000))
    build_q_network(2, 2, (8,)).save(tmp / "two_features.keras")
    (tmp / "bare.keras").write_bytes((run_dir / "q_network.keras").read_bytes())
    cases = {
        "json": [run_dir, "--episodes", "2", "--json", "--out", tmp / "result.json"],
        "bc": [run_dir, "--policy", "bc", "--episodes", "2", "--seed", "3"],
        "missing": [tmp / "nowhere", "--task", "cartpole"],
        "no models": [tmp / "empty", "--task", "cartpole"],
        "not keras": [tmp / "model.h5", "--task", "cartpole"],
        "corrupt": [tmp / "corrupt.keras", "--task", "cartpole"],
        "misfit": [tmp / "two_features.keras", "--task", "cartpole"],
        "no task": [tmp / "bare.keras"],
        "zero episodes": [run_dir, "--episodes", "0"],
    }
    return {name: [str(a) for a in args] for name, args in cases.items()}


@pytest.fixture(scope="module")
def script(cases) -> dict[str, Answer]:
    """{case: what evaluate.py answers}, for the cases a user meets first."""
    return {name: call("evaluate.py", *cases[name]) for name in ("json", "bc", "corrupt")}


def test_script_prints_and_writes_the_json_result(script, cases):
    done = script["json"]
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    assert set(result) >= KEYS and (result["task"], result["policy"], result["episodes"]) == ("cartpole", "q", 2)
    assert json.loads(Path(cases["json"][-1]).read_text()) == result


def test_script_plays_the_bc_model_and_prints_a_summary(script):
    done = script["bc"]
    assert done.returncode == 0, done.stderr
    assert "bc_model.keras" in done.stdout and "bc policy, 2 greedy episodes (seeds 3..4)" in done.stdout


def test_script_error_is_one_line_and_exit_2(script):
    done = script["corrupt"]
    assert (done.returncode, done.stdout) == (2, "") and len(done.stderr.splitlines()) == 1
    assert "corrupt.keras: corrupt" in done.stderr


@pytest.mark.parametrize(
    "case, problem",
    [
        ("missing", "nowhere: no such file"),
        ("no models", "without q_network.keras"),
        ("not keras", "model.h5: not a .keras model file"),
        ("corrupt", "corrupt.keras: corrupt"),
        ("misfit", "expects 2 observation features, task cartpole gives 4"),
        ("no task", "pass --task"),
        ("zero episodes", "--episodes: must be a positive integer"),
    ],
)
def test_cli_errors_are_one_line_and_exit_2(cases, case, problem):
    done = call("evaluate.py", *cases[case])
    assert (done.returncode, done.stdout) == (2, "")
    assert len(done.stderr.splitlines()) == 1 and problem in done.stderr, done.stderr


def test_video_records_one_mp4_per_episode_and_never_overwrites(tmp_path):
    pytest.importorskip("moviepy")
    from dqfd_bc_keras.evaluation import record_video

    policy, settings = load_policy(REPO / "models" / "mountaincar")
    files = record_video(policy, settings.task, tmp_path, episodes=2, seed=0)
    assert [f.name for f in files] == ["mountaincar-episode-0.mp4", "mountaincar-episode-1.mp4"]
    assert all(f.read_bytes()[4:8] == b"ftyp" for f in files)  # an MP4 container
    before = files[0].read_bytes()
    with pytest.raises(ConfigError, match="already holds mountaincar videos"):
        record_video(policy, settings.task, tmp_path, episodes=1, seed=5)
    assert files[0].read_bytes() == before
