"""A design probe, not the package: how fast Algorithm 1's online loop on MinAtar runs when
everything but the gradient step lives in numpy (issue S's 2× goal; docs/PERFORMANCE.md).

The package's loop (`training/interaction.py`) is one TensorFlow graph per episode: acting,
storing, settling, sampling and learning are graph ops, each with a fixed cost. This probe runs
the same work the way SB3 and CleanRL do, on the package's own preset, networks, π_bc and
`DQfDAgent.train_step`:

- acting: ε-greedy with a numpy forward pass of Q on the θ the last update call returned;
- D_demo ∪ D_replay: numpy arrays (frames as uint8, s and s' per row), a two-level sum tree in
  numpy (blocks of 64, as `core/sum_tree.py`), new rows at the largest priority;
- settling (before each sample): the n-step returns of the new rows and of the n − 1 before them,
  and the BC model's view (π̄_bc, σ² from K MC-dropout passes of its head) in numpy;
- learning: one graph call per update, `train_step` on the sampled batch passed in as two arrays
  (the frames, the rest), returning |δ| and θ (flat).

`bench_pixels.py --design numpy-probe` times it against SB3 exactly as it times the package's
loop. What it leaves out, so its figure bounds a numpy design from above: checkpoints, the
evaluation grid, the per-episode records (loss means, imitation weights), dynamic
demonstrations, SQIL's batches and frame stacks (MinAtar's frames are single). Its random draws
are numpy's, so its runs are not the package's. `tests/test_benchmarks.py` holds its numpy
network, n-step views and BC view to the package's.
"""

from __future__ import annotations

import time

import numpy as np


class NumpyReplay:
    """D_demo (rows [0, demo_capacity)) and a circular D_replay, prioritized, with n-step views."""

    WIDTH = 64

    def __init__(self, frame_shape, n_actions, capacity, demo_capacity, n_step, gamma, alpha, eps_a, eps_d, seed):
        rows = demo_capacity + capacity
        self.capacity, self.demo_capacity, self.n_step, self.gamma = capacity, demo_capacity, n_step, gamma
        self.alpha, self.eps_a, self.eps_d = alpha, eps_a, eps_d
        self.obs = np.zeros((rows, *frame_shape), np.uint8)
        self.next_obs = np.zeros((rows, *frame_shape), np.uint8)
        self.action = np.zeros(rows, np.int32)
        self.reward = np.zeros(rows, np.float32)
        self.terminated = np.zeros(rows, bool)
        self.done = np.zeros(rows, bool)
        self.pi_bc = np.zeros((rows, n_actions), np.float32)
        self.sigma_sq = np.zeros(rows, np.float32)
        self.n_return = np.zeros(rows, np.float32)
        self.n_last = np.zeros(rows, np.int64)
        """The row t+m−1 whose s' is s_{t+m}."""
        self.n_discount = np.zeros(rows, np.float32)
        self.blocks = -(-rows // self.WIDTH)
        self.leaf = np.zeros((self.blocks, self.WIDTH), np.float32)
        self.block_sum = np.zeros(self.blocks, np.float32)
        self.max_priority = 1.0
        self.demo_size = self.agent_size = self.head = self.unsettled = 0
        self.powers = gamma ** np.arange(n_step, dtype=np.float32)
        self.rng = np.random.default_rng(seed)

    def _set(self, index: np.ndarray, values: np.ndarray) -> None:
        block, position = np.divmod(index, self.WIDTH)
        self.leaf[block, position] = values
        block = np.unique(block)
        self.block_sum[block] = self.leaf[block].sum(axis=1)

    def set_demos(self, obs, actions, rewards, next_obs, terminated, truncated, pi_bc, sigma_sq) -> None:
        n = len(obs)
        rows = np.arange(n)
        self.obs[:n], self.next_obs[:n], self.action[:n], self.reward[:n] = obs, next_obs, actions, rewards
        self.terminated[:n], self.done[:n] = terminated, np.logical_or(terminated, truncated)
        self.pi_bc[:n], self.sigma_sq[:n] = pi_bc, sigma_sq
        self.demo_size = n
        self._refresh_n_step(rows)
        self._set(rows, np.full(n, self.max_priority, np.float32))

    def store(self, obs, action, reward, next_obs, terminated, truncated) -> None:
        i = self.demo_capacity + self.head
        self.obs[i], self.next_obs[i], self.action[i], self.reward[i] = obs, next_obs, action, reward
        self.terminated[i], self.done[i] = terminated, terminated or truncated
        block, position = divmod(i, self.WIDTH)
        self.block_sum[block] += self.max_priority - self.leaf[block, position]
        self.leaf[block, position] = self.max_priority
        self.head = (self.head + 1) % self.capacity
        self.agent_size = min(self.agent_size + 1, self.capacity)
        self.unsettled += 1

    def _newest(self, m: int) -> np.ndarray:
        return self.demo_capacity + (self.head - 1 - np.arange(m)) % self.capacity

    def settle(self, expert_view) -> None:
        if self.unsettled == 0:
            return
        self._refresh_n_step(self._newest(min(self.unsettled + self.n_step - 1, self.agent_size)))
        rows = self._newest(self.unsettled)
        self.pi_bc[rows], self.sigma_sq[rows] = expert_view(self.obs[rows])
        self.unsettled = 0

    def _refresh_n_step(self, rows: np.ndarray) -> None:
        """R = Σ_{k<m} γ^k r_{t+k}, s_{t+m} and γ^m(1 − terminated) of `rows`, as the package's replay."""
        k = np.arange(self.n_step)
        demo = rows < self.demo_capacity
        window = np.where(
            demo[:, None],
            rows[:, None] + k,
            self.demo_capacity + (rows[:, None] - self.demo_capacity + k) % self.capacity,
        )
        ahead = np.where(demo, self.demo_size - 1 - rows, (self.head - 1 - (rows - self.demo_capacity)) % self.capacity)
        window = np.minimum(window, len(self.reward) - 1)
        done = self.done[window]
        ended_before = np.cumsum(done, axis=1) - done > 0
        inside = ~ended_before & (k <= ahead[:, None])
        m = inside.sum(axis=1)
        last = window[np.arange(len(rows)), m - 1]
        self.n_return[rows] = (inside * self.powers * self.reward[window]).sum(axis=1)
        self.n_last[rows] = last
        self.n_discount[rows] = self.gamma**m * (1.0 - self.terminated[last])

    def sample(self, batch_size: int, beta: float) -> tuple[np.ndarray, np.ndarray]:
        cumulative = np.cumsum(self.block_sum)
        total = cumulative[-1]
        mass = np.minimum(self.rng.random(batch_size, np.float32) * total, total * (1 - 1e-6))
        block = np.minimum(np.searchsorted(cumulative, mass, side="right"), self.blocks - 1)
        mass -= np.concatenate([[0.0], cumulative])[block]
        within = np.cumsum(self.leaf[block], axis=1)
        mass = np.minimum(mass, within[:, -1] * (1 - 1e-6))
        position = (within <= mass[:, None]).sum(axis=1)
        index = block * self.WIDTH + position
        weights = ((self.demo_size + self.agent_size) * self.leaf[block, position] / total) ** -beta
        return index, weights / weights.max()

    def batch(self, index: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(frames (3B, …): s, s', s_{t+m}; floats (B, 7 + A + 1))."""
        frames = np.concatenate([self.obs[index], self.next_obs[index], self.next_obs[self.n_last[index]]])
        floats = np.column_stack(
            [
                self.action[index],
                self.reward[index],
                self.gamma * (1.0 - self.terminated[index]),
                self.n_return[index],
                self.n_discount[index],
                index < self.demo_capacity,
                weights,
                self.pi_bc[index],
                self.sigma_sq[index],
            ]
        ).astype(np.float32)
        return frames, floats

    def update_priorities(self, index: np.ndarray, td_abs: np.ndarray) -> None:
        priorities = (td_abs + np.where(index < self.demo_capacity, self.eps_d, self.eps_a)) ** self.alpha
        self._set(index, priorities)
        self.max_priority = max(self.max_priority, float(priorities.max()))


def conv_features(kernel: np.ndarray, bias: np.ndarray, frames: np.ndarray, scale: float) -> np.ndarray:
    """MinAtar's torso on uint8 frames (B, h, w, c): a 3×3 convolution (valid, stride 1) as one
    product of the frames' patches (gathered by a precomputed index) with the kernel, ReLU, flattened."""
    h, w, c = frames.shape[1:]
    kh, kw = kernel.shape[:2]
    key = (h, w, c, kh, kw)
    if key not in _PATCHES:
        cells = np.arange(h * w * c).reshape(h, w, c)
        _PATCHES[key] = np.stack(
            [cells[i : i + kh, j : j + kw].reshape(-1) for i in range(h - kh + 1) for j in range(w - kw + 1)]
        )
    patches = frames.reshape(len(frames), -1)[:, _PATCHES[key]]  # (B, h'·w', kh·kw·c)
    x = patches.astype(np.float32) @ (scale * kernel.reshape(-1, kernel.shape[-1])) + bias
    return np.maximum(x, 0.0).reshape(len(frames), -1)


_PATCHES: dict[tuple[int, ...], np.ndarray] = {}


def minatar_forward(weights: list[np.ndarray], frames: np.ndarray, scale: float) -> np.ndarray:
    """Q of MinAtar's network (the torso, dense ReLU layers, a linear output) on uint8 frames."""
    x = conv_features(weights[0], weights[1], frames, scale)
    for i in range(2, len(weights) - 2, 2):
        x = np.maximum(x @ weights[i] + weights[i + 1], 0.0)
    return x @ weights[-2] + weights[-1]


def bc_view(bc, scale: float, rng: np.random.Generator):
    """The BC model's π̄_bc and σ² in numpy: its features once, K dropout passes of its head."""
    kernel, bias = (w.numpy() for w in next(layer for layer in bc.body if layer.weights).weights)
    head = [w.numpy() for layer in bc.stack for w in layer.weights]
    rate, passes, sigma0_sq = bc.network.dropout, bc.estimator.mc_passes, bc.estimator.sigma0_sq

    def view(frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x = conv_features(kernel, bias, frames, scale)
        for i in range(0, len(head) - 2, 2):
            x = np.maximum(x @ head[i] + head[i + 1], 0.0)  # (B, h), then (K, B, h)
            x = x * (rng.random((passes, *x.shape[-2:]), np.float32) >= rate) / (1.0 - rate)
        logits = x @ head[-2] + head[-1]
        probs = np.exp(logits - logits.max(axis=-1, keepdims=True))
        probs /= probs.sum(axis=-1, keepdims=True)
        pi_bc = probs.sum(axis=0) / passes
        variance = np.square(probs - pi_bc).sum(axis=(0, 2)) / (passes * probs.shape[-1])  # mean_a Var_k
        return pi_bc, sigma0_sq + variance

    return view


def uniform_view(n_actions: int, sigma0_sq: float):
    """The view without a BC model, as `DQfDAgent.expert_targets` gives it: π̄_bc uniform, σ² = σ0²."""

    def view(frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return np.full((len(frames), n_actions), 1 / n_actions, np.float32), np.full(len(frames), sigma0_sq, np.float32)

    return view


def run(steps: int, warmup: int, train_freq: int, expert_loss: str = "bayes") -> dict[str, float]:
    """Build the preset's agent and π_bc (the package's code), then time the numpy loop."""
    import tensorflow as tf

    from dqfd_bc_keras.core.config import Config
    from dqfd_bc_keras.core.replay import Batch
    from dqfd_bc_keras.training.loop import build, episode_seed

    c = Config.for_task(
        "minatar-breakout",
        expert_loss=expert_loss,
        total_steps=warmup + steps,
        pretrain_steps=warmup,
        bc_epochs=2,
        train_freq=train_freq,
    )
    learner, _ = build(c)
    agent, env, demos = learner.agent, learner.interaction.env, learner.demos
    scale = agent.net_input.frames.scale
    A = agent.n_actions
    replay = NumpyReplay(
        agent.net_input.shape, A, c.replay_capacity, c.demo_capacity, c.n_step, c.gamma,
        c.priority_alpha, c.priority_eps_agent, c.priority_eps_demo, c.seed,
    )  # fmt: skip
    rng = np.random.default_rng(c.seed + 1)
    expert_view = bc_view(learner.bc, scale, rng) if learner.bc is not None else uniform_view(A, c.sigma0_sq)
    pi, sig = expert_view(demos.obs)
    replay.set_demos(
        demos.obs, demos.actions, demos.rewards, demos.next_obs, demos.terminated, demos.truncated, pi, sig
    )
    B = c.batch_size
    shape = agent.net_input.shape
    theta = agent.q_network.trainable_weights

    @tf.function(
        autograph=False,
        input_signature=[tf.TensorSpec([3 * B, *shape], tf.uint8), tf.TensorSpec([B, 8 + A], tf.float32)],
    )
    def update(frames, floats):
        obs, next_obs, n_next_obs = tf.split(frames, 3)
        batch = Batch(
            indices=tf.zeros([B], tf.int32),
            obs=obs,
            actions=tf.cast(floats[:, 0], tf.int32),
            rewards=floats[:, 1],
            next_obs=next_obs,
            discount=floats[:, 2],
            n_returns=floats[:, 3],
            n_next_obs=n_next_obs,
            n_discount=floats[:, 4],
            pi_bc=floats[:, 7 : 7 + A],
            sigma_sq=floats[:, 7 + A],
            is_demo=floats[:, 5],
            weights=floats[:, 6],
        )
        delta = agent.train_step(batch)
        return tf.abs(delta), tf.concat([tf.reshape(w, [-1]) for w in theta], 0)

    def beta(train_steps: int) -> float:
        return c.priority_beta0 + (1 - c.priority_beta0) * min(1.0, train_steps / max(c.beta_anneal_steps, 1))

    shapes = [tuple(w.shape) for w in theta]
    bounds = np.cumsum([0] + [int(np.prod(shape)) for shape in shapes])

    def unflatten(flat: np.ndarray) -> list[np.ndarray]:
        return [flat[a:b].reshape(shape) for a, b, shape in zip(bounds[:-1], bounds[1:], shapes, strict=True)]

    weights = [w.numpy() for w in theta]
    train_steps = int(agent.train_steps.numpy())
    decay = c.epsilon_fraction * c.total_steps
    marks, env_steps, episode = [], 0, 0
    while env_steps < warmup + steps:
        obs, _ = env.reset(seed=episode_seed(c.seed, episode))
        done = False
        while not done and env_steps < warmup + steps:
            if env_steps == warmup:
                marks.append((time.perf_counter(), env_steps))
            epsilon = max(c.epsilon_end, c.initial_epsilon - (c.initial_epsilon - c.epsilon_end) * env_steps / decay)
            if rng.random() < epsilon:
                action = int(rng.integers(A))
            else:
                action = int(minatar_forward(weights, obs[None], scale)[0].argmax())
            next_obs, reward, terminated, truncated, _ = env.step(action)
            replay.store(obs, action, reward, next_obs, terminated, truncated)
            env_steps += 1
            if env_steps % c.train_freq == 0:
                replay.settle(expert_view)
                index, is_weights = replay.sample(B, beta(train_steps))
                td_abs, theta_now = update(*replay.batch(index, is_weights))
                replay.update_priorities(index, td_abs.numpy())
                weights = unflatten(theta_now.numpy())
                train_steps += 1
            obs, done = next_obs, terminated or truncated
        episode += 1
    marks.append((time.perf_counter(), env_steps))
    (t0, s0), (t1, s1) = marks[0], marks[-1]
    return {"env_steps_per_s": (s1 - s0) / (t1 - t0)}
