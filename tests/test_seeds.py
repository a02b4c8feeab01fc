"""Seed derivations: deterministic, and the streams of one run never share a seed."""

from dqfd_bc_keras.seeds import BC_FIT, ROLLOUT, TRAIN, demo_seed, episode_seed, eval_seed, final_eval_seed


def test_episode_seed_is_deterministic_and_distinct_per_episode_and_stream():
    seed = episode_seed(0, 3)
    assert episode_seed(0, 3) == seed == episode_seed(0, 3, TRAIN)
    assert len({episode_seed(0, e) for e in range(200)}) == 200
    assert len({episode_seed(0, 3, stream) for stream in (TRAIN, ROLLOUT, BC_FIT)}) == 3
    assert episode_seed(1, 3) != seed


def test_demo_and_evaluation_seeds_keep_their_ranges_apart():
    assert [demo_seed(s) for s in (0, 1, 2)] == [0, 1000, 2000]
    assert [eval_seed(s) for s in (0, 1)] == [10_000, 11_000]
    assert final_eval_seed(3) == 13_000 + 1_000_000
    for seed in range(100):  # within one run, demonstrations and evaluations never share a reset seed
        demos = {demo_seed(seed) + i for i in range(20)}
        evals = {eval_seed(seed) + i for i in range(20)}
        final = {final_eval_seed(seed) + i for i in range(100)}
        assert not demos & evals and not demos & final and not evals & final
