"""Tests for the scripted demonstrators in dqfd_bc_keras.demos.experts."""

import numpy as np
import pytest

from dqfd_bc_keras.choices import EXPERT_NAMES
from dqfd_bc_keras.commands.experts import main
from dqfd_bc_keras.demos.experts import expert_returns, make_expert
from dqfd_bc_keras.envs.make import task_spaces
from dqfd_bc_keras.tasks import TASKS, families, family_preset

FAMILIES = families()
"""The package's families (read when the module is imported, before a test registers one of its own)."""
EXPERTS = {family: family_preset(family).experts for family in FAMILIES}
"""Each family's scripted experts by name, as its first preset declares them."""


def test_cartpole_strong_balances_and_imperfect_is_clearly_worse() -> None:
    strong = expert_returns("cartpole", "strong", episodes=5, seed=0)
    imperfect = expert_returns("cartpole", "imperfect", episodes=5, seed=0)
    assert strong.dtype == np.float64 and strong.shape == (5,)
    np.testing.assert_array_equal(strong, 500.0)
    assert imperfect.mean() < 400.0


def test_mountaincar_strong_solves_and_imperfect_is_worse() -> None:
    strong = expert_returns("mountaincar", "strong", episodes=10, seed=0)
    imperfect = expert_returns("mountaincar", "imperfect", episodes=10, seed=0)
    assert strong.mean() >= -110.0
    assert imperfect.mean() < strong.mean() - 5.0
    assert imperfect.mean() < -110.0


@pytest.mark.slow
@pytest.mark.parametrize(
    ("family", "solved", "strong_band", "imperfect_band"),
    [
        ("acrobot", -100.0, (-90.0, -70.0), (-130.0, -100.0)),
        ("lunarlander", 200.0, (200.0, 280.0), (50.0, 200.0)),
    ],
)
def test_new_experts_quality_bands_over_100_episodes(family, solved, strong_band, imperfect_band) -> None:
    """The bands around the figures in the rules' docstrings (100 episodes, seeds 0–99): the strong
    expert solves the env on average, the imperfect one does not."""
    strong = expert_returns(family, "strong", episodes=100, seed=0)
    imperfect = expert_returns(family, "imperfect", episodes=100, seed=0)
    assert strong_band[0] <= strong.mean() <= strong_band[1] and strong.mean() >= solved
    assert imperfect_band[0] <= imperfect.mean() < imperfect_band[1] and imperfect.mean() < solved


def test_lunarlander_strong_is_gymnasiums_heuristic() -> None:
    pytest.importorskip("Box2D")
    from types import SimpleNamespace

    from gymnasium.envs.box2d.lunar_lander import heuristic

    env = SimpleNamespace(unwrapped=SimpleNamespace(continuous=False))
    rng = np.random.default_rng(0)
    for _ in range(2000):
        obs = rng.normal(size=8)
        obs[6:] = rng.random(2) < 0.2  # legs touching
        assert TASKS["lunarlander"].experts["strong"](obs) == heuristic(env, obs)


OBS_DIM = {
    family: spaces.obs_dim for family in FAMILIES if (spaces := task_spaces(family_preset(family).name)).layout.flat
}
"""The families observed as vectors, by width, read from their envs; the frame families' experts
(MinAtar's) are tested in test_minatar_tasks.py."""


def test_every_family_of_the_package_has_a_strong_and_an_imperfect_expert() -> None:
    """Config's default `expert`, the command lines' help and the lab's suites name them (docs/EXTENDING.md's
    rules); a user's family needs neither (test_registries.py: a preset whose only expert is `lean`)."""
    assert all(set(EXPERT_NAMES) <= set(experts) for experts in EXPERTS.values())


def test_the_vector_families_are_told_from_the_frame_ones_by_their_observations() -> None:
    assert {family: OBS_DIM.get(family) for family in ("cartpole", "mountaincar", "acrobot", "lunarlander")} == {
        "cartpole": 4,
        "mountaincar": 2,
        "acrobot": 6,
        "lunarlander": 8,
    }
    assert {"minatar-breakout", "minatar-freeway"} <= set(FAMILIES) - set(OBS_DIM)


@pytest.mark.parametrize(("family", "name"), [(family, name) for family in OBS_DIM for name in EXPERTS[family]])
def test_epsilon_zero_equals_rule_and_ignores_extra_feature(family: str, name: str) -> None:
    rng = np.random.default_rng(1)
    expert = make_expert(family, name, epsilon=0.0, seed=0)
    width = OBS_DIM[family]
    for _ in range(50):
        obs = rng.uniform(-0.5, 0.5, size=width).astype(np.float32)
        action = expert(obs)
        assert type(action) is int
        assert action == EXPERTS[family][name](obs)
        assert expert(np.append(obs, np.float32(0.3))) == action


@pytest.mark.parametrize(("family", "n_actions"), [("cartpole", 2), ("mountaincar", 3)])
def test_epsilon_one_is_uniform_random(family: str, n_actions: int) -> None:
    expert = make_expert(family, "strong", epsilon=1.0, seed=0)
    obs = np.zeros(4 if family == "cartpole" else 2, dtype=np.float32)
    counts = np.bincount([expert(obs) for _ in range(3000)], minlength=n_actions)
    assert counts.shape == (n_actions,)
    np.testing.assert_allclose(counts / counts.sum(), 1.0 / n_actions, atol=0.05)


def test_same_seed_gives_same_actions_and_returns() -> None:
    obs = np.array([0.01, -0.02, 0.03, 0.04], dtype=np.float32)
    a, b = (make_expert("cartpole", "imperfect", 0.5, seed=7) for _ in range(2))
    seq_a = [a(obs) for _ in range(200)]
    assert seq_a == [b(obs) for _ in range(200)]
    assert len(set(seq_a)) == 2
    np.testing.assert_array_equal(
        expert_returns("mountaincar", "strong", episodes=2, seed=3, epsilon=0.2),
        expert_returns("mountaincar", "strong", episodes=2, seed=3, epsilon=0.2),
    )


@pytest.mark.parametrize(
    ("family", "name", "epsilon", "match"),
    [
        ("pong", "strong", 0.0, r"'pong'.*cartpole, mountaincar, acrobot, lunarlander"),
        ("cartpole", "perfect", 0.0, r"'perfect'.*strong, imperfect"),
        ("cartpole", "strong", 1.5, r"1\.5"),
        ("mountaincar", "strong", -0.1, r"-0\.1"),
    ],
)
def test_bad_input_raises_value_error(family: str, name: str, epsilon: float, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        make_expert(family, name, epsilon)
    with pytest.raises(ValueError, match=match):
        expert_returns(family, name, episodes=1, epsilon=epsilon)


@pytest.mark.slow
def test_cli_prints_table(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--episodes", "2"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[0].startswith("| family | expert | env id |")
    assert len(lines) == 2 + sum(len(experts) for experts in EXPERTS.values())
    assert any("| cartpole | strong | CartPole-v1 | 2 | 500.00" in line for line in lines)
    assert any("| mountaincar | imperfect | MountainCar-v0 | 2 |" in line for line in lines)


def test_minigrids_teachers_take_the_short_and_the_long_way_round_the_room() -> None:
    """Empty-8x8, from the top-left corner facing east to the goal in the bottom-right one (a 6×6 floor):
    turning right at walls is 5 forward, a turn, 5 forward = 11 steps; turning left goes round three
    walls, 5 + 2 turns + 5 + 1 + 5 + 1 + 5 = 24. MiniGrid pays 1 − 0.9·steps/256 at the goal."""
    strong = expert_returns("minigrid-empty", "strong", episodes=3, seed=0)
    imperfect = expert_returns("minigrid-empty", "imperfect", episodes=3, seed=0)
    np.testing.assert_allclose(strong, 1 - 0.9 * 11 / 256)
    np.testing.assert_allclose(imperfect, 1 - 0.9 * 24 / 256)


def test_a_preset_whose_package_is_missing_says_how_to_install_it(tmp_path) -> None:
    """train.py as a user runs it on a machine without minigrid: one line and exit 2, nothing written."""
    import subprocess
    import sys

    from helpers import ENV, REPO

    code = (
        "import runpy, sys; sys.modules['minigrid'] = None; "
        f"sys.argv = ['train.py', '--task', 'minigrid-empty', '--quick', '--out', {str(tmp_path / 'run')!r}]; "
        "runpy.run_path('train.py', run_name='__main__')"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, env=ENV, timeout=120)
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip().splitlines()[-1] == (
        "error: task 'minigrid-empty' needs the minigrid package: pip install minigrid"
    )
    assert not (tmp_path / "run").exists()
