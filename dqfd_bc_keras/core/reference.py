"""The learning core stated plainly: Algorithm 1's learning steps, eager, in TensorFlow and numpy.

The package learns inside graphs (agent.py, replay.py: a sum tree in variables, cached n-step returns,
a fused Adam op, a `tf.while_loop`). This is the same mathematics (ALGORITHM.md §1–§4) without them.
Nothing trains through it; tests/test_reference.py runs it beside the graph loop and shows both
compute the same loss terms and end with the same weights: documentation that cannot rot.

    pre-train:   k steps on D_demo alone, then θ_prior ← θ
    every step:  rows i drawn with P(i) = p_i / Σ_k p_k, weights w_i = (N·P(i))^(−β) / max_j w_j
                 J = J_DQ + λ1·J_n + λ2·J_E + λ3·J_L2, one step of Keras's Adam on θ
                 p_i ← (|δ_i| + ε)^α, ε = ε_d on D_demo, ε_a on D_replay;  θ' ← θ every τ steps

Left to the caller: acting (§4 step 3), whose transitions it `store`s, and dynamic demonstrations (§5).

J_E is each method's declared reference formula (`Method.reference`; the built-ins' are the functions
at the end of this module, written without losses.py), never a stand-in: a method with a term and
no reference is refused, so a new method cannot pass as another one.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
import tensorflow as tf

from dqfd_bc_keras.errors import ConfigError

if TYPE_CHECKING:
    from dqfd_bc_keras.core.config import Config
    from dqfd_bc_keras.core.methods import Method, Term, TermAgent, TermBatch

Draw = Callable[[np.ndarray, int], np.ndarray]  # (p^α of every row, batch size) → the batch's rows


def expert_reference(method: Method) -> Term | None:
    """The eager formula `method`'s J_E is checked against: its declared reference; None for a
    method without a term (J_E = 0). A method with a term and no reference is a `ConfigError`."""
    if method.term is None:
        return None
    if method.reference is None:
        raise ConfigError(
            f"method {method.name!r} declares no reference formula of its J_E: give Method(..., "
            "reference=...) the same loss written eagerly and independently of its term, to be checked against it"
        )
    return method.reference_term()


class Transitions(NamedTuple):
    """n transitions in time order, each with the BC model's view of its state (bc.py)."""

    obs: np.ndarray  # (n, d) s_t
    actions: np.ndarray  # (n,) a_t
    rewards: np.ndarray  # (n,) r_t
    next_obs: np.ndarray  # (n, d) s_{t+1}
    terminated: np.ndarray  # (n,) the episode ended for good: nothing to bootstrap from
    truncated: np.ndarray  # (n,) the episode was cut (a time limit): bootstrap from s_{t+1}
    pi_bc: np.ndarray  # (n, A) π̄_bc(·|s_t)
    sigma_sq: np.ndarray  # (n,) σ²(s_t)


def proportional(p: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Rows with P(i) = p_i / Σ_k p_k: each u ∈ [0, 1) picks the row whose slice
    [Σ_{k<i} p_k, Σ_{k≤i} p_k) of the total holds u·Σ_k p_k."""
    cumulative = np.cumsum(p)
    return np.searchsorted(cumulative, u * cumulative[-1], side="right")


class Replay:
    """D_demo in rows [0, n_demo), never evicted; D_replay in the next `replay_capacity` rows, a
    ring whose newest transition overwrites the oldest. Row i has priority p_i (p^α; 0: empty)."""

    def __init__(self, demos: Transitions, config) -> None:
        self.c, self.n_demo, self.capacity = config, len(demos.actions), config.replay_capacity
        self.data = Transitions(*(np.concatenate([x, np.zeros((self.capacity, *x.shape[1:]), x.dtype)]) for x in demos))
        self.p = np.zeros(self.n_demo + self.capacity)
        self.p[: self.n_demo] = self.max_p = 1.0  # a new row enters at the largest p so far
        self.head = self.stored = 0  # the ring's next slot; how many transitions it holds

    def store(self, t: Transitions) -> None:  # (at most `replay_capacity` at once)
        rows = self.n_demo + (self.head + np.arange(len(t.actions))) % self.capacity
        for column, values in zip(self.data, t, strict=True):
            column[rows] = values
        self.p[rows] = self.max_p
        self.head, self.stored = (self.head + len(rows)) % self.capacity, min(self.stored + len(rows), self.capacity)

    def following(self, row: int) -> int | None:
        """The row stored right after `row` in its region; None after the newest."""
        if row < self.n_demo:
            return row + 1 if row + 1 < self.n_demo else None
        newest = self.n_demo + (self.head - 1) % self.capacity
        return None if row == newest else self.n_demo + (row - self.n_demo + 1) % self.capacity

    def n_step(self, row: int) -> tuple[np.float32, np.ndarray, np.float32]:
        """(Σ_{k<m} γ^k r_{t+k}, s_{t+m}, γ^m·(1 − terminated_{t+m−1})): m ≤ n stops at the end
        of the episode (terminated or truncated) or at the newest stored transition."""
        d, gamma, ret, m = self.data, np.float32(self.c.gamma), np.float32(0), 0
        while True:
            ret, m, after = ret + gamma**m * d.rewards[row], m + 1, self.following(row)
            if m == self.c.n_step or d.terminated[row] or d.truncated[row] or after is None:
                return ret, d.next_obs[row], gamma**m * (1 - np.float32(d.terminated[row]))
            row = after

    def sample(self, batch_size: int, beta: float, draw: Draw) -> tuple[np.ndarray, np.ndarray]:
        """(rows, importance weights w_i = (N·P(i))^(−β) / max_j w_j)."""
        rows = draw(self.p, batch_size)
        w = ((self.n_demo + self.stored) * self.p[rows] / self.p.sum()) ** -beta
        return rows, w / w.max()

    def update_priorities(self, rows: np.ndarray, td_abs: np.ndarray) -> None:
        eps = np.where(rows < self.n_demo, self.c.priority_eps_demo, self.c.priority_eps_agent)
        self.p[rows] = (td_abs + eps) ** self.c.priority_alpha
        self.max_p = max(self.max_p, self.p[rows].max())


class ExpertRows(NamedTuple):
    """A batch as J_E reads it (methods.TermBatch)."""

    actions: tf.Tensor
    is_demo: tf.Tensor
    weights: tf.Tensor
    pi_bc: tf.Tensor
    sigma_sq: tf.Tensor


class ReferenceLearner:
    """θ, θ', θ_prior, Adam's state and the replay; `config` is a Config (squared TD loss; no SQIL);
    J_E is its method's reference (`expert_reference`). A `methods.TermAgent`.
    θ = [W_1, b_1, …, W_L, b_L] (`build_q_network(…).get_weights()`'s layout), `obs_scale` = (μ, σ):
    Q(s, ·; θ) = W_L·relu(… relu(W_1·(s − μ)/σ + b_1) …) + b_L. `draw` picks each batch's rows."""

    def __init__(
        self,
        config: Config,
        theta: list[np.ndarray],
        obs_scale: tuple[np.ndarray, np.ndarray],
        demos: Transitions,
        draw: Draw | None = None,
    ) -> None:
        if config.method.sqil_rewards or config.td_loss != "squared":
            raise ConfigError("the reference has neither SQIL nor the Huber TD loss")
        self.j_e = expert_reference(config.method)
        self.config, self.mu, sigma = config, *(np.float32(x) for x in obs_scale)
        self.sigma = np.where(sigma > 0, np.maximum(sigma, 1e-3), 1).astype(np.float32)  # 0: centred only
        self.expert_scale = 1.0  # w_E of a method with a decay, set by the caller (§8)
        self.theta = [tf.Variable(np.float32(w)) for w in theta]
        self.target = [tf.identity(w) for w in self.theta]  # θ'
        self.prior_weights = [tf.zeros_like(w) for w in self.theta]  # θ_prior is 0 while pre-training
        self.m, self.v = [np.zeros(w.shape, np.float32) for w in theta], [np.zeros(w.shape, np.float32) for w in theta]
        self.steps, self.replay = 0, Replay(demos, config)
        rng = np.random.default_rng(config.seed)
        self.draw = draw or (lambda p, size: proportional(p, rng.random(size)))

    @property
    def demo_size(self) -> int:
        """N = |D_demo|."""
        return self.replay.n_demo

    def q(self, s: np.ndarray, theta: list[tf.Tensor]) -> tf.Tensor:
        x = (s - self.mu) / self.sigma
        for i in range(0, len(theta) - 2, 2):
            x = tf.nn.relu(x @ theta[i] + theta[i + 1])
        return x @ theta[-2] + theta[-1]

    def pretrain(self, k: int) -> list[dict[str, float]]:
        """Algorithm 1, step 2: k steps on D_demo alone, then θ_prior ← θ (if "pretrained")."""
        if self.replay.stored:
            raise ValueError("pre-training samples D_demo alone, but the replay holds agent data")
        terms = self.learn(k)
        if self.config.prior_center == "pretrained":
            self.prior_weights = [tf.identity(w) for w in self.theta]
        return terms

    def learn(self, steps: int) -> list[dict[str, float]]:  # the loss terms of each step
        return [self.learn_step() for _ in range(steps)]

    def beta(self) -> float:  # linear from β0 to 1 over `beta_anneal_steps` steps, then 1
        c = self.config
        return c.priority_beta0 + (1 - c.priority_beta0) * min(1.0, self.steps / max(c.beta_anneal_steps, 1))

    def next_values(self, s: np.ndarray) -> np.ndarray:
        """V'(s) = max_a Q(s, a; θ') (dqn) or Q(s, argmax_a Q(s, a; θ); θ') (double)."""
        q_target = self.q(s, self.target).numpy()
        a = q_target.argmax(1) if self.config.target == "dqn" else self.q(s, self.theta).numpy().argmax(1)
        return q_target[np.arange(len(s)), a]

    def learn_step(self) -> dict[str, float]:
        """One Adam step on J for a prioritized batch; returns J's terms."""
        c, replay = self.config, self.replay
        rows, w = replay.sample(c.batch_size, self.beta(), self.draw)
        b, w = Transitions(*(x[rows] for x in replay.data)), w.astype(np.float32)
        ret_n, s_n, discount_n = (np.array(x) for x in zip(*(replay.n_step(i) for i in rows), strict=True))
        # Constant targets: y = r + γ(1 − terminated)·V'(s'),
        #                   y_n = Σ_{k<m} γ^k r_{t+k} + γ^m(1 − terminated)·V'(s_{t+m})
        v, v_n = np.split(self.next_values(np.concatenate([b.next_obs, s_n])), 2)
        y, y_n = b.rewards + np.float32(c.gamma) * (1 - np.float32(b.terminated)) * v, ret_n + discount_n * v_n
        demo = np.float32(rows < replay.n_demo)
        expert_rows = ExpertRows(*(tf.constant(x) for x in (b.actions, demo, w, b.pi_bc, b.sigma_sq)))
        with tf.GradientTape() as tape:
            q = self.q(b.obs, self.theta)
            q_sa = tf.gather_nd(q, np.stack([np.arange(len(rows)), b.actions], 1))
            delta = y - q_sa
            terms = {
                "td": tf.reduce_mean(w * tf.square(delta)),
                "n_step": tf.reduce_mean(w * tf.square(y_n - q_sa)),
                "expert": tf.constant(0.0) if self.j_e is None else self.j_e(self, q, expert_rows),
                "l2": tf.add_n([tf.reduce_sum(tf.square(W)) for W in self.theta[::2]]),
            }  # kernels, not biases
            loss = (
                terms["td"]
                + c.lambda_n * terms["n_step"]
                + c.lambda_expert * terms["expert"]
                + c.lambda_l2 * terms["l2"]
            )
        self.adam(tape.gradient(loss, self.theta))
        replay.update_priorities(rows, np.abs(delta.numpy()))
        self.steps += 1
        if self.steps % c.target_update_period == 0:
            self.target = [tf.identity(w) for w in self.theta]
        return {"loss": float(loss), **{name: float(value) for name, value in terms.items()}}

    def adam(self, grads: list[tf.Tensor], b1=np.float32(0.9), b2=np.float32(0.999), eps=np.float32(1e-7)) -> None:
        """Keras's Adam in float32: m ← β1·m + (1 − β1)·g, v ← β2·v + (1 − β2)·g²,
        θ ← θ − lr·√(1 − β2^t)/(1 − β1^t) · m/(√v + ε), t = this step's number."""
        t = self.steps + 1
        size = np.float32(self.config.learning_rate) * np.sqrt(1 - b2**t) / (1 - b1**t)
        for i, (g, w) in enumerate(zip((g.numpy() for g in grads), self.theta, strict=True)):
            self.m[i], self.v[i] = b1 * self.m[i] + (1 - b1) * g, b2 * self.v[i] + (1 - b2) * g**2
            w.assign(w.numpy() - size * self.m[i] / (np.sqrt(self.v[i]) + eps))


# J_E of the built-in methods (their `Method.reference`), importance-weighted, in plain TensorFlow and numpy.


def margin(agent: TermAgent, q: tf.Tensor, batch: TermBatch) -> tf.Tensor:
    """DQfD: the large margin around the demonstrated action a_E, on D_demo's rows only."""
    w = np.asarray(batch.weights) * np.asarray(batch.is_demo)
    return _large_margin(q, np.asarray(batch.actions), agent.config.margin, w)


def bc_margin(agent: TermAgent, q: tf.Tensor, batch: TermBatch) -> tf.Tensor:
    """DQfD-BC: the large margin around a_E = argmax_a π̄_bc(a|s), on every row."""
    return _large_margin(q, np.asarray(batch.pi_bc).argmax(1), agent.config.margin, np.asarray(batch.weights))


def _large_margin(q: tf.Tensor, a_e: np.ndarray, margin: float, w: np.ndarray) -> tf.Tensor:
    """mean_i w_i·(max_a [Q(s_i, a) + l(a_E, a)] − Q(s_i, a_E)), l = margin where a ≠ a_E, else 0."""
    l = np.float32(margin * (np.arange(q.shape[1]) != a_e[:, None]))  # noqa: E741 (the paper's l)
    q_e = tf.gather_nd(q, np.stack([np.arange(len(a_e)), a_e], 1))
    return tf.reduce_mean(w * (tf.reduce_max(q + l, 1) - q_e))


def ce(agent: TermAgent, q: tf.Tensor, batch: TermBatch) -> tf.Tensor:
    """H(π_bc, p_Q) = −Σ_a π_bc(a|s) log p_Q(a|s),  p_Q = softmax(Q/T), on every row."""
    log_p_q = tf.nn.log_softmax(q / agent.config.temperature)
    return tf.reduce_mean(batch.weights * -tf.reduce_sum(batch.pi_bc * log_p_q, 1))


def bayes(agent: TermAgent, q: tf.Tensor, batch: TermBatch) -> tf.Tensor:
    """mean_s Σ_a (p_Q(a|s) − π̄_bc(a|s))² / (2σ²(s))  +  ‖θ − θ_prior‖² / (2·s_p²·N) (no prior
    with `bayes_prior=False`)."""
    c = agent.config
    p_q = tf.nn.softmax(q / c.temperature)
    likelihood = tf.reduce_mean(batch.weights * tf.reduce_sum(tf.square(p_q - batch.pi_bc), 1) / (2 * batch.sigma_sq))
    if not c.bayes_prior:
        return likelihood
    theta, prior = agent.theta, agent.prior_weights
    squared = tf.add_n([tf.reduce_sum(tf.square(t - p)) for t, p in zip(theta, prior, strict=True)])
    return likelihood + squared / (2 * c.prior_scale**2 * float(agent.demo_size))


def qfilter(agent: TermAgent, q: tf.Tensor, batch: TermBatch) -> tf.Tensor:
    """mean_s 1[Q(s, a_bc) + l ≥ max_a Q(s, a)]·H(π_bc, p_Q),  a_bc = argmax_a π̄_bc(a|s), l the
    margin; the filter is a constant of θ."""
    q_now, a_bc = q.numpy(), np.asarray(batch.pi_bc).argmax(1)
    kept = np.float32(q_now[np.arange(len(a_bc)), a_bc] + agent.config.margin >= q_now.max(1))
    log_p_q = tf.nn.log_softmax(q / agent.config.temperature)
    return tf.reduce_mean(batch.weights * kept * -tf.reduce_sum(batch.pi_bc * log_p_q, 1))


def ce_decay(agent: TermAgent, q: tf.Tensor, batch: TermBatch) -> tf.Tensor:
    """w_E·H(π_bc, p_Q), w_E the agent's teacher-relative weight."""
    log_p_q = tf.nn.log_softmax(q / agent.config.temperature)
    return float(agent.expert_scale) * tf.reduce_mean(batch.weights * -tf.reduce_sum(batch.pi_bc * log_p_q, 1))
