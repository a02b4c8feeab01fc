"""Tests for the prioritized replay in dqfd_bc_keras.core.replay (ALGORITHM.md §1).

Every expected value is worked out by hand (the arithmetic is written as literals); none is
computed by calling the code under test. Transition rows are tagged: row t has
s = [t, −t], s' = [t+1, −(t+1)], r = t+1 unless a test says otherwise, so a row read back
identifies itself.
"""

import numpy as np
import pytest
import tensorflow as tf

from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.core.replay import PrioritizedReplay, ReplaySettings
from dqfd_bc_keras.core.sum_tree import SumTree
from dqfd_bc_keras.errors import ConfigError

G = 0.9  # γ in every test
ATOL = 1e-5


def close(actual, expected, atol=ATOL) -> None:
    np.testing.assert_allclose(
        np.asarray(actual, dtype=np.float64), np.asarray(expected, dtype=np.float64), rtol=1e-6, atol=atol
    )


def make_replay(n_actions: int = 2, **kwargs) -> PrioritizedReplay:
    options = dict(
        capacity=8,
        demo_capacity=10,
        n_step=3,
        gamma=G,
        alpha=0.5,
        eps_agent=0.25,
        eps_demo=1.0,
        seed=0,
    )
    options.update(kwargs)
    return PrioritizedReplay(2, n_actions, ReplaySettings(**options))


def make_rows(replay, tags, rewards=None, terminated=(), truncated=(), actions=None, pi_bc=None, sigma_sq=None):
    """Packed rows for tags t: s = [t, −t], s' = [t+1, −(t+1)]; `terminated`/`truncated` list positions."""
    t = np.asarray(tags, dtype=np.float32)
    n, A = len(t), replay.n_actions
    obs = np.stack([t, -t], axis=1)
    next_obs = np.stack([t + 1, -(t + 1)], axis=1)
    rewards = t + 1 if rewards is None else np.asarray(rewards, dtype=np.float32)
    term = np.zeros(n, np.float32)
    term[list(terminated)] = 1.0
    trunc = np.zeros(n, np.float32)
    trunc[list(truncated)] = 1.0
    actions = np.zeros(n, np.int32) if actions is None else np.asarray(actions, np.int32)
    pi_bc = np.full((n, A), 1.0 / A, np.float32) if pi_bc is None else np.asarray(pi_bc, np.float32)
    sigma_sq = np.full(n, 0.5, np.float32) if sigma_sq is None else np.asarray(sigma_sq, np.float32)
    return replay.rows(obs, actions, rewards, next_obs, term, trunc, pi_bc, sigma_sq)


def store_all(replay, rows) -> None:
    for row in rows:
        replay.store(row)


def n_rows(replay) -> int:
    return replay.demo_capacity + replay.capacity


def leaves(replay, indices) -> np.ndarray:
    return replay.tree.leaves(tf.constant(indices, tf.int32)).numpy()


def sample_only(replay, index, batch_size=4):
    """Sample with every priority but `index`'s set to zero, so the batch is that row only."""
    values = np.zeros(n_rows(replay), np.float32)
    values[index] = 1.0
    replay.tree.set(tf.range(n_rows(replay)), tf.constant(values))
    batch = replay.sample(batch_size, tf.constant(0.4))
    assert batch.indices.numpy().tolist() == [index] * batch_size
    return batch


def draw(replay, calls, batch_size=1000, beta=0.4) -> np.ndarray:
    return np.concatenate([replay.sample(batch_size, tf.constant(beta)).indices.numpy() for _ in range(calls)])


# --------------------------------------------------------------------------------------------
# 1. SumTree
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "mass, leaf",
    [
        (0.0, 0),
        (0.5, 0),
        (0.999, 0),
        (1.0, 2),  # the boundary of leaf 0 skips the empty leaf 1
        (1.2, 2),
        (3.9, 2),
        (4.0, 3),
        (4.1, 3),
        (5.9, 3),
        (6.0, 3),  # mass == total (float rounding at the edge) still lands on the last non-empty leaf
    ],
)
def test_sumtree_find_hand_built(mass, leaf):
    tree = SumTree(4)
    tree.set(tf.constant([0, 1, 2, 3]), tf.constant([1.0, 0.0, 3.0, 2.0]))
    close(tree.total, 1.0 + 0.0 + 3.0 + 2.0)
    assert tree.find(tf.constant([mass])).numpy().tolist() == [leaf]


def test_sumtree_zero_leaves_never_found():
    tree = SumTree(4)
    tree.set(tf.constant([0, 1, 2, 3]), tf.constant([1.0, 0.0, 3.0, 2.0]))
    masses = tf.constant(np.linspace(0.0, 6.0, 601, dtype=np.float32))
    found = tree.find(masses).numpy()
    assert set(found.tolist()) == {0, 2, 3}
    # leaf 0 holds [0, 1), leaf 2 [1, 4), leaf 3 [4, 6]
    m = masses.numpy()
    assert (found[m < 1.0] == 0).all()
    assert (found[(m >= 1.0 + 1e-6) & (m < 4.0 - 1e-6)] == 2).all()
    assert (found[m >= 4.0 + 1e-6] == 3).all()


def test_sumtree_multi_level_total_and_find():
    tree = SumTree(2000)  # 32 blocks of 64 leaves; 63 | 64 and 1023 | 1024 straddle block edges
    assert (tree.blocks, tree.width) == (32, 64)
    tree.set(tf.constant([0, 63, 64, 1023, 1024, 1999]), tf.constant([1.0, 2.0, 3.0, 4.0, 5.0, 6.0]))
    close(tree.total, 1 + 2 + 3 + 4 + 5 + 6)
    tree.set(tf.constant([63]), tf.constant([0.5]))  # overwrite one leaf
    close(tree.total, 1 + 0.5 + 3 + 4 + 5 + 6)
    close(tree.leaves(tf.constant([0, 63, 64, 1023, 1024, 1999, 7])), [1, 0.5, 3, 4, 5, 6, 0])
    # cumulative: leaf 0 → [0, 1), 63 → [1, 1.5), 64 → [1.5, 4.5), 1023 → [4.5, 8.5),
    #             1024 → [8.5, 13.5), 1999 → [13.5, 19.5)
    masses = tf.constant([0.5, 1.2, 1.5, 4.4, 4.6, 8.4, 8.6, 13.4, 13.6, 19.4])
    assert tree.find(masses).numpy().tolist() == [0, 63, 64, 64, 1023, 1023, 1024, 1024, 1999, 1999]
    tree.set(tf.constant([1999]), tf.constant([0.0]))
    close(tree.total, 1 + 0.5 + 3 + 4 + 5)
    assert tree.find(tf.constant([13.49])).numpy().tolist() == [1024]


def test_sumtree_with_nan_priorities_still_returns_stored_rows():
    """A diverged update writes NaN priorities: sampling must not crash a gather (the NaN loss
    is what stops the run, in `training.check_finite`)."""
    tree = SumTree(100)  # 2 blocks of 64 leaves, the last 28 padding
    tree.set(tf.range(100), tf.fill([100], float("nan")))
    found = tree.find(tf.constant([0.0, 1.0, float("nan")])).numpy()
    assert ((found >= 0) & (found < 100)).all()


def test_sumtree_many_sets_against_numpy():
    rng = np.random.default_rng(3)
    tree = SumTree(2000)
    reference = np.zeros(2000)
    for _ in range(5):
        index = rng.choice(2000, size=300, replace=False)
        value = rng.uniform(0.0, 3.0, size=300).astype(np.float32)
        value[:30] = 0.0
        tree.set(tf.constant(index), tf.constant(value))
        reference[index] = value
        np.testing.assert_allclose(float(tree.total), reference.sum(), rtol=1e-5)
    np.testing.assert_allclose(tree.leaves(tf.range(2000)).numpy(), reference, rtol=1e-6)
    # every found leaf is non-empty and its cumulative interval holds the mass
    masses = rng.uniform(0.0, reference.sum(), size=500).astype(np.float32)
    found = tree.find(tf.constant(masses)).numpy()
    cumulative = np.cumsum(reference)
    assert (reference[found] > 0).all()
    tol = 1e-3
    assert (cumulative[found] - reference[found] <= masses + tol).all()
    assert (masses <= cumulative[found] + tol).all()


# --------------------------------------------------------------------------------------------
# 2./3. Sampling proportions, determinism, importance weights
# --------------------------------------------------------------------------------------------

# α = 0.5, ε_d = 1, ε_a = 0.25: |δ| chosen so that (|δ|+ε)^½ is a round number.
DEMO_TD = [0.0, 3.0, 8.0, 0.0]  # (0+1)^½ = 1, (3+1)^½ = 2, (8+1)^½ = 3, 1
AGENT_TD = [0.75, 3.75, 0.0, 8.75]  # (0.75+0.25)^½ = 1, (3.75+.25)^½ = 2, (0+.25)^½ = 0.5, (8.75+.25)^½ = 3
PRIORITY = {0: 1.0, 1: 2.0, 2: 3.0, 3: 1.0, 10: 1.0, 11: 2.0, 12: 0.5, 13: 3.0}
TOTAL = 1 + 2 + 3 + 1 + 1 + 2 + 0.5 + 3  # 13.5


def proportional_replay(seed=0) -> PrioritizedReplay:
    replay = make_replay(seed=seed)
    replay.set_demos(make_rows(replay, [100, 101, 102, 103], terminated=[3]))
    store_all(replay, make_rows(replay, [0, 1, 2, 3]))
    replay.update_priorities(tf.constant([0, 1, 2, 3, 10, 11, 12, 13]), tf.constant(DEMO_TD + AGENT_TD))
    return replay


def test_priorities_of_the_proportional_setup():
    replay = proportional_replay()
    indices = sorted(PRIORITY)
    close(leaves(replay, indices), [PRIORITY[i] for i in indices])
    close(replay.tree.total, TOTAL)
    assert int(replay.size) == 8


def test_sampling_frequencies_match_priorities():
    replay = proportional_replay()
    samples = draw(replay, calls=20)  # 20 000 draws
    assert set(samples.tolist()) <= set(PRIORITY)
    for index, p in PRIORITY.items():
        frequency = np.mean(samples == index)
        # P = p / 13.5: 1/13.5 ≈ 0.074, 2/13.5 ≈ 0.148, 3/13.5 ≈ 0.222, 0.5/13.5 ≈ 0.037
        assert frequency == pytest.approx(p / 13.5, abs=0.012), (index, frequency)


def test_sampling_follows_p_alpha_not_p():
    # α = 0.5: a row with p = (|δ|+ε) = 9 is drawn 3 times as often as one with p = 1, not 9 times
    replay = make_replay(alpha=0.5, eps_demo=1.0)
    replay.set_demos(make_rows(replay, [0, 1], terminated=[1]))
    replay.update_priorities(tf.constant([0, 1]), tf.constant([0.0, 8.0]))
    samples = draw(replay, calls=10)
    assert np.mean(samples == 1) == pytest.approx(3 / (1 + 3), abs=0.015)


def test_same_seed_same_samples():
    a, b, c = proportional_replay(seed=7), proportional_replay(seed=7), proportional_replay(seed=8)
    draws_a = [a.sample(64, tf.constant(0.4)) for _ in range(3)]
    draws_b = [b.sample(64, tf.constant(0.4)) for _ in range(3)]
    for x, y in zip(draws_a, draws_b, strict=True):
        np.testing.assert_array_equal(x.indices.numpy(), y.indices.numpy())
        np.testing.assert_array_equal(x.weights.numpy(), y.weights.numpy())
    other = np.concatenate([c.sample(64, tf.constant(0.4)).indices.numpy() for _ in range(3)])
    assert not np.array_equal(np.concatenate([x.indices.numpy() for x in draws_a]), other)


@pytest.mark.parametrize("beta", [0.0, 0.6, 1.0])
def test_importance_weights_by_hand(beta):
    replay = proportional_replay()
    batch = replay.sample(256, tf.constant(beta))
    indices = batch.indices.numpy()
    assert {12, 13} <= set(indices.tolist())  # the rarest (p = 0.5) and a most likely (p = 3) row
    n = 8  # stored rows
    w = np.array([(n * PRIORITY[i] / 13.5) ** -beta for i in indices])
    close(batch.weights, w / w.max())
    close(batch.weights.numpy().max(), 1.0)
    weight = dict(zip(indices.tolist(), batch.weights.numpy().tolist(), strict=True))
    # the rarest row has the largest weight, 1; a p = 3 row has (3/0.5)^−β = 6^−β
    close(weight[12], 1.0)
    close(weight[13], 6.0**-beta)
    close(weight[11], 4.0**-beta)  # (2/0.5)^−β


# --------------------------------------------------------------------------------------------
# 4. Priority update and max priority
# --------------------------------------------------------------------------------------------


def test_update_priorities_by_hand():
    replay = make_replay(alpha=0.4, eps_demo=1.0, eps_agent=0.25)
    replay.set_demos(make_rows(replay, [0, 1, 2], terminated=[2]))
    store_all(replay, make_rows(replay, [10, 11]))
    close(leaves(replay, [0, 1, 2, 10, 11]), [1.0] * 5)  # everything enters at the initial max, 1
    close(replay.max_priority, 1.0)

    # same |δ| = 3 on a demo and an agent row: the demo bonus makes the difference
    replay.update_priorities(tf.constant([1, 10]), tf.constant([3.0, 3.0]))
    close(leaves(replay, [1, 10]), [(3 + 1.0) ** 0.4, (3 + 0.25) ** 0.4])  # 1.7411, 1.6017
    close(replay.max_priority, (3 + 1.0) ** 0.4)
    # the row at demo_capacity − 1 is a demo row, the one at demo_capacity an agent row
    replay.update_priorities(tf.constant([9, 11]), tf.constant([0.0, 0.0]))
    close(leaves(replay, [9, 11]), [(0 + 1.0) ** 0.4, (0 + 0.25) ** 0.4])  # 1, 0.5743
    close(leaves(replay, [0, 2]), [1.0, 1.0])  # untouched rows keep theirs

    # a smaller update leaves the max alone; a new row enters at the max
    replay.update_priorities(tf.constant([10]), tf.constant([0.5]))
    close(leaves(replay, [10]), [(0.5 + 0.25) ** 0.4])
    close(replay.max_priority, 4.0**0.4)
    store_all(replay, make_rows(replay, [12]))
    close(leaves(replay, [12]), [4.0**0.4])

    # a larger one raises it
    replay.update_priorities(tf.constant([0, 12]), tf.constant([1.0, 10.0]))
    close(replay.max_priority, (10 + 0.25) ** 0.4)
    close(
        replay.tree.total, (1 + 1.0) ** 0.4 + 4.0**0.4 + 1.0 + 0.75**0.4 + 0.25**0.4 + 10.25**0.4 + 1.0
    )  # rows 0, 1, 2, 10, 11, 12 and the never-stored row 9 (set to (0+1)^0.4 above)


def test_max_priority_stays_one_when_updates_are_small():
    replay = make_replay(alpha=0.5, eps_agent=0.25)
    store_all(replay, make_rows(replay, [0]))
    replay.update_priorities(tf.constant([10]), tf.constant([0.0]))
    close(leaves(replay, [10]), [0.5])  # (0 + 0.25)^½
    close(replay.max_priority, 1.0)
    store_all(replay, make_rows(replay, [1]))
    close(leaves(replay, [11]), [1.0])


def test_set_demos_enters_at_max_priority():
    replay = make_replay(alpha=0.5)
    replay.set_demos(make_rows(replay, [0, 1], terminated=[1]))
    replay.update_priorities(tf.constant([0]), tf.constant([3.0]))  # (3+1)^½ = 2
    replay.set_demos(make_rows(replay, [5, 6, 7], terminated=[2]))
    close(leaves(replay, [0, 1, 2]), [2.0, 2.0, 2.0])


# --------------------------------------------------------------------------------------------
# 5. Eviction and replacing D_demo
# --------------------------------------------------------------------------------------------


def test_agent_buffer_evicts_oldest_and_keeps_demos():
    replay = make_replay(capacity=8, demo_capacity=10)
    demo_rows = make_rows(replay, [100, 101, 102, 103, 104], terminated=[4])
    replay.set_demos(demo_rows)
    store_all(replay, make_rows(replay, range(8)))
    replay.update_priorities(tf.constant([10]), tf.constant([0.0]))  # the oldest row's priority: 0.5
    store_all(replay, make_rows(replay, range(8, 13)))  # 13 stored in a buffer of 8

    assert int(replay.agent_size) == 8
    assert int(replay.head) == 13 - 8  # 5: the next row to be overwritten
    assert int(replay.demo_size) == 5
    assert int(replay.size) == 5 + 8
    table = replay.table.numpy()
    # positions 0..4 were overwritten by tags 8..12, positions 5..7 still hold tags 5..7
    np.testing.assert_array_equal(table[10:18, 0], [8, 9, 10, 11, 12, 5, 6, 7])
    np.testing.assert_array_equal(table[10:18, 5], [9, 10, 11, 12, 13, 6, 7, 8])  # rewards t+1
    np.testing.assert_array_equal(table[0:5], demo_rows.numpy())  # demos untouched
    np.testing.assert_array_equal(table[5:10], np.zeros((5, table.shape[1])))
    # the overwritten row re-entered at max priority, not the 0.5 it had
    close(leaves(replay, range(18)), [1.0] * 5 + [0.0] * 5 + [1.0] * 8)
    close(replay.tree.total, 5 + 8)
    np.testing.assert_array_equal(replay.stored_indices().numpy(), [0, 1, 2, 3, 4] + list(range(10, 18)))

    samples = replay.sample(2000, tf.constant(0.4))
    tags = set(samples.obs.numpy()[:, 0].tolist())
    assert tags == {100, 101, 102, 103, 104, 5, 6, 7, 8, 9, 10, 11, 12}  # never the evicted 0..4


def test_set_demos_with_fewer_rows_drops_the_rest():
    replay = make_replay(capacity=8, demo_capacity=10)
    replay.set_demos(make_rows(replay, [100, 101, 102, 103, 104], terminated=[4]))
    store_all(replay, make_rows(replay, [0, 1]))
    replay.set_demos(make_rows(replay, [200, 201, 202], terminated=[2]))
    assert int(replay.demo_size) == 3
    close(leaves(replay, [0, 1, 2, 3, 4, 10, 11]), [1, 1, 1, 0, 0, 1, 1])
    close(replay.tree.total, 3 + 2)
    np.testing.assert_array_equal(replay.table.numpy()[0:3, 0], [200, 201, 202])
    samples = draw(replay, calls=3)
    assert set(samples.tolist()) == {0, 1, 2, 10, 11}
    np.testing.assert_array_equal(replay.stored_indices().numpy(), [0, 1, 2, 10, 11])


# --------------------------------------------------------------------------------------------
# 6. n-step returns
# --------------------------------------------------------------------------------------------


def load(replay, rows, region) -> int:
    """Put `rows` into D_demo or D_replay; the table index of the first one."""
    if region == "demo":
        replay.set_demos(rows)
        return 0
    store_all(replay, rows)
    return replay.demo_capacity


def check_n_step(replay, index, n_return, n_discount, n_next_obs) -> None:
    batch = sample_only(replay, index)
    close(batch.n_returns, [n_return] * 4)
    close(batch.n_discount, [n_discount] * 4)
    close(batch.n_next_obs, [n_next_obs] * 4)


REGIONS = pytest.mark.parametrize("region", ["demo", "agent"])


@REGIONS
@pytest.mark.parametrize(
    "n_step, position, n_return, n_discount, n_next_obs",
    [
        # rewards r_t = t+1 = 1, 2, 3, 4, 5, 6; the episode terminates at t = 5
        (3, 0, 1 + 0.9 * 2 + 0.9**2 * 3, 0.9**3, [3, -3]),  # 5.23, s_3
        (3, 2, 3 + 0.9 * 4 + 0.9**2 * 5, 0.9**3, [5, -5]),  # 10.65, s_5
        (4, 0, 1 + 0.9 * 2 + 0.9**2 * 3 + 0.9**3 * 4, 0.9**4, [4, -4]),  # 8.146, s_4
        (4, 1, 2 + 0.9 * 3 + 0.9**2 * 4 + 0.9**3 * 5, 0.9**4, [5, -5]),
        (3, 4, 5 + 0.9 * 6, 0.0, [6, -6]),  # hits the termination
        (3, 5, 6, 0.0, [6, -6]),
    ],
)
def test_n_step_inside_an_episode(region, n_step, position, n_return, n_discount, n_next_obs):
    replay = make_replay(n_step=n_step)
    start = load(replay, make_rows(replay, range(6), terminated=[5]), region)
    check_n_step(replay, start + position, n_return, n_discount, n_next_obs)


@REGIONS
@pytest.mark.parametrize(
    "terminated, truncated, position, n_return, n_discount, n_next_obs",
    [
        # episode A = t 0..1, episode B = t 2..5 (terminates at 5); rewards 1..6
        ([1, 5], [], 0, 1 + 0.9 * 2, 0.0, [2, -2]),  # stops at the termination, no bootstrap
        ([1, 5], [], 1, 2, 0.0, [2, -2]),
        ([1, 5], [], 2, 3 + 0.9 * 4 + 0.9**2 * 5, 0.9**3, [5, -5]),  # the next episode is not affected
        ([5], [1], 0, 1 + 0.9 * 2, 0.9**2, [2, -2]),  # a truncation stops but bootstraps
        ([5], [1], 1, 2, 0.9, [2, -2]),
        ([1, 5], [1], 0, 1 + 0.9 * 2, 0.0, [2, -2]),  # both flags: a termination
        ([5], [0], 0, 1, 0.9, [1, -1]),  # truncated at the first step: m = 1
        ([0, 5], [], 0, 1, 0.0, [1, -1]),  # terminated at the first step
    ],
)
def test_n_step_across_episode_boundary(region, terminated, truncated, position, n_return, n_discount, n_next_obs):
    replay = make_replay(n_step=3)
    rows = make_rows(replay, range(6), terminated=terminated, truncated=truncated)
    start = load(replay, rows, region)
    check_n_step(replay, start + position, n_return, n_discount, n_next_obs)


@REGIONS
def test_n_step_stops_at_the_newest_transition(region):
    # an ongoing episode (no flags): the window ends at the last row stored so far
    replay = make_replay(n_step=3)
    start = load(replay, make_rows(replay, [0, 1]), region)
    check_n_step(replay, start + 0, 1 + 0.9 * 2, 0.9**2, [2, -2])  # m = 2
    check_n_step(replay, start + 1, 2, 0.9, [2, -2])  # m = 1
    if region == "agent":
        store_all(replay, make_rows(replay, [2]))  # the episode goes on
    else:
        replay.set_demos(make_rows(replay, [0, 1, 2]))
    check_n_step(replay, start + 0, 1 + 0.9 * 2 + 0.9**2 * 3, 0.9**3, [3, -3])  # m = 3 now
    check_n_step(replay, start + 1, 2 + 0.9 * 3, 0.9**2, [3, -3])


def test_n_step_ignores_stale_demo_rows_after_set_demos_shrinks():
    replay = make_replay(n_step=3)
    replay.set_demos(make_rows(replay, range(6), rewards=[100] * 6, terminated=[5]))
    replay.set_demos(make_rows(replay, [0, 1, 2]))  # an incomplete episode, rewards 1, 2, 3
    check_n_step(replay, 1, 2 + 0.9 * 3, 0.9**2, [3, -3])  # not 2 + 0.9·3 + 0.81·100
    check_n_step(replay, 2, 3, 0.9, [3, -3])


@pytest.mark.parametrize(
    "position, n_return, n_discount, n_next_obs",
    [
        # capacity 4, tags 0..5 stored (rewards 1..6): positions hold [4, 5, 2, 3], head = 2
        (3, 4 + 0.9 * 5 + 0.9**2 * 6, 0.9**3, [6, -6]),  # t = 3, 4, 5 — across the buffer's end: 13.36
        (2, 3 + 0.9 * 4 + 0.9**2 * 5, 0.9**3, [5, -5]),  # t = 2, 3, 4: 10.65
        (0, 5 + 0.9 * 6, 0.9**2, [6, -6]),  # t = 4, 5, then the newest: m = 2
        (1, 6, 0.9, [6, -6]),  # t = 5, the newest
    ],
)
def test_n_step_wraps_around_the_agent_buffer(position, n_return, n_discount, n_next_obs):
    replay = make_replay(n_step=3, capacity=4, demo_capacity=5)
    replay.set_demos(make_rows(replay, [50, 51, 52, 53, 54], rewards=[1000] * 5))  # no leak from here
    store_all(replay, make_rows(replay, range(6)))
    np.testing.assert_array_equal(replay.table.numpy()[5:9, 0], [4, 5, 2, 3])
    assert int(replay.head) == 2
    check_n_step(replay, 5 + position, n_return, n_discount, n_next_obs)


def test_n_step_wraps_around_and_stops_at_a_termination():
    replay = make_replay(n_step=3, capacity=4, demo_capacity=5)
    replay.set_demos(make_rows(replay, [50], rewards=[1000], terminated=[0]))
    store_all(replay, make_rows(replay, range(6), terminated=[4]))  # positions hold [4, 5, 2, 3]
    check_n_step(replay, 5 + 3, 4 + 0.9 * 5, 0.0, [5, -5])  # t = 3, 4 (terminated)
    check_n_step(replay, 5 + 1, 6, 0.9, [6, -6])  # t = 5 begins a new episode


@pytest.mark.parametrize(
    "flags, position, n_return, n_discount, n_next_obs",
    [
        # D_demo fills the region (6 rows, demo_capacity 6): episode 1 = t 0..2 (terminated),
        # episode 2 = t 3..5, ending truncated, or unfinished (ending at the last demo row)
        ("truncated", 1, 2 + 0.9 * 3, 0.0, [3, -3]),
        ("truncated", 0, 1 + 0.9 * 2 + 0.9**2 * 3, 0.0, [3, -3]),
        ("truncated", 3, 4 + 0.9 * 5 + 0.9**2 * 6, 0.9**3, [6, -6]),
        ("truncated", 4, 5 + 0.9 * 6, 0.9**2, [6, -6]),
        ("truncated", 5, 6, 0.9, [6, -6]),
        ("open", 4, 5 + 0.9 * 6, 0.9**2, [6, -6]),  # the demo region ends: no agent rows follow
        ("open", 5, 6, 0.9, [6, -6]),
    ],
)
def test_n_step_demo_episodes_in_time_order(flags, position, n_return, n_discount, n_next_obs):
    replay = make_replay(n_step=3, capacity=4, demo_capacity=6)
    store_all(replay, make_rows(replay, [60, 61, 62, 63], rewards=[1000] * 4))  # right after the demos
    truncated = [5] if flags == "truncated" else []
    replay.set_demos(make_rows(replay, range(6), terminated=[2], truncated=truncated))
    check_n_step(replay, position, n_return, n_discount, n_next_obs)


def test_n_step_private_helper_agrees_for_a_whole_batch():
    # the same windows evaluated together, without sampling
    replay = make_replay(n_step=3)
    replay.set_demos(make_rows(replay, range(6), terminated=[1, 5]))
    store_all(replay, make_rows(replay, range(10, 13)))  # rewards 11, 12, 13; ongoing
    indices = tf.constant([0, 2, 4, 10, 11, 12])
    window = tf.gather(replay.table, replay._window(indices))
    n_returns, n_next_obs, n_discount = replay._n_step(indices, window)
    close(
        n_returns, [1 + 0.9 * 2, 3 + 0.9 * 4 + 0.9**2 * 5, 5 + 0.9 * 6, 11 + 0.9 * 12 + 0.9**2 * 13, 12 + 0.9 * 13, 13]
    )
    close(n_discount, [0.0, 0.9**3, 0.0, 0.9**3, 0.9**2, 0.9])
    close(n_next_obs, [[2, -2], [5, -5], [6, -6], [13, -13], [13, -13], [13, -13]])


def test_n_step_view_equals_the_windows_recomputed_on_a_random_stream():
    """The cached view (refreshed when a row's window changes, for stored rows when they are settled)
    is the plain windowed computation after every settle: random episode ends, 1 to 3 rows stored
    between settles, D_demo replaced twice, the agent buffer wrapping 5 times."""
    rng = np.random.default_rng(7)
    replay = make_replay(n_step=4, capacity=6, demo_capacity=8)

    def flags(n):
        return [i for i in range(n) if rng.random() < 0.2], [i for i in range(n) if rng.random() < 0.1]

    tag = 0
    for round_ in range(3):
        terminated, truncated = flags(5 + round_)
        replay.set_demos(
            make_rows(
                replay,
                range(100 * round_, 100 * round_ + 5 + round_),
                rewards=rng.normal(size=5 + round_),
                terminated=terminated,
                truncated=truncated,
            )
        )
        for _ in range(10):
            n = int(rng.integers(1, 4))
            terminated, truncated = flags(n)
            rows = make_rows(replay, range(tag, tag + n), rng.normal(size=n), terminated, truncated)
            store_all(replay, rows)
            tag += n
            assert int(replay.unsettled.numpy()) == n
            replay.settle()
            indices = replay.stored_indices()
            plain = replay._n_step(indices, tf.gather(replay.table, replay._window(indices)))
            cached = tf.split(tf.gather(replay.n_step_view, indices), [1, 2, 1], axis=1)
            for expected, got in zip(plain, (cached[0][:, 0], cached[1], cached[2][:, 0]), strict=True):
                np.testing.assert_array_equal(got.numpy(), expected.numpy())


# --------------------------------------------------------------------------------------------
# 7. 1-step fields
# --------------------------------------------------------------------------------------------


def test_one_step_fields_round_trip():
    replay = make_replay(n_actions=3, capacity=4, demo_capacity=4, n_step=2)
    # flags per row (terminated, truncated): (0,0), (1,0), (0,1), (1,1)
    pi = [[0.1, 0.2, 0.7], [0.5, 0.25, 0.25], [0.0, 1.0, 0.0], [0.6, 0.3, 0.1]]
    replay.set_demos(
        make_rows(
            replay,
            [0, 1, 2, 3],
            rewards=[-1.5, 0.0, 2.5, 100.0],
            terminated=[1, 3],
            truncated=[2, 3],
            actions=[2, 0, 1, 2],
            pi_bc=pi,
            sigma_sq=[0.5, 0.75, 1.0, 2.0],
        )
    )
    store_all(
        replay,
        make_rows(
            replay,
            [10, 11, 12, 13],
            rewards=[1.0, -2.0, 3.0, -100.0],
            terminated=[1, 3],
            truncated=[2, 3],
            actions=[1, 2, 0, 1],
            pi_bc=pi[::-1],
            sigma_sq=[3, 4, 5, 6],
        ),
    )
    expected = {
        # index: (tag, action, reward, discount, pi_bc, sigma_sq, is_demo)
        0: (0, 2, -1.5, 0.9, pi[0], 0.5, 1.0),
        1: (1, 0, 0.0, 0.0, pi[1], 0.75, 1.0),
        2: (2, 1, 2.5, 0.9, pi[2], 1.0, 1.0),  # truncated keeps γ
        3: (3, 2, 100.0, 0.0, pi[3], 2.0, 1.0),  # row demo_capacity − 1 is still a demo row
        4: (10, 1, 1.0, 0.9, pi[3], 3.0, 0.0),  # row demo_capacity is the first agent row
        5: (11, 2, -2.0, 0.0, pi[2], 4.0, 0.0),
        6: (12, 0, 3.0, 0.9, pi[1], 5.0, 0.0),
        7: (13, 1, -100.0, 0.0, pi[0], 6.0, 0.0),
    }
    batch = replay.sample(256, tf.constant(0.4))
    assert batch.actions.dtype == tf.int32
    assert batch.indices.dtype == tf.int32
    got = batch.indices.numpy()
    assert set(got.tolist()) == set(expected)
    for field in (
        "obs",
        "rewards",
        "next_obs",
        "discount",
        "pi_bc",
        "sigma_sq",
        "is_demo",
        "weights",
        "n_returns",
        "n_discount",
        "n_next_obs",
    ):
        assert getattr(batch, field).dtype == tf.float32, field
    for b, index in enumerate(got):
        tag, action, reward, discount, pi_bc, sigma_sq, is_demo = expected[index]
        close(batch.obs[b], [tag, -tag])
        close(batch.next_obs[b], [tag + 1, -(tag + 1)])
        assert int(batch.actions[b]) == action
        close(batch.rewards[b], reward)
        close(batch.discount[b], discount)
        close(batch.pi_bc[b], pi_bc)
        close(batch.sigma_sq[b], sigma_sq)
        assert float(batch.is_demo[b]) == is_demo  # exactly 1.0 or 0.0
    assert batch.obs.shape == (256, 2) and batch.pi_bc.shape == (256, 3)


def test_set_expert_targets_overwrites_only_pi_bc_and_sigma_sq():
    replay = make_replay(capacity=4, demo_capacity=4, n_step=2)
    replay.set_demos(make_rows(replay, [0, 1], terminated=[1]))
    store_all(replay, make_rows(replay, [10]))
    before = replay.table.numpy()
    replay.set_expert_targets(tf.constant([1, 4]), tf.constant([[0.9, 0.1], [0.2, 0.8]]), tf.constant([7.0, 8.0]))
    after = replay.table.numpy()
    np.testing.assert_array_equal(after[[0, 2, 3, 5, 6, 7]], before[[0, 2, 3, 5, 6, 7]])
    np.testing.assert_array_equal(after[[1, 4], :8], before[[1, 4], :8])  # s, s', a, r, flags kept
    close(after[[1, 4], 8:10], [[0.9, 0.1], [0.2, 0.8]])
    close(after[[1, 4], 10], [7.0, 8.0])


# --------------------------------------------------------------------------------------------
# 8. Errors
# --------------------------------------------------------------------------------------------


def test_capacity_below_n_step_is_a_config_error():
    with pytest.raises(ConfigError, match=r"n_step=10.*got 5"):
        make_replay(capacity=5, n_step=10)
    make_replay(capacity=3, n_step=3)  # equal is fine


def test_a_runs_replay_has_its_configs_sizes_returns_and_priorities():
    config = Config.for_task(
        "cartpole",
        replay_capacity=3000,
        demo_capacity=600,
        n_step=4,
        gamma=0.9,
        priority_alpha=0.6,
        priority_eps_agent=0.01,
        priority_eps_demo=0.5,
        seed=3,
    )
    replay = PrioritizedReplay(4, 2, ReplaySettings.from_config(config))
    got = (replay.capacity, replay.demo_capacity, replay.n_step, replay.gamma, replay.alpha)
    assert got == (3000, 600, 4, 0.9, 0.6) and (replay.eps_agent, replay.eps_demo) == (0.01, 0.5)
    assert replay.table.shape == (3600, 2 * 4 + 5 + 2) and ReplaySettings.from_config(config).seed == 3


@pytest.mark.parametrize("n", [0, 11])
def test_set_demos_size_out_of_range_is_a_config_error(n):
    replay = make_replay(demo_capacity=10)
    with pytest.raises(ConfigError, match=rf"demo_capacity=10.*got {n}\b"):
        replay.set_demos(make_rows(replay, list(range(n))))
    assert int(replay.demo_size) == 0


def test_set_demos_wrong_width_is_a_config_error():
    replay = make_replay()
    with pytest.raises(ConfigError, match="width"):
        replay.set_demos(tf.zeros([3, 5]))
