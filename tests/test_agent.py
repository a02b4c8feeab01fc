"""The Q-agent: J(Q) assembled as §2 says, target refresh, θ_prior, save/resume, and that
pre-training on an expert's demonstrations teaches the expert's actions."""

import dataclasses

import keras
import numpy as np
import pytest
import tensorflow as tf

import dqfd_bc_keras  # noqa: F401  (first: TensorFlow's threads and log level)
from dqfd_bc_keras.core import expert_terms, reference
from dqfd_bc_keras.core.agent import DQfDAgent, make_agent
from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.core.methods import METHODS, Method, register
from dqfd_bc_keras.errors import ConfigError

EXPERT_LOSSES = tuple(name for name, method in METHODS.items() if method.term is not None)
"""Every registered method with a J_E term."""
Q_LEARNING = tuple(name for name, method in METHODS.items() if method.q_learning)
"""Every registered method that trains a Q-network (all but behavioural cloning alone)."""


def agent_for(loss, demos, bc_models, **overrides):
    """An agent of method `loss` with the shared BC model of its kind of fit (a method registered
    after the `bc_models` fixture was made included)."""
    keras.utils.set_random_seed(0)
    config = Config.for_task("cartpole", expert_loss=loss, **overrides)
    by_fit = {METHODS[name].bc_fit: model for name, model in bc_models.items()}
    return make_agent(config, demos, by_fit.get(config.method.bc_fit))


def agreement(agent, data):
    return float(np.mean(agent.greedy_actions(data.obs).numpy() == data.actions))


@pytest.mark.slow
@pytest.mark.parametrize("loss", EXPERT_LOSSES)
def test_pretraining_imitates_the_expert_on_held_out_states(loss, demos, held_out, bc_models):
    """Within the default pre-training budget k = 1,000 (≈ 0.5 s); measured: ≥ 0.90 already
    after 200–600 updates, depending on the loss and the seed."""
    agent = agent_for(loss, demos, bc_models)
    agent.pretrain(Config.for_task("cartpole").pretrain_steps)
    assert agreement(agent, held_out) >= 0.90


@pytest.mark.slow
def test_without_an_expert_loss_pretraining_does_not_imitate(demos, held_out, bc_models):
    """The control: TD alone on expert-only data cannot tell the actions apart."""
    agent = agent_for("none", demos, bc_models)
    agent.pretrain(Config.for_task("cartpole").pretrain_steps)
    assert agreement(agent, held_out) < 0.85


def batch_of(agent, size=8):
    """A fixed prioritized batch (as numpy), drawn once."""
    return agent.replay.sample(size, agent.beta())


def expert_loss_by_hand(loss, q, b, theta, prior, n) -> float | None:
    """J_E of a built-in method on batch `b` worked out in numpy from Q(s, ·) `q` (the cartpole
    defaults: margin 0.8, T = 1, s_p = 1; N = n); None for a method of another name."""
    w, a, rows = b.weights.numpy(), b.actions.numpy(), np.arange(len(q))
    pi, sigma_sq = b.pi_bc.numpy(), b.sigma_sq.numpy()
    p_q = np.exp(q) / np.exp(q).sum(1, keepdims=True)
    if loss == "margin":
        return np.mean(w * b.is_demo.numpy() * ((q + 0.8 * (np.arange(2) != a[:, None])).max(1) - q[rows, a]))
    if loss == "bc_margin":
        a_e = pi.argmax(1)
        return np.mean(w * ((q + 0.8 * (np.arange(2) != a_e[:, None])).max(1) - q[rows, a_e]))
    if loss == "ce":
        return np.mean(w * -(pi * np.log(p_q)).sum(1))
    if loss == "ce_decay":  # w_E = 0.3, as assert_assembles_the_total_loss sets it
        return 0.3 * np.mean(w * -(pi * np.log(p_q)).sum(1))
    if loss == "qfilter":
        kept = q[rows, pi.argmax(1)] + 0.8 >= q.max(1)
        return np.mean(w * kept * -(pi * np.log(p_q)).sum(1))
    if loss in ("bayes", "bayes_local"):
        return np.mean(w * ((p_q - pi) ** 2).sum(1) / (2 * sigma_sq)) + sum(
            ((t - p) ** 2).sum() for t, p in zip(theta, prior, strict=True)
        ) / (2 * 1.0**2 * n)
    return None


def assert_assembles_the_total_loss(loss, target, demos, bc_models):
    """J = J_DQ + λ1 J_n + λ2 J_E + λ3 J_L2, recomputed from the networks' outputs: J_E is the
    method's declared reference formula on the same batch (reference.py refuses a method that
    declares none), which for a built-in is also J_E worked out here in numpy; 0 without a term
    (each term has its hand-worked test in test_losses.py)."""
    agent = agent_for(loss, demos, bc_models, target=target, lambda_n=0.5, lambda_expert=2.0, lambda_l2=1e-3)
    agent.pretrain(5, steps_per_call=5)  # some non-trivial weights; θ_prior captured
    agent.expert_scale.assign(0.3)  # w_E, which only a method with a decay reads
    for w in agent.target_network.weights:  # a target network different from the online one
        w.assign(w * 0.9)
    b = batch_of(agent)
    q = agent.q_network(b.obs).numpy()
    q_next_t, q_n_t = agent.target_network(b.next_obs).numpy(), agent.target_network(b.n_next_obs).numpy()
    q_next_o, q_n_o = agent.q_network(b.next_obs).numpy(), agent.q_network(b.n_next_obs).numpy()
    theta = [w.numpy() for w in agent.q_network.trainable_weights]
    kernels = [layer.kernel.numpy() for layer in agent.q_network.layers if hasattr(layer, "kernel")]
    prior = [p.numpy() for p in agent.prior_weights]
    w, a, rows = b.weights.numpy(), b.actions.numpy(), np.arange(8)

    def value(q_t, q_o):
        return q_t.max(1) if target == "dqn" else q_t[rows, q_o.argmax(1)]

    y = b.rewards.numpy() + b.discount.numpy() * value(q_next_t, q_next_o)
    y_n = b.n_returns.numpy() + b.n_discount.numpy() * value(q_n_t, q_n_o)
    j_dq = np.mean(w * (y - q[rows, a]) ** 2)
    j_n = np.mean(w * (y_n - q[rows, a]) ** 2)
    formula = reference.expert_reference(METHODS[loss])
    j_e = 0.0 if formula is None else float(formula(agent, tf.constant(q), b))
    by_hand = expert_loss_by_hand(loss, q, b, theta, prior, len(demos))
    if by_hand is not None:
        np.testing.assert_allclose(j_e, by_hand, rtol=1e-4, atol=1e-6, err_msg="the reference formula")
    j_l2 = sum((k**2).sum() for k in kernels)
    expected = j_dq + 0.5 * j_n + 2.0 * j_e + 1e-3 * j_l2

    agent.reset_metrics()
    delta = agent.train_step(b)
    result = {name: float(value) for name, value in agent.losses_so_far().items()}
    np.testing.assert_allclose(result["td"], j_dq, rtol=1e-4, err_msg="td")
    np.testing.assert_allclose(result["n_step"], j_n, rtol=1e-4, err_msg="n_step")
    np.testing.assert_allclose(result["expert"], j_e, rtol=1e-4, atol=1e-6, err_msg="expert")
    np.testing.assert_allclose(result["l2"], j_l2, rtol=1e-4, err_msg="l2")
    np.testing.assert_allclose(result["loss"], expected, rtol=1e-4, err_msg="loss")
    np.testing.assert_allclose(delta, y - q[rows, a], rtol=1e-4, atol=1e-4)


@pytest.mark.parametrize("loss", Q_LEARNING)
@pytest.mark.parametrize("target", ["dqn", "double"])
def test_train_step_assembles_the_total_loss_as_written(loss, target, demos, bc_models):
    """Every registered method that trains a Q-network, a new one included."""
    assert_assembles_the_total_loss(loss, target, demos, bc_models)


def half_ce(agent, q, batch):
    return 0.5 * expert_terms.ce(agent, q, batch)


def test_a_method_whose_term_is_not_its_reference_fails_the_assembly_check(demos, bc_models):
    """The check cannot pass a term that computes something else than its method declares: half of
    ce's cross-entropy declared as the whole of it."""
    register(Method("half_ce", "half of ce's J_E", bc_fit="mle", term=half_ce, reference=reference.ce))
    with pytest.raises(AssertionError, match="expert"):
        assert_assembles_the_total_loss("half_ce", "dqn", demos, bc_models)


def test_a_method_that_declares_no_reference_is_refused_by_the_check(demos, bc_models):
    register(Method("half_ce", "half of ce's J_E", bc_fit="mle", term=half_ce))
    with pytest.raises(ConfigError, match="method 'half_ce' declares no reference formula of its J_E"):
        assert_assembles_the_total_loss("half_ce", "dqn", demos, bc_models)


@pytest.mark.slow
def test_target_network_is_refreshed_every_period(demos, bc_models):
    agent = agent_for("ce", demos, bc_models, target_update_period=4)

    def same():
        return all(
            np.array_equal(t.numpy(), o.numpy())
            for t, o in zip(agent.target_network.weights, agent.q_network.weights, strict=True)
        )

    assert same()
    agent.learn(tf.constant(3))
    assert not same()
    agent.learn(tf.constant(1))  # the 4th gradient step
    assert same() and int(agent.train_steps.numpy()) == 4


@pytest.mark.slow
@pytest.mark.parametrize("center", ["pretrained", "zero"])
def test_prior_center_is_captured_after_pretraining(center, demos, bc_models):
    agent = agent_for("bayes", demos, bc_models, prior_center=center)
    assert all(not p.numpy().any() for p in agent.prior_weights)  # zero during pre-training
    agent.pretrain(10, steps_per_call=10)
    for prior, weight in zip(agent.prior_weights, agent.q_network.trainable_weights, strict=True):
        expected = weight.numpy() if center == "pretrained" else 0.0
        np.testing.assert_array_equal(prior.numpy(), np.broadcast_to(expected, prior.shape))


@pytest.mark.slow
def test_importance_weights_anneal_beta_to_one(demos, bc_models):
    agent = agent_for("margin", demos, bc_models, priority_beta0=0.6, beta_anneal_steps=10)
    np.testing.assert_allclose(float(agent.beta()), 0.6)
    agent.learn(tf.constant(5))
    np.testing.assert_allclose(float(agent.beta()), 0.8)
    agent.learn(tf.constant(10))
    np.testing.assert_allclose(float(agent.beta()), 1.0)


@pytest.mark.slow
def test_store_in_a_graph_adds_agent_rows_whose_bc_view_is_written_when_settled(demos, bc_models):
    """Rows stored one by one hold NaN for π̄_bc and σ² until the replay settles them in one batch
    (as `sample` does first, and by itself every SETTLE_ROWS rows): then each holds its state's view."""
    agent = agent_for("ce", demos, bc_models)
    store = tf.function(agent.store)
    replay = agent.replay
    for t in range(3):
        store(
            tf.constant(demos.obs[t]),
            tf.constant(1),
            tf.constant(1.0),
            tf.constant(demos.next_obs[t]),
            tf.constant(False),
            tf.constant(True),
        )
    rows = replay.demo_capacity + np.arange(3)
    assert int(replay.agent_size.numpy()) == 3 and int(replay.unsettled.numpy()) == 3
    assert np.isnan(tf.gather(replay.table, rows).numpy()[:, replay.SIGMA_SQ]).all()
    replay.sample(8, agent.beta())  # settles first
    table = tf.gather(replay.table, rows).numpy()
    np.testing.assert_allclose(table[:, replay.PI_BC], tf.nn.softmax(bc_models["ce"](demos.obs[:3])), rtol=1e-5)
    np.testing.assert_array_equal(table[:, replay.SIGMA_SQ], agent.config.sigma0_sq)  # the MLE model: σ0²
    assert (table[:, replay.ACTION] == 1).all() and (table[:, replay.TRUNCATED] == 1).all()
    assert (table[:, replay.TERMINATED] == 0).all() and int(replay.unsettled.numpy()) == 0
    for t in range(replay.SETTLE_ROWS):  # no sample comes: the replay settles the batch by itself
        store(*(tf.constant(x[t]) for x in (demos.obs, demos.actions, demos.rewards, demos.next_obs)),
              tf.constant(False), tf.constant(False))  # fmt: skip
    assert int(replay.unsettled.numpy()) == 0
    assert not np.isnan(replay.table[: replay.demo_capacity + 3 + replay.SETTLE_ROWS].numpy()).any()


def test_q_network_round_trips_through_keras_file(demos, bc_models, held_out, tmp_path):
    agent = agent_for("bayes", demos, bc_models)
    agent.pretrain(5, steps_per_call=5)
    path = tmp_path / "q_network.keras"
    agent.q_network.save(path)
    loaded = keras.saving.load_model(path)  # safe mode, no custom objects needed
    np.testing.assert_allclose(loaded(held_out.obs), agent.q_network(held_out.obs), rtol=1e-6, atol=1e-6)


@pytest.mark.slow
def test_checkpoint_restores_optimizer_and_replay_for_an_identical_continuation(demos, bc_models, tmp_path):
    first = agent_for("bayes", demos, bc_models)
    first.learn(tf.constant(20))
    saved = first.checkpoint().write(str(tmp_path / "ckpt"))
    first.learn(tf.constant(10))

    second = agent_for("bayes", demos, bc_models)
    second.checkpoint().read(saved).assert_consumed()
    assert int(second.optimizer.iterations.numpy()) == 20
    second.learn(tf.constant(10))
    for a, b in zip(
        first.q_network.weights + first.optimizer.variables,
        second.q_network.weights + second.optimizer.variables,
        strict=True,
    ):
        np.testing.assert_array_equal(a.numpy(), b.numpy())


@pytest.mark.slow
def test_fused_learning_equals_one_graph_call_per_update(demos, bc_models, tmp_path):
    """`learn(K)` (K updates in one graph call) is K × `learn(1)`: the same weights, Adam state,
    priorities, target network and loss means, bit for bit (K spans a target refresh)."""
    fused, single = agent_for("bayes", demos, bc_models), agent_for("bayes", demos, bc_models)
    # The same start, D_demo's MC-dropout view included (the shared BC model's dropout stream moved on).
    single.checkpoint().read(fused.checkpoint().write(str(tmp_path / "start"))).assert_consumed()
    steps = fused.config.target_update_period + 5
    fused_losses = fused.learn(tf.constant(steps))
    for _ in range(steps):
        single_losses = single.learn(tf.constant(1))
    for a, b in zip(
        fused.q_network.weights + fused.target_network.weights + fused.optimizer.variables,
        single.q_network.weights + single.target_network.weights + single.optimizer.variables,
        strict=True,
    ):
        np.testing.assert_array_equal(a.numpy(), b.numpy())
    np.testing.assert_array_equal(fused.replay.tree.leaf.numpy(), single.replay.tree.leaf.numpy())
    assert {k: float(v) for k, v in fused_losses.items()} == {k: float(v) for k, v in single_losses.items()}


@pytest.mark.parametrize(
    "change, match",
    [
        ({"expert_loss": "kl"}, "expert_loss='kl' is not one of"),
        ({"n_step": 0}, "n_step must be ≥ 1, got 0"),
        ({"gamma": 1.5}, r"gamma must be in \[0, 1\], got 1.5"),
        ({"target": "triple"}, "target='triple' is not one of"),
        ({"td_loss": "l1"}, "td_loss='l1' is not one of"),
        ({"sigma0_sq": 0.0}, "sigma0_sq must be > 0, got 0.0"),
        ({"task": "pong"}, "unknown task 'pong'"),
    ],
)
def test_incompatible_settings_fail_early_naming_the_value(change, match):
    with pytest.raises(ConfigError, match=match):
        dataclasses.replace(Config.for_task("cartpole"), **change)


@pytest.mark.slow
def test_a_batch_larger_than_the_demonstrations_draws_them_with_replacement(demos, bc_models):
    """One short demonstration (a noisy expert's) is still learnt from: rows repeat in a batch."""
    agent = agent_for("margin", demos, bc_models, batch_size=4096)
    batch = agent.replay.sample(4096, agent.beta())
    assert len(np.unique(batch.indices.numpy())) < 2500 and np.all(batch.indices.numpy() < 2500)
    assert np.isfinite(agent.pretrain(1)["loss"])


def test_a_bc_loss_without_a_bc_model_is_refused(demos):
    with pytest.raises(ConfigError, match="expert_loss='ce' needs a fitted BC model"):
        make_agent(Config.for_task("cartpole", expert_loss="ce"), demos, None)
    assert isinstance(make_agent(Config.for_task("cartpole", expert_loss="margin"), demos, None), DQfDAgent)


@pytest.mark.slow
def test_sqil_rewards_demonstrations_1_and_its_own_data_0_in_balanced_batches(demos):
    """SQIL (Reddy et al. 2020) on our DQN: the env's rewards are replaced, half of each batch is
    demonstrations, sampled uniformly (no priorities), and no expert loss is added."""
    keras.utils.set_random_seed(0)
    agent = make_agent(Config.for_task("cartpole", expert_loss="sqil"), demos, None)
    replay = agent.replay
    assert agent.bc_model is None and np.all(replay.table[:2500, replay.REWARD].numpy() == 1.0)
    early = replay.sample_balanced(64)  # D_replay empty: every row a demonstration
    assert np.all(early.is_demo.numpy() == 1.0) and np.all(early.weights.numpy() == 1.0)
    for t in range(100):
        agent.store(
            tf.constant(demos.obs[t]),
            tf.constant(1),
            tf.constant(1.0),
            tf.constant(demos.next_obs[t]),
            tf.constant(False),
            tf.constant(False),
        )
    agent_rows = replay.demo_capacity + np.arange(100)
    assert np.all(tf.gather(replay.table, agent_rows)[:, replay.REWARD].numpy() == 0.0)
    batch = replay.sample_balanced(64)
    np.testing.assert_array_equal(batch.is_demo.numpy(), [1.0] * 32 + [0.0] * 32)
    assert set(batch.indices.numpy()[32:]) <= set(agent_rows) and np.all(batch.rewards.numpy()[32:] == 0.0)
    priorities = replay.tree.leaf.numpy().copy()
    losses = {k: float(v) for k, v in agent.learn(5).items()}
    assert losses["expert"] == 0.0 and np.isfinite(losses["loss"])
    np.testing.assert_array_equal(replay.tree.leaf.numpy(), priorities)  # SQIL writes no priorities
