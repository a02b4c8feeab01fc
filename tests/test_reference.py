"""The readable reference (reference.py) against the graph loop (agent.py, replay.py).

On one seed both pre-train on the strong expert's demonstrations, then learn from a replay that
also holds a noisy expert's episodes (standing in for the agent's own: falls, time-limit cuts,
and more than the ring's capacity, so old ones are evicted). They must compute the same loss
terms and end with the same weights.

Shared by both: the Q-network's initial weights; the transitions; the BC model's view of each
state (π̄_bc, σ²: MC dropout draws it once, when the graph stores a row; the reference reads it
from the graph's table); the sampler's uniforms (the graph replay's generator, replayed); and,
where a uniform's mass lies within float rounding of the boundary between two rows, which of
the two the graph took (its float32 sum tree and the reference's float64 cumulative sum may
round either way there; such draws are a few in ten thousand, and every other row the
reference draws itself must be the graph's).

Independent: everything else: the reference's own priorities, its proportional draw and
importance weights, β's schedule, the n-step returns (walked at sampling time, where the graph
caches them when a row is written), the targets, every loss term, the gradient, Adam (written
out, where the graph runs TensorFlow's fused kernel), the target refreshes and θ_prior.

Tolerances (float32, 250 steps, seed 0): loss terms per graph call rtol 1e-4 (measured ≤ 1e-6);
each weight variable within 1e-4 of its norm (measured ~3e-7); priorities rtol 1e-4, atol 3e-4
(TensorFlow's op determinism, which any earlier training in the same pytest worker turns on for the
whole process, changes the graph's reductions: then one priority of 2650 differed by 2.1e-4, |δ| by
2.4e-4 at |δ| = 0.27; without it all were within 1e-4). A norm,
not each element: where a ReLU pre-activation lands within rounding of 0, the two send that unit's
gradient different ways and Adam carries it on (seen while writing this: ~1e-4 on a few elements,
3e-5 of the norm). Changing one constant of the graph loop fails the test: the margin or ε_d by 1%,
σ² of the bayes likelihood by 1%, its prior by 10%, β's schedule by one step, τ by one, Adam's ε.
"""

import keras
import numpy as np
import pytest
import tensorflow as tf

import dqfd_bc_keras  # noqa: F401  (first: TensorFlow's threads and log level)
from dqfd_bc_keras.core import expert_terms, reference
from dqfd_bc_keras.core.agent import DQfDAgent, make_agent
from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.core.methods import Method, register
from dqfd_bc_keras.demos import DemoDataset, record
from dqfd_bc_keras.errors import ConfigError

PRETRAIN, ROUNDS, STORE, LEARN = 100, 3, 100, 50
"""Pre-training steps, then rounds of (store STORE agent transitions, LEARN steps)."""
BOUNDARY = 1e-5
"""How close (× the total) to a boundary between rows a mass may lie where the two disagree."""


@pytest.fixture(scope="module")
def agent_data() -> DemoDataset:
    """300 transitions of a noisy imperfect expert, episodes cut at 60 steps."""
    data = record("cartpole", "imperfect", episodes=12, seed=7, epsilon=0.3, max_steps=60)
    assert len(data) >= ROUNDS * STORE and data.terminated.any() and data.truncated.any()
    return data


def config_for(loss: str) -> Config:
    return Config.for_task(
        "cartpole", expert_loss=loss, replay_capacity=150, target_update_period=50, beta_anneal_steps=200, seed=0
    )


class GraphRows:
    """The rows of every batch the graph loop draws, logged by a wrapper of its replay's `sample`
    (traced into `learn`'s graph), and the uniforms its generator gives them, replayed."""

    def __init__(self, agent: DQfDAgent, steps: int) -> None:
        replay = agent.replay
        self.demo_capacity, self.n_demo = replay.demo_capacity, int(replay.demo_size.numpy())
        self.log = tf.Variable(tf.zeros([steps, agent.config.batch_size], tf.int32))
        self.count = tf.Variable(0)
        rng = replay.rng
        self.uniform = tf.random.Generator.from_state(rng.state.numpy(), rng.algorithm).uniform
        sample = replay.sample

        def logged(batch_size, beta):
            batch = sample(batch_size, beta)
            self.log.scatter_nd_update(self.count[None, None], batch.indices[None])
            self.count.assign_add(1)
            return batch

        replay.sample = logged
        self.step, self.mismatches, self.draws = 0, 0, 0

    def draw(self, p: np.ndarray, size: int) -> np.ndarray:
        """The reference's own rows from the graph's uniforms; where a mass sits on a boundary, the graph's."""
        u = self.uniform([size]).numpy().astype(np.float64)
        mine = reference.proportional(p, u)
        theirs = self.log.numpy()[self.step]
        theirs = np.where(theirs < self.demo_capacity, theirs, theirs - self.demo_capacity + self.n_demo)
        cumulative = np.cumsum(p)
        for i in np.flatnonzero(mine != theirs):
            boundary = cumulative[min(mine[i], theirs[i])]
            assert (
                abs(mine[i] - theirs[i]) == 1 and abs(u[i] * cumulative[-1] - boundary) <= BOUNDARY * cumulative[-1]
            ), f"step {self.step}: the graph drew row {theirs[i]}, the reference's priorities give {mine[i]}"
        self.step, self.mismatches, self.draws = (
            self.step + 1,
            self.mismatches + int((mine != theirs).sum()),
            self.draws + size,
        )
        return theirs


def transitions(
    agent: DQfDAgent, data: DemoDataset, rows: np.ndarray, part: slice = slice(None)
) -> reference.Transitions:
    """`data[part]` with the BC model's view of each state, as the graph stored it in table rows `rows`."""
    table = agent.replay.table.numpy()[rows]
    return reference.Transitions(
        *(x[part] for x in (data.obs, data.actions, data.rewards, data.next_obs, data.terminated, data.truncated)),
        table[:, agent.replay.PI_BC],
        table[:, agent.replay.SIGMA_SQ],
    )


def standardization(agent: DQfDAgent) -> tuple[np.ndarray, np.ndarray]:
    """(μ, σ) of the Q-network's input layer."""
    layer = agent.q_network.get_layer("standardize")
    return np.asarray(layer.mean)[0], np.sqrt(np.asarray(layer.variance))[0]


def assert_same_weights(graph: list, ref: list) -> None:
    """Each variable within 1e-4 of its norm (see the module's docstring for why a norm)."""
    for a, b in zip(graph, ref, strict=True):
        a, b = np.asarray(a), np.asarray(b)
        assert np.linalg.norm(b - a) <= 1e-4 * np.linalg.norm(a), (np.linalg.norm(b - a), np.linalg.norm(a))


def assert_same_terms(graph: dict, steps: list[dict]) -> None:
    mean = {name: np.mean([s[name] for s in steps]) for name in steps[0]}
    for name, value in graph.items():
        np.testing.assert_allclose(mean[name], float(value), rtol=1e-4, err_msg=name)


def run_both(config: Config, demos: DemoDataset, agent_data: DemoDataset, bc_model) -> tuple:
    """Pre-training, then ROUNDS × (store, learn) in both; returns (agent, reference learner, the
    graph's loss terms per call, the reference's per step grouped as those calls, the rows' log)."""
    keras.utils.set_random_seed(0)
    agent = make_agent(config, demos, bc_model)
    rows = GraphRows(agent, PRETRAIN + ROUNDS * LEARN)
    ref = reference.ReferenceLearner(
        config,
        agent.q_network.get_weights(),
        standardization(agent),
        transitions(agent, demos, np.arange(len(demos))),
        draw=rows.draw,
    )
    graph_terms = [agent.pretrain(PRETRAIN)]
    ref_terms = [ref.pretrain(PRETRAIN)]
    store = tf.function(agent.store, autograph=False)
    for r in range(ROUNDS):
        chunk = slice(r * STORE, (r + 1) * STORE)
        slots = (np.arange(STORE) + int(agent.replay.head.numpy())) % config.replay_capacity
        for t in range(chunk.start, chunk.stop):
            store(
                *(
                    tf.constant(x[t])
                    for x in (
                        agent_data.obs,
                        agent_data.actions,
                        agent_data.rewards,
                        agent_data.next_obs,
                        agent_data.terminated,
                        agent_data.truncated,
                    )
                )
            )
        agent.replay.settle()  # the BC model's view of the last rows, as a sample would before reading them
        ref.replay.store(transitions(agent, agent_data, agent.replay.demo_capacity + slots, chunk))
        agent.reset_metrics()
        graph_terms.append(agent.learn(tf.constant(LEARN)))
        ref_terms.append(ref.learn(LEARN))
    return agent, ref, graph_terms, ref_terms, rows


@pytest.mark.slow
@pytest.mark.parametrize("loss", ["margin", "bayes"])
def test_reference_learns_what_the_graph_loop_learns(loss, demos, agent_data, bc_models):
    agent, ref, graph_terms, ref_terms, rows = run_both(config_for(loss), demos, agent_data, bc_models.get(loss))
    for graph, steps in zip(graph_terms, ref_terms, strict=True):
        assert_same_terms(graph, steps)
    assert_same_weights(agent.q_network.weights, ref.theta)
    assert_same_weights(agent.target_network.weights, ref.target)
    assert_same_weights(agent.prior_weights, ref.prior_weights)
    graph_p = agent.replay.tree.leaves(agent.replay.stored_indices()).numpy()
    # p = (|δ| + ε)^α is steep near δ = 0 (slope ≤ α·ε_a^(α−1) ≈ 25): atol 3e-4 is |δ| within 1.2e-5 there.
    np.testing.assert_allclose(ref.replay.p[: len(graph_p)], graph_p, rtol=1e-4, atol=3e-4)
    assert rows.mismatches <= 1e-3 * rows.draws


def learner_for(config: Config) -> reference.ReferenceLearner:
    """A reference learner of `config` on made-up weights and two demonstrated transitions."""
    two = reference.Transitions(
        np.zeros((2, 4), np.float32), np.zeros(2, np.int64), np.ones(2, np.float32), np.zeros((2, 4), np.float32),
        np.zeros(2, bool), np.zeros(2, bool), np.full((2, 2), 0.5, np.float32), np.ones(2, np.float32),
    )  # fmt: skip
    theta = [np.zeros((4, 2), np.float32), np.zeros(2, np.float32)]
    return reference.ReferenceLearner(config, theta, (np.zeros(4), np.ones(4)), two)


def test_a_method_without_a_reference_formula_is_refused():
    """Its J_E would otherwise be checked against nothing (or against another method's)."""
    register(Method("unchecked", "the margin with nothing to check it against", term=expert_terms.margin))
    with pytest.raises(ConfigError, match="method 'unchecked' declares no reference formula of its J_E"):
        learner_for(config_for("unchecked"))
    register(Method("checked", "the margin", term=expert_terms.margin, reference=reference.margin))
    assert learner_for(config_for("checked")).j_e is reference.margin


@pytest.mark.parametrize("change", [{"expert_loss": "sqil"}, {"td_loss": "huber"}])
def test_what_the_reference_does_not_state_is_refused(change):
    with pytest.raises(ConfigError, match="the reference has neither SQIL nor the Huber TD loss"):
        learner_for(Config.for_task("cartpole", **change))
