"""The BC classifier: MLE vs MAP fits, MC-dropout predictive, save/load round trip."""

import keras
import numpy as np
import pytest
import tensorflow as tf

import dqfd_bc_keras  # noqa: F401  (registers the custom objects)
from dqfd_bc_keras.core.bc import BCModel, build_bc_model
from dqfd_bc_keras.core.config import Config


def test_map_model_has_dropout_and_prior_mle_has_neither(bc_models):
    bayes, ce = bc_models["bayes"], bc_models["ce"]
    assert bayes.network.map_fit and bayes.network.dropout == Config.for_task("cartpole").bc_dropout > 0
    assert not ce.network.map_fit and ce.network.dropout == 0.0
    assert float(ce.prior_loss()) == 0.0
    # ‖w‖²/(2 s² N) by hand, N = 2,500 demonstration transitions
    squared = sum(float(np.sum(np.square(w))) for w in bayes.trainable_weights)
    np.testing.assert_allclose(float(bayes.prior_loss()), squared / (2 * 1.0 * 2500), rtol=1e-5)


@pytest.mark.parametrize("loss", ["bayes", "ce"])
def test_bc_reaches_95_percent_on_the_strong_experts_demos(bc_models, demos, held_out, loss):
    model = bc_models[loss]
    for data in (demos, held_out):
        predicted = np.argmax(model(data.obs).numpy(), axis=1)
        assert np.mean(predicted == data.actions) >= 0.95


def test_predictive_of_mle_model_is_its_softmax_with_sigma0(bc_models, held_out):
    model = bc_models["ce"]
    pi_bar, sigma_sq = model.predictive(tf.constant(held_out.obs[:50]))
    np.testing.assert_allclose(pi_bar, tf.nn.softmax(model(held_out.obs[:50])), rtol=1e-6)
    np.testing.assert_allclose(sigma_sq, np.full(50, 0.5))


def test_predictive_of_map_model_averages_k_dropout_passes(bc_models, held_out):
    model = bc_models["bayes"]
    obs = tf.constant(held_out.obs[:50])
    pi_bar, sigma_sq = model.predictive(obs)
    assert pi_bar.shape == (50, 2) and sigma_sq.shape == (50,)
    np.testing.assert_allclose(tf.reduce_sum(pi_bar, axis=1), np.ones(50), rtol=1e-5)
    assert np.all(sigma_sq.numpy() >= 0.5)  # σ² = σ0² + epistemic variance ≥ σ0²
    # Dropout is active: two draws differ, while the deterministic call does not.
    assert not np.allclose(model.predictive(obs)[0], pi_bar)
    np.testing.assert_array_equal(model(obs), model(obs))


def test_map_variance_peaks_where_the_bc_model_is_unsure(bc_models, demos):
    """σ²(s) − σ0², the MC-dropout variance, is largest where the classifier hesitates."""
    model = bc_models["bayes"]
    pi_bar, sigma_sq = (x.numpy() for x in model.predictive(tf.constant(demos.obs)))
    confidence = pi_bar.max(axis=1)
    unsure, sure = sigma_sq[confidence < 0.8] - 0.5, sigma_sq[confidence > 0.99] - 0.5
    assert len(unsure) >= 20 and len(sure) >= 100
    assert unsure.mean() > 10 * sure.mean()


def test_map_variance_vanishes_far_from_the_demonstrations(bc_models, demos):
    """A finding, not the hoped-for property: far off the demonstrated states the ReLU
    network's logits grow, the softmax saturates, every dropout pass agrees, and σ² falls
    back to σ0², below its average on the demonstrations themselves. The Bayesian loss
    therefore weakens imitation near the expert's decision boundary, not in unvisited states
    (README, "Findings")."""
    model = bc_models["bayes"]
    rng = np.random.default_rng(0)
    mean, std = demos.obs_scale()
    far = mean + std * rng.uniform(3.0, 6.0, size=(1000, 4)) * rng.choice([-1, 1], size=(1000, 4))
    epistemic_far = model.predictive(tf.constant(far, tf.float32))[1].numpy() - 0.5
    epistemic_demo = model.predictive(tf.constant(demos.obs))[1].numpy() - 0.5
    assert epistemic_far.mean() < epistemic_demo.mean()
    np.testing.assert_allclose(epistemic_far, 0.0, atol=1e-3)


@pytest.mark.parametrize("loss", ["bayes", "ce"])
def test_save_load_round_trip_in_safe_mode(bc_models, held_out, tmp_path, loss):
    model = bc_models[loss]
    path = tmp_path / "bc_model.keras"
    model.save(path)
    loaded = keras.saving.load_model(path)  # safe_mode=True by default
    assert isinstance(loaded, BCModel)
    assert loaded.get_config() == model.get_config()
    np.testing.assert_allclose(loaded(held_out.obs), model(held_out.obs), rtol=1e-6, atol=1e-6)
    assert float(loaded.n_data) == 2500.0


def test_warm_started_refit_keeps_the_fit(bc_models, demos, held_out):
    model = build_bc_model(Config.for_task("cartpole", expert_loss="ce"), 4, 2, demos.obs_scale())
    model.set_weights(bc_models["ce"].get_weights())
    metrics = model.fit_demos(held_out.obs, held_out.actions, epochs=1)
    assert metrics["accuracy"] >= 0.9
    assert float(model.n_data) == len(held_out.obs)
