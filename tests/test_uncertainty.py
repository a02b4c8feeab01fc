"""The three estimators of σ²(s) − σ0² (uncertainty.py): values on constructed inputs,
the ensemble's bootstrap, save/load round trips, and their use by the agent."""

import keras
import numpy as np
import pytest
import tensorflow as tf
from helpers import call

import dqfd_bc_keras  # noqa: F401  (first: TensorFlow's threads and log level)
from dqfd_bc_keras.core.agent import make_agent
from dqfd_bc_keras.core.bc import BCModel, build_bc_model
from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.core.uncertainty import (
    NearestDemoVariance,
    bootstrap_counts,
    max_policy_variance,
    policy_variance,
    reference_rows,
)
from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.evaluation import GreedyPolicy


@pytest.fixture(scope="module")
def fitted(demos) -> dict[str, BCModel]:
    """{estimator: the bayes BC model with that estimator, fitted on the strong expert's demos}."""
    models = {}
    for uncertainty in ("ensemble", "distance"):
        keras.utils.set_random_seed(0)
        config = Config.for_task("cartpole", uncertainty=uncertainty)
        models[uncertainty] = build_bc_model(config, 4, 2, demos.obs_scale())
        models[uncertainty].fit_demos(demos.obs, demos.actions, epochs=config.bc_epochs, seed=3)
    return models


def test_policy_variance_by_hand_and_its_largest_value():
    certain_apart = tf.constant([[[1.0, 0.0]], [[0.0, 1.0]]])  # (K=2, B=1, A=2)
    np.testing.assert_allclose(policy_variance(certain_apart), [0.25])  # Var = ¼ for both actions
    assert max_policy_variance(2) == 0.25
    spread = tf.constant(np.eye(3, dtype=np.float32)[:, None, :])  # three members, one action each
    np.testing.assert_allclose(policy_variance(spread), [max_policy_variance(3)], rtol=1e-6)
    np.testing.assert_allclose(max_policy_variance(3), 2 / 9)
    agree = tf.constant([[[0.3, 0.7]]] * 4)
    np.testing.assert_allclose(policy_variance(agree), [0.0], atol=1e-7)


def test_bootstrap_counts_are_resamples_of_size_n_fixed_by_the_seed():
    counts = bootstrap_counts(5, 1000, tf.constant(4, tf.int64)).numpy()
    assert counts.shape == (5, 1000) and np.all(counts.sum(axis=1) == 1000)
    assert np.all(counts >= 0) and np.all(counts == np.round(counts))
    # About 1 − 1/e ≈ 63% of the pairs are drawn at least once, and the members differ.
    assert np.all(np.abs((counts > 0).mean(axis=1) - (1 - np.exp(-1))) < 0.05)
    assert not np.array_equal(counts[0], counts[1])
    np.testing.assert_array_equal(counts, bootstrap_counts(5, 1000, tf.constant(4, tf.int64)).numpy())


def test_ensemble_variance_is_zero_when_the_members_agree(demos, fitted):
    model = BCModel.from_config(fitted["ensemble"].get_config())
    model.set_weights(fitted["ensemble"].get_weights())
    for layer in model.stack:  # every member becomes a copy of member 0
        layer.kernel.assign(tf.repeat(layer.kernel[:1], model.estimator.members, axis=0))
        layer.bias.assign(tf.repeat(layer.bias[:1], model.estimator.members, axis=0))
    obs = tf.constant(demos.obs[:100])
    pi_bar, sigma_sq = model.predictive(obs)
    np.testing.assert_allclose(sigma_sq, np.full(100, 0.5), atol=1e-7)
    np.testing.assert_allclose(pi_bar, tf.nn.softmax(model.member_logits(obs)[0]), rtol=1e-5)


def test_ensemble_members_differ_and_their_mean_imitates(demos, held_out, fitted):
    model = fitted["ensemble"]
    assert model.estimator.members == 5 and model.network.dropout == 0.0 and model.network.map_fit
    logits = model.member_logits(tf.constant(held_out.obs)).numpy()
    assert logits.shape == (5, len(held_out.obs), 2) and not np.allclose(logits[0], logits[1])
    pi_bar, sigma_sq = model.predictive(tf.constant(held_out.obs))
    assert np.mean(np.argmax(pi_bar, axis=1) == held_out.actions) >= 0.95
    probs = tf.nn.softmax(logits).numpy()  # σ² − σ0² = mean_a Var_k, by hand
    np.testing.assert_allclose(sigma_sq - 0.5, probs.var(axis=0).mean(axis=1), rtol=1e-4, atol=1e-7)
    np.testing.assert_allclose(np.exp(model(held_out.obs)), probs.mean(axis=0), rtol=1e-4, atol=1e-8)


def test_distance_variance_by_hand_and_monotone_in_the_distance():
    layer = NearestDemoVariance(obs_dim=2, n_actions=2, capacity=8)
    layer.set_references(np.array([[0.0, 0.0], [10.0, 0.0]], np.float32))
    d = np.array([0.0, 0.25, 0.5, 1.0, 2.0, 3.0, 5.0], np.float32)
    z = np.stack([np.zeros_like(d), d], axis=1)  # straight up from the reference at the origin
    variance = layer(tf.constant(z)).numpy()
    np.testing.assert_allclose(variance, 0.25 * (1 - np.exp(-(d**2))), rtol=1e-5, atol=1e-7)
    assert variance[0] == 0.0 and np.all(np.diff(variance) > 0) and variance[-1] == pytest.approx(0.25)
    # The nearest reference counts: next to the second one the variance is 0 again.
    assert float(layer(tf.constant([[10.0, 0.0]]))[0]) == pytest.approx(0.0, abs=1e-6)


def test_distance_ignores_unused_reference_slots_and_subsamples_past_capacity():
    layer = NearestDemoVariance(obs_dim=2, n_actions=2, capacity=4)
    layer.set_references(np.array([[3.0, 4.0]], np.float32))  # slots 1–3 stay at zero
    np.testing.assert_allclose(layer.nearest_distance(tf.zeros([1, 2])), [5.0], rtol=1e-6)
    many = np.arange(20, dtype=np.float32).reshape(10, 2)
    rows = reference_rows(len(many), layer.capacity, seed=1)
    assert len(rows) == 4 and len(set(rows)) == 4 and np.all(np.diff(rows) > 0)
    np.testing.assert_array_equal(reference_rows(3, 4, seed=1), [0, 1, 2])  # all of them, in order
    layer.set_references(many[rows])
    assert float(layer.count) == 4 and np.array_equal(layer.references.numpy(), many[rows])


def test_distance_on_frames_takes_the_median_nearest_neighbour_distance_as_its_length():
    layer = NearestDemoVariance(obs_dim=2, n_actions=2, capacity=8, length=None)
    # Nearest-neighbour distances: 1, 1, 2 (the third is 2 from the second): median 1 → ℓ² = 1.
    layer.set_references(np.array([[0.0, 0.0], [1.0, 0.0], [3.0, 0.0]], np.float32))
    assert float(layer.length_sq) == pytest.approx(1.0)
    layer.set_references(np.array([[0.0, 0.0], [2.0, 0.0], [6.0, 0.0]], np.float32))  # 2, 2, 4: ℓ² = 4
    assert float(layer.length_sq) == pytest.approx(4.0)
    z = tf.constant([[0.0, 2.0]])
    assert float(layer(z)[0]) == pytest.approx(0.25 * (1 - np.exp(-4.0 / 4.0)), rel=1e-5)
    layer.set_references(np.zeros((3, 2), np.float32))  # all duplicates: no scale to read, ℓ² = 1
    assert float(layer.length_sq) == 1.0


def test_distance_estimator_is_standardised_by_the_demonstrations(demos, held_out, fitted):
    model = fitted["distance"]
    assert model.network.dropout > 0 and model.estimator.uncertainty == "distance"
    pi_bar, sigma_sq = model.predictive(tf.constant(demos.obs[:200]))
    # Demonstrated states are references (2,500 > 2,048 of them are kept, so most are exactly 0).
    assert np.median(sigma_sq - 0.5) == 0.0
    np.testing.assert_allclose(pi_bar, tf.nn.softmax(model(demos.obs[:200])), rtol=1e-5)
    mean, std = demos.obs_scale()
    far = mean + 4.0 * std * np.array([1.0, 0.0, 0.0, 0.0], np.float32)  # 4 std along one axis
    _, far_sigma = model.predictive(tf.constant(far[None].astype(np.float32)))
    assert float(far_sigma[0]) - 0.5 > 0.2


@pytest.mark.parametrize("uncertainty", ["ensemble", "distance"])
def test_estimators_save_and_load_with_the_bc_model(tmp_path, fitted, held_out, uncertainty):
    model = fitted[uncertainty]
    model.save(tmp_path / "bc.keras")
    loaded = keras.saving.load_model(tmp_path / "bc.keras")
    obs = tf.constant(held_out.obs[:64])
    for original, restored in zip(model.predictive(obs), loaded.predictive(obs), strict=True):
        np.testing.assert_allclose(restored, original, rtol=1e-6)
    assert loaded.estimator == model.estimator and loaded.estimator.uncertainty == uncertainty
    policy = GreedyPolicy.from_model(loaded)  # what evaluate.py --policy bc plays
    np.testing.assert_allclose(policy.values(held_out.obs[:64]), loaded(obs), rtol=1e-4, atol=1e-5)
    assert policy(held_out.obs[0]) == int(np.argmax(loaded(obs[:1])[0]))


def test_the_agent_stores_the_estimators_variance_and_recomputes_it_after_a_refit(demos, held_out, fitted):
    config = Config.for_task("cartpole", uncertainty="distance")
    keras.utils.set_random_seed(0)
    bc = build_bc_model(config, 4, 2, demos.obs_scale())
    bc.fit_demos(demos.obs, demos.actions, epochs=2)
    agent = make_agent(config, demos, bc)
    rows = agent.replay.stored_indices()
    stored = lambda: tf.gather(agent.replay.table, rows)[:, agent.replay.SIGMA_SQ].numpy()
    np.testing.assert_allclose(stored(), bc.predictive(tf.constant(demos.obs))[1], rtol=1e-6)
    bc.fit_demos(held_out.obs, held_out.actions, epochs=1)  # other references: σ² of D_demo rises
    agent.refresh_expert_targets()
    after = bc.predictive(tf.constant(demos.obs))[1].numpy()
    np.testing.assert_allclose(stored(), after, rtol=1e-6)
    assert after.mean() > 0.5


@pytest.mark.parametrize(
    "change, match",
    [
        ({"uncertainty": "laplace"}, "uncertainty='laplace' is not one of"),
        (
            {"uncertainty": "ensemble", "mc_dropout": False},
            "mc_dropout must be True when uncertainty is not mc_dropout",
        ),
        ({"uncertainty": "ensemble", "ensemble_members": 1}, "ensemble_members must be ≥ 2"),
    ],
)
def test_bad_estimator_settings_are_refused(change, match):
    with pytest.raises(ConfigError, match=match):
        Config.for_task("cartpole", **change)


def test_only_the_bayes_loss_uses_the_estimator(demos):
    ce = build_bc_model(Config.for_task("cartpole", expert_loss="ce", uncertainty="ensemble"), 4, 2, demos.obs_scale())
    assert ce.estimator.uncertainty == "mc_dropout" and ce.estimator.members == 1 and not ce.network.map_fit


@pytest.mark.parametrize("uncertainty", ["ensemble", "distance"])
def test_a_run_checkpoint_restores_the_estimator_for_a_resume(demos, held_out, tmp_path, uncertainty):
    """A resumed run rebuilds π_bc unfitted and reads its variables (members, references) back."""
    config = Config.for_task("cartpole", uncertainty=uncertainty)

    def agent(fit: bool):
        keras.utils.set_random_seed(1 if fit else 2)
        bc = build_bc_model(config, 4, 2, demos.obs_scale())
        if fit:
            bc.fit_demos(demos.obs, demos.actions, epochs=2, seed=5)
        else:
            bc.optimizer.build(bc.trainable_variables)
        return make_agent(config, demos, bc)

    saved, resumed = agent(fit=True), agent(fit=False)
    obs = tf.constant(held_out.obs[:64])
    assert not np.allclose(saved.bc_model.predictive(obs)[1], resumed.bc_model.predictive(obs)[1])
    resumed.checkpoint().read(saved.checkpoint().write(str(tmp_path / "ckpt"))).expect_partial()
    for original, restored in zip(saved.bc_model.predictive(obs), resumed.bc_model.predictive(obs), strict=True):
        np.testing.assert_allclose(restored, original, rtol=1e-6)


@pytest.mark.slow
def test_a_run_logs_the_imitation_weight_on_and_off_the_demonstrations(tmp_path, demos, bc_models):
    """train.py with the distance estimator at σ0² = 0.1: on D_demo's states (its references, d = 0)
    σ² = σ0², so the weight 1/(2σ²) is 1/(2·0.1) = 5; on the agent's own states it lies between
    1/(2(σ0² + v)) with v = 1/4 (CartPole's largest policy variance), 1.43, and 5, and below 5 once
    the agent leaves the demonstrations. ce reads no σ²: no weight (its columns are empty)."""
    import csv

    done = call(
        "train.py",
        "--task",
        "cartpole",
        "--quick",
        "--expert-loss",
        "bayes",
        "--set",
        "uncertainty=distance",
        "--set",
        "sigma0_sq=0.1",
        "--set",
        "dynamic_demos=off",
        "--out",
        tmp_path / "bayes",
    )
    assert done.returncode == 0, done.stderr
    rows = list(csv.DictReader((tmp_path / "bayes" / "metrics.csv").open()))
    on, off = ([float(r[f"imitation_weight_{kind}"]) for r in rows] for kind in ("demo", "agent"))
    assert on == pytest.approx([5.0] * len(rows), rel=1e-4)
    assert all(1 / (2 * 0.35) - 1e-4 <= w <= 5.0 + 1e-4 for w in off) and min(off) < 4.9
    ce = make_agent(Config.for_task("cartpole", expert_loss="ce"), demos, bc_models["ce"])
    assert ce.imitation_weights() == (None, None)
