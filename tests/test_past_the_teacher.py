"""Issue W: the methods that let the agent leave its teacher where its own Q-values say it knows
better (qfilter, ce_decay, bayes_local; ALGORITHM.md §8), each worked out by hand, the weights a run
logs for them, and the MiniGrid rule that training used to unlearn (docs/TASKS.md)."""

import json

import gymnasium as gym
import numpy as np
import pytest
import tensorflow as tf
from helpers import call

import dqfd_bc_keras  # noqa: F401  (first: TensorFlow's threads and log level)
from dqfd_bc_keras import DQfD
from dqfd_bc_keras.core import expert_terms, reference
from dqfd_bc_keras.core.agent import make_agent
from dqfd_bc_keras.core.bc import build_bc_model
from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.core.expert_terms import next_expert_scale
from dqfd_bc_keras.core.methods import METHODS
from dqfd_bc_keras.core.networks import normalization
from dqfd_bc_keras.core.uncertainty import VarianceEstimator


class Agent:
    """What a term reads of the agent (methods.TermAgent), with made-up values."""

    def __init__(self, expert_scale=1.0, margin=0.8):
        self.config = Config.for_task("cartpole", margin=margin)
        self.expert_scale = expert_scale


class Rows:
    """A batch of two rows (methods.TermBatch)."""

    actions = tf.constant([1, 0])
    is_demo = tf.constant([1.0, 0.0])
    weights = tf.constant([1.0, 0.5])
    pi_bc = tf.constant([[0.9, 0.1], [0.8, 0.2]])
    sigma_sq = tf.constant([0.5, 2.0])


Q = tf.constant([[1.0, 2.0], [3.0, 0.0]])
"""Row 1 prefers action 1, row 2 action 0; the teacher (argmax π_bc) takes action 0 in both."""
CE_ROW_2 = 0.8 * np.log(1 + np.exp(-3.0)) + 0.2 * (3.0 + np.log(1 + np.exp(-3.0)))
"""H(π_bc, softmax(Q)) on row 2: −0.8·log p(0) − 0.2·log p(1), p = softmax([3, 0])."""


def test_the_q_filter_keeps_only_the_rows_where_the_agent_does_not_prefer_another_action_by_the_margin():
    """l = 0.8. Row 1: Q(s, a_bc = 0) + l = 1.8 < max 2, dropped. Row 2: 3 + l ≥ 3, kept."""
    np.testing.assert_array_equal(expert_terms.qfilter_weight(Agent(), Q, Rows), [0.0, 1.0])
    expected = (0.0 + 0.5 * CE_ROW_2) / 2  # the mean over the batch of w_i·kept_i·H_i
    assert float(expert_terms.qfilter(Agent(), Q, Rows)) == pytest.approx(expected, rel=1e-6)
    assert float(reference.qfilter(Agent(), Q, Rows)) == pytest.approx(expected, rel=1e-6)
    close = tf.constant([[1.5, 2.0], [3.0, 0.0]])  # row 1: the agent prefers action 1 by 0.5 < l: kept
    np.testing.assert_array_equal(expert_terms.qfilter_weight(Agent(), close, Rows), [1.0, 1.0])
    # l = 0, Nair's filter read for a DQN: kept only where a_bc is greedy (a tie counts)
    np.testing.assert_array_equal(expert_terms.qfilter_weight(Agent(margin=0.0), close, Rows), [0.0, 1.0])
    ties = tf.constant([[2.0, 2.0], [3.0, 0.0]])
    np.testing.assert_array_equal(expert_terms.qfilter_weight(Agent(margin=0.0), ties, Rows), [1.0, 1.0])


def test_the_q_filter_trains_nothing_on_a_dropped_row_and_not_through_the_filter():
    q = tf.Variable(Q)
    with tf.GradientTape() as tape:
        loss = expert_terms.qfilter(Agent(), q, Rows)
    grad = tape.gradient(loss, q).numpy()
    np.testing.assert_array_equal(grad[0], [0.0, 0.0])  # row 1 dropped: no imitation there
    p = np.exp([3.0, 0.0]) / np.exp([3.0, 0.0]).sum()
    np.testing.assert_allclose(grad[1], 0.5 * (p - [0.8, 0.2]) / 2, rtol=1e-5)  # ce's gradient, w = 0.5, mean of 2


def test_ce_decay_is_ce_weighted_by_w_e():
    ce = float(expert_terms.ce(Agent(), Q, Rows))
    assert float(expert_terms.ce_decay(Agent(expert_scale=0.3), Q, Rows)) == pytest.approx(0.3 * ce, rel=1e-6)
    assert float(reference.ce_decay(Agent(expert_scale=0.3), Q, Rows)) == pytest.approx(0.3 * ce, rel=1e-6)
    np.testing.assert_allclose(expert_terms.decay_weight(Agent(expert_scale=0.3), Q, Rows), [0.3, 0.3])


def test_w_e_decays_while_the_agent_is_at_the_teachers_level_and_comes_back_when_it_falls():
    """Teacher 10, W = 2, ρ = 0.5, by hand: nothing before two episodes; averages 12.5 and 15 ≥ 10
    halve it twice; 5 and 0 below 10 double it back, never above 1."""
    returns, scales, scale = [5.0, 20.0, 10.0, 0.0, 0.0, 0.0], [], 1.0
    for t in range(1, len(returns) + 1):
        scale = next_expert_scale(scale, returns[:t], teacher=10.0, window=2, decay=0.5)
        scales.append(scale)
    assert scales == [1.0, 0.5, 0.25, 0.5, 1.0, 1.0]
    assert METHODS["ce_decay"].decay == 0.9 and METHODS["ce"].decay is None


def test_local_sigma_sq_divides_sigma0_sq_by_what_is_left_of_the_confidence():
    """σ² = σ0²/(1 − v/v_max), v_max = 1/4 with two actions: v = 0 → σ0²; v = 1/8 → 2σ0²; v = v_max
    → σ0²/1e-6 (finite). The paper's form adds: σ0² + v."""
    v = tf.constant([0.0, 0.125, 0.25])
    local = VarianceEstimator("local", sigma0_sq=0.5).sigma_sq(v, n_actions=2).numpy()
    np.testing.assert_allclose(local, [0.5, 1.0, 0.5e6], rtol=1e-5)
    np.testing.assert_allclose(expert_terms.likelihood_weight(None, Q, Rows), [1.0, 0.25])
    additive = VarianceEstimator("distance", sigma0_sq=0.5).sigma_sq(v, n_actions=2).numpy()
    np.testing.assert_allclose(additive, [0.5, 0.625, 0.75], rtol=1e-6)


def test_bayes_local_imitates_fully_on_the_demonstrations_and_not_far_from_them(demos):
    """Its BC model measures the distance to the nearest demonstrated state (ℓ = one standard
    deviation): weight 1/(2σ²) = 1/(2σ0²) = 1 on D_demo, e^(−d²) at d standard deviations."""
    config = Config.for_task("cartpole", expert_loss="bayes_local")
    model = build_bc_model(config, 4, 2, demos.obs_scale())
    model.fit_demos(demos.obs, demos.actions, epochs=2, seed=0)
    assert model.estimator.uncertainty == "local"
    _, on_demos = model.predictive(tf.constant(demos.obs[:100]))
    assert np.median(0.5 / on_demos.numpy()) == pytest.approx(1.0)
    mean, std = demos.obs_scale()
    for d in (1.0, 2.0, 4.0):
        state = (mean + d * std * np.array([1.0, 0.0, 0.0, 0.0], np.float32))[None]
        _, sigma_sq = model.predictive(tf.constant(state.astype(np.float32)))
        nearest = float(model.distance.nearest_distance(model.distance_view(tf.constant(state)))[0])
        assert 0.5 / float(sigma_sq[0]) == pytest.approx(max(np.exp(-(nearest**2)), 1e-6), rel=1e-4)
    _, far = model.predictive(tf.constant((mean + 10.0 * std)[None].astype(np.float32)))  # 20 std away
    assert 0.5 / float(far[0]) < 1e-3


def test_the_logged_q_filter_weight_is_the_share_of_rows_it_keeps(demos, bc_models):
    config = Config.for_task("cartpole", expert_loss="qfilter", margin=0.1)
    agent = make_agent(config, demos, bc_models["qfilter"])
    agent.pretrain(20, steps_per_call=20)
    on_demos, on_agents = agent.imitation_weights()
    assert on_agents is None  # no agent data yet
    read = np.arange(1024) * len(demos.obs) // 1024  # 2,500 rows: 1,024 evenly spaced ones are read
    q = agent.q_network(demos.obs[read]).numpy()
    pi_bc, _ = agent.expert_view(tf.constant(demos.obs[read]))
    kept = q[np.arange(len(q)), pi_bc.numpy().argmax(1)] + 0.1 >= q.max(1)
    assert 0 < kept.mean() < 1 and on_demos == pytest.approx(kept.mean(), abs=1e-6)


@pytest.mark.parametrize("loss", ["qfilter", "ce_decay", "bayes_local"])
def test_train_py_logs_each_methods_weight_on_the_agents_states(tmp_path, loss):
    """Through the command: every episode's row holds the weight on D_demo's rows and on the agent's;
    the checkpoint's state.json keeps w_E, the weight of the last row for ce_decay."""
    import csv

    out = tmp_path / loss
    done = call("train.py", "--task", "cartpole", "--quick", "--expert-loss", loss, "--out", out)
    assert done.returncode == 0, done.stderr
    rows = list(csv.DictReader((out / "metrics.csv").open()))
    on, off = ([float(r[f"imitation_weight_{kind}"]) for r in rows] for kind in ("demo", "agent"))
    assert all(0.0 <= w <= 1.0 + 1e-6 for w in on + off), (on, off)
    if loss == "ce_decay":
        state = json.loads(next((out / "checkpoints").glob("ckpt-*/state.json")).read_text())
        assert on == off and state["expert_scale"] == pytest.approx(off[-1])
    if loss == "bayes_local":
        assert on == pytest.approx([1.0] * len(on), rel=1e-4) and min(off) < 1.0


def test_a_feature_the_demonstrations_never_vary_is_centred_not_scaled():
    """std 0 → 1 (scikit-learn's StandardScaler does the same); a tiny std is still floored at 1e-3."""
    layer = normalization([1.0, 2.0, 0.0], [0.0, 0.5, 1e-5])
    np.testing.assert_allclose(layer(np.array([[3.0, 3.0, 0.01]], np.float32)), [[2.0, 2.0, 10.0]], rtol=1e-5)


AHEAD = 4 + (3 * 7 + 5) * 3
"""MiniGrid's flattened observation: the direction's one-hot (4), then the 7×7×3 view; the cell
ahead of the agent is the view's (x = 3, y = 5), its object index first (2: a wall)."""


def walk_to_the_goal(obs):
    """Forward until a wall is ahead, then turn right: in Empty-5x5 the goal in 5 steps (0.91)."""
    return 1 if obs[AHEAD] == 2 else 2


@pytest.mark.slow
@pytest.mark.parametrize(("loss", "seed"), [("ce", 0), ("ce", 1), ("ce", 2), ("bayes", 0)])
def test_a_perfect_rule_on_minigrid_is_kept_after_3000_steps(loss, seed):
    """Issue W, as a user wrote it: five episodes of a rule that walks to the goal, 3,000 steps.
    Before the fix, 135 of the view's 151 features, constant along the rule's path, were scaled by
    1/1e-3: every greedy episode timed out (0.00) in these four runs; now ≥ 0.8 of the rule's 0.91."""
    pytest.importorskip("minigrid")
    model = DQfD(
        gym.make("minigrid:MiniGrid-Empty-5x5-v0", max_steps=50),
        walk_to_the_goal,
        max_steps=50,
        demo_episodes=5,
        expert_loss=loss,
        seed=seed,
    )
    assert np.mean(model.dataset.meta.episode_returns) == pytest.approx(0.91, abs=1e-6)
    model.learn(3000)
    assert model.evaluate(10).mean_return >= 0.8 * 0.91
