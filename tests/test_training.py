"""Algorithm 1 end to end (ALGORITHM.md §4–§6): the early-stopping rule, the ε schedule, episode
seeds, the demonstrations step, one interaction episode as one graph call, dynamic
demonstrations, the run directory `runs.train` writes, and the config's typed overrides.

Every budget is tiny: two learners are built once per module and shared, and two 300-step runs
are trained end to end.
"""

import csv
import dataclasses
import itertools
import json

import numpy as np
import pytest
import tensorflow as tf

import dqfd_bc_keras  # noqa: F401  (first: TF settings, custom objects)
from dqfd_bc_keras import demos as demo_io
from dqfd_bc_keras.choices import LOSS_TERMS
from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.envs.make import make_task
from dqfd_bc_keras.errors import ConfigError, OutputExistsError
from dqfd_bc_keras.evaluation import GreedyPolicy, load_model
from dqfd_bc_keras.runs import directory as runs
from dqfd_bc_keras.seeds import ROLLOUT, episode_seed
from dqfd_bc_keras.training import loop as training
from dqfd_bc_keras.training.dynamic import DynamicDemos
from dqfd_bc_keras.training.records import DemoSummary, DemoUpdate, EpisodeRow, EvalRow, Losses
from dqfd_bc_keras.training.state import TrainingState

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def tiny(expert_loss: str = "bayes", **overrides) -> Config:
    settings = dict(
        expert_loss=expert_loss,
        total_steps=300,
        pretrain_steps=20,
        bc_epochs=1,
        bc_refit_epochs=1,
        demo_episodes=2,
        eval_every=150,
        eval_episodes=1,
        final_eval_episodes=1,
        checkpoint_every=150,
        replay_capacity=2000,
        demo_capacity=5000,
    )
    settings.update(overrides)
    return Config.for_task("cartpole", **settings)


def ret(episode: demo_io.DemoDataset) -> float:
    return episode.meta.episode_returns[0]


# --- the early-stopping rule (§6) ----------------------------------------------------------------


def test_early_stop_needs_the_whole_window_at_98_percent_of_the_limit():
    config = Config.for_task("cartpole", early_stop_window=10, early_stop_fraction=0.98)
    assert config.limit == 500
    assert training.early_stop(config, [490.0] * 10)
    assert training.early_stop(config, [12.0, -80.0] + [490.0] * 10)  # only the last 10 count
    assert not training.early_stop(config, [500.0] * 9 + [489.9])
    assert not training.early_stop(config, [489.9] + [500.0] * 9)
    assert not training.early_stop(config, [500.0] * 9)
    assert not training.early_stop(config, [])
    never = Config.for_task("cartpole", early_stop_window=0)
    assert not training.early_stop(never, [500.0] * 100)


def test_early_stop_threshold_follows_the_step_limit():
    short = Config.for_task("cartpole-200")
    assert short.limit == 200 and short.early_stop_window == 10
    assert training.early_stop(short, [196.0] * 10)  # 0.98 × 200
    assert not training.early_stop(short, [196.0] * 9 + [195.9])
    capped = Config.for_task("cartpole", max_steps=100)
    assert training.early_stop(capped, [98.0] * 10)
    assert not training.early_stop(capped, [97.9] * 10)
    assert Config.for_task("mountaincar").early_stop_window == 0


# --- episode seeds -------------------------------------------------------------------------------


def test_run_state_round_trips_through_json():
    row = EpisodeRow(
        episode=1,
        env_step=20,
        interactions=20,
        return_=20.0,
        plain_return=20.0,
        length=20,
        goals=0,
        epsilon=0.5,
        losses=Losses(1.0, 0.5, 0.25, 0.125, 0.0625),
        demo_size=100,
        wall_time=1.5,
    )
    update = DemoUpdate(
        episode=1,
        env_step=20,
        interactions=25,
        moving_average=20.0,
        mode="rollouts",
        new_returns=[30.0],
        new_transitions=5,
        demo_transitions=105,
        demo_episodes=3,
        bc_accuracy=0.5,
    )
    state = TrainingState(
        episode=3,
        returns=[1.0, -50.0, 500.0],
        metrics=[row],
        bc_fits=2,
        demo_updates=[update],
        evals=[EvalRow(env_step=0, interactions=0, episode=0, mean_return=9.5, std_return=0.5)],
    )
    assert state.best_average == -np.inf
    fields = json.loads(json.dumps(state.to_dict()))
    assert (fields["metrics"][0]["return"], fields["metrics"][0]["td"], fields["evals"][0]["mean_goals"]) == (
        20.0,
        0.5,
        None,
    )
    assert list(fields["metrics"][0]) == list(EpisodeRow.columns())  # state.json keys rows as metrics.csv does
    assert TrainingState.from_dict({**fields, "unknown": 1}) == state


# --- step 1: demonstrations ----------------------------------------------------------------------


def test_demonstrations_records_the_configured_expert_with_the_timeout_and_limit():
    config = tiny(timeout="naive", max_steps=30, seed=2)
    data = training.demonstrations(config, None)
    assert data.n_episodes == 2 and len(data) == 60  # the imperfect expert outlasts 30 steps
    assert (data.meta.task, data.meta.expert, data.meta.timeout, data.meta.seed) == (
        "cartpole",
        "imperfect",
        "naive",
        2000,
    )
    assert data.meta.episode_returns == [30.0, 30.0]
    # naive mode: the time limit is a termination, never a truncation
    assert not data.truncated.any()
    assert np.flatnonzero(data.terminated).tolist() == [29, 59]
    again = demo_io.record("cartpole", "imperfect", 2, seed=2000, timeout="naive", max_steps=30)
    np.testing.assert_array_equal(data.obs, again.obs)
    np.testing.assert_array_equal(data.actions, again.actions)


def test_demonstrations_passes_a_dataset_through_and_none_has_none(demos):
    assert training.demonstrations(tiny(), demos) is demos
    assert training.demonstrations(tiny("none"), None) is None
    assert training.demonstrations(tiny("none"), demos) is None


# --- step 2: the pre-trained learner -------------------------------------------------------------


@pytest.fixture(scope="module")
def built():
    """The tiny bayes learner, and its counters right after `build`."""
    config = tiny()
    learner, losses = training.build(config)
    snapshot = {
        "train_steps": int(learner.agent.train_steps.numpy()),
        "agent_size": int(learner.agent.replay.agent_size.numpy()),
        "env_steps": int(learner.interaction.env_steps.numpy()),
    }
    return learner, losses, snapshot


def test_build_fits_bc_and_pretrains_on_the_recorded_demonstrations(built):
    learner, losses, snapshot = built
    config, agent = learner.config, learner.agent
    data = training.demonstrations(config, None)
    assert snapshot == {"train_steps": config.pretrain_steps, "agent_size": 0, "env_steps": 0}
    assert int(agent.replay.demo_size.numpy()) == len(data)
    np.testing.assert_array_equal(agent.replay.table.numpy()[: len(data), agent.replay.OBS], data.obs)
    assert set(losses) == set(LOSS_TERMS) and all(np.isfinite(v) for v in losses.values())
    assert learner.bc is not None and learner.dynamic is not None
    assert learner.dynamic.demo_average == pytest.approx(np.mean(data.meta.episode_returns))


# --- step 3: ε-greedy schedule -------------------------------------------------------------------


@pytest.mark.parametrize("loss, start", [("bayes", 0.1), ("none", 1.0)])
def test_epsilon_decays_linearly_over_the_first_tenth_of_the_budget(built, loss, start):
    learner = built[0]
    config = tiny(loss)  # total_steps 300, epsilon_fraction 0.1: the decay ends at env step 30
    assert config.initial_epsilon == start
    interaction = training.Interaction(learner.agent, learner.interaction.env, config)
    end = config.epsilon_end
    for steps, expected in [
        (0, start),
        (6, start - (start - end) * 0.2),
        (15, (start + end) / 2),
        (30, end),
        (31, end),
        (300, end),
    ]:
        interaction.env_steps.assign(steps)
        assert float(interaction.epsilon()) == pytest.approx(expected, abs=1e-6), steps


def test_epsilon_start_can_be_set():
    assert tiny(epsilon_start=0.5).initial_epsilon == 0.5
    assert tiny("none", epsilon_start=0.0).initial_epsilon == 0.0


# --- step 3: one episode is one graph call -------------------------------------------------------


def episode_rows(agent, length: int) -> np.ndarray:
    """The last `length` rows stored in D_replay (no wrap-around at these sizes)."""
    replay = agent.replay
    head = int(replay.head.numpy())
    assert head >= length
    return replay.table.numpy()[replay.demo_capacity + head - length : replay.demo_capacity + head]


def test_one_episode_acts_stores_and_learns_every_step(built):
    learner = built[0]
    agent, interaction = learner.agent, learner.interaction
    replay = agent.replay
    assert int(replay.size.numpy()) >= learner.config.batch_size  # the demos alone fill a batch
    obs = interaction.reset(episode_seed(learner.config.seed, 0))
    env0, size0, train0 = (int(v.numpy()) for v in (interaction.env_steps, replay.agent_size, agent.train_steps))

    last_obs, done = interaction.play(tf.constant(obs, tf.float32), tf.constant(10_000, tf.int64))

    stats = interaction.episode
    length = stats.length
    assert bool(done) and 8 <= length <= 500
    assert int(interaction.env_steps.numpy()) - env0 == length
    assert int(replay.agent_size.numpy()) - size0 == length
    assert int(agent.train_steps.numpy()) - train0 == length  # train_freq 1, replay ≥ batch_size throughout
    assert stats.plain == length
    rows = episode_rows(agent, length)
    np.testing.assert_array_equal(rows[0, replay.OBS], obs)
    np.testing.assert_array_equal(rows[1:, replay.OBS], rows[:-1, replay.NEXT_OBS])  # one continuous episode
    np.testing.assert_array_equal(rows[-1, replay.NEXT_OBS], last_obs.numpy())
    assert not rows[:-1, replay.TERMINATED].any() and not rows[:-1, replay.TRUNCATED].any()
    np.testing.assert_array_equal(rows[:-1, replay.REWARD], 1.0)
    if rows[-1, replay.TERMINATED]:  # the pole fell: −100 instead of +1 on the last step
        assert length < 500 and rows[-1, replay.TRUNCATED] == 0
        assert rows[-1, replay.REWARD] == -100.0
        assert stats.ret == length - 1 - 100
    else:  # the 500-step limit
        assert length == 500 and rows[-1, replay.TRUNCATED] == 1
        assert stats.ret == 500


def test_play_stops_at_the_step_budget_and_the_episode_continues(built):
    learner = built[0]
    interaction = learner.interaction
    obs = interaction.reset(episode_seed(learner.config.seed, 1))
    env0 = int(interaction.env_steps.numpy())
    obs3, done = interaction.play(tf.constant(obs, tf.float32), tf.constant(3, tf.int64))
    assert not bool(done)
    assert int(interaction.env_steps.numpy()) - env0 == 3 and interaction.episode.length == 3
    assert interaction.episode.ret == 3.0  # no pole falls within 3 steps
    rows = episode_rows(learner.agent, 3)
    assert not rows[:, learner.agent.replay.TRUNCATED].any() and not rows[:, learner.agent.replay.TERMINATED].any()
    _, done = interaction.play(obs3, tf.constant(10_000, tf.int64))  # the same episode, on from step 3
    assert bool(done)
    assert int(interaction.env_steps.numpy()) - env0 == interaction.episode.length > 3


@pytest.mark.slow
def test_a_bayes_run_learns_the_same_whatever_its_evaluation_grid():
    """The replay settles its newest rows (their n-step returns, the BC model's MC-dropout view) before
    each sample and every SETTLE_ROWS rows, never where a graph call ends: so where `play` stops (the
    evaluation grid) changes no draw, and the two runs end with the same weights and the same replay."""
    ends = []
    for every in (150, 70):  # a learning step every 4 env steps: 70 is not a multiple of 4, nor 302
        learner, _ = training.build(tiny(eval_every=every, train_freq=4, total_steps=302))
        training.train_episodes(learner, TrainingState(), lambda *_: None, lambda points: [])
        agent = learner.agent
        assert int(agent.replay.unsettled.numpy()) > 0  # the last rows wait for a sample that never came
        ends.append([*agent.q_network.get_weights(), agent.replay.table.numpy(), agent.replay.n_step_view.numpy()])
    for first, second in zip(*ends, strict=True):
        np.testing.assert_array_equal(first, second)


@pytest.mark.parametrize("timeout, terminated, truncated", [("bootstrap", 0.0, 1.0), ("naive", 1.0, 0.0)])
def test_an_episode_cut_by_the_time_limit_stores_the_timeout_modes_flags(built, timeout, terminated, truncated):
    """max_steps=5: CartPole's pole cannot fall in fewer than 8 steps, so the limit always ends it.
    train_freq=2 from env step 0: learning steps at env steps 2 and 4 only."""
    learner = built[0]
    agent = learner.agent
    config = tiny(max_steps=5, timeout=timeout, train_freq=2)
    env = make_task("cartpole", timeout=timeout, max_steps=5)
    interaction = training.Interaction(agent, env, config)
    obs, _ = env.reset(seed=7)
    train0, size0 = int(agent.train_steps.numpy()), int(agent.replay.agent_size.numpy())
    _, done = interaction.play(tf.constant(obs, tf.float32), tf.constant(10_000, tf.int64))
    assert bool(done)
    assert int(interaction.env_steps.numpy()) == 5 and int(agent.replay.agent_size.numpy()) - size0 == 5
    assert int(agent.train_steps.numpy()) - train0 == 2
    assert (interaction.episode.length, interaction.episode.ret, interaction.episode.plain) == (5, 5.0, 5.0)
    replay = agent.replay
    head = int(replay.head.numpy())
    last = replay.table.numpy()[replay.demo_capacity + (head - 1)]
    assert (last[replay.TERMINATED], last[replay.TRUNCATED]) == (terminated, truncated)
    assert last[replay.REWARD] == 1.0
    rows = episode_rows(agent, 5)
    assert not rows[:-1, replay.TERMINATED].any() and not rows[:-1, replay.TRUNCATED].any()


# --- step 4: dynamic demonstrations (§5) ---------------------------------------------------------


def test_dynamic_demos_are_due_at_a_new_best_moving_average_at_least_the_demos(demos):
    assert demos.meta.episode_returns == [500.0] * 5
    config = tiny(dynamic_window=3)
    dynamic = DynamicDemos(config, demos, env=None)
    assert dynamic.demo_average == 500.0
    state = training.TrainingState()
    for r in (500.0, 500.0):
        state.returns.append(r)
        assert not dynamic.due(state)  # fewer than W returns
    state.returns.append(500.0)
    assert dynamic.due(state) and state.best_average == 500.0
    state.returns.append(500.0)
    assert not dynamic.due(state)  # 500 again: no new best
    state.returns.append(530.0)
    assert dynamic.due(state) and state.best_average == 510.0  # (500 + 500 + 530) / 3
    state.returns.append(470.0)
    assert not dynamic.due(state) and state.best_average == 510.0  # 500: below the best

    below = training.TrainingState()
    for r in [499.0] * 5 + [400.0, 600.0, 497.0]:  # moving averages 499, …, 499.0, 499.67, 499.0 < 500
        below.returns.append(r)
        assert not dynamic.due(below)
    assert below.best_average == -np.inf


@pytest.fixture(scope="module")
def capped():
    """A bayes learner whose episodes last at most 50 steps, M = 3 rollouts per update."""
    learner, _ = training.build(tiny(max_steps=50, dynamic_demos="rollouts", dynamic_rollouts=3, dynamic_window=3))
    return learner


def greedy_rollouts(learner, episode: int) -> demo_io.DemoDataset:
    """What `update` should add at `state.episode = episode`: M greedy episodes on stream 2."""
    c = learner.config
    seeds = [episode_seed(c.seed, episode * 100 + i, ROLLOUT) for i in range(c.dynamic_rollouts)]
    return demo_io.rollout(
        make_task(c.task, timeout=c.timeout, max_steps=c.max_steps),
        GreedyPolicy.from_model(learner.agent.q_network),
        seeds,
        task=c.task,
        source="agent",
    )


def test_dynamic_update_adds_m_greedy_episodes_and_refits_bc(capped):
    learner = capped
    agent, dynamic, bc = learner.agent, learner.dynamic, learner.bc
    episodes0 = len(dynamic.episodes)
    size0 = int(agent.replay.demo_size.numpy())
    expected = greedy_rollouts(learner, episode=7)
    weights0 = [w.numpy().copy() for w in bc.trainable_weights]
    state = training.TrainingState(episode=7, best_average=50.0)

    update = dynamic.update(agent, bc, state, env_step=1234, interactions=1500)

    assert (update.env_step, update.interactions, update.mode) == (1234, 1500, "rollouts")
    assert update["new_returns"] == expected.meta.episode_returns
    size = int(agent.replay.demo_size.numpy())
    assert size == size0 + len(expected)
    assert update["demo_transitions"] == size == len(dynamic.dataset)
    assert update["demo_episodes"] == len(dynamic.episodes) == episodes0 + 3
    assert update["moving_average"] == 50.0 and update["episode"] == 7
    assert state.bc_fits == 1 and 0.0 <= update["bc_accuracy"] <= 1.0
    assert any(not np.array_equal(w0, w.numpy()) for w0, w in zip(weights0, bc.trainable_weights, strict=True))
    returns = [ret(e) for e in dynamic.episodes]
    assert returns == sorted(returns, reverse=True)
    np.testing.assert_array_equal(agent.replay.table.numpy()[:size, agent.replay.OBS], dynamic.dataset.obs)
    np.testing.assert_array_equal(agent.replay.table.numpy()[:size, agent.replay.ACTION], dynamic.dataset.actions)


def test_dynamic_update_past_capacity_drops_the_lowest_returns_first(capped):
    learner = capped
    agent, dynamic = learner.agent, learner.dynamic
    size0 = int(agent.replay.demo_size.numpy())
    capacity = size0 + 10  # any new episode (≥ 8 steps each, 3 of them) forces an eviction
    assert capacity >= learner.config.max_steps  # so every single episode fits
    before = list(dynamic.episodes)
    new = greedy_rollouts(learner, episode=8).episodes()
    original = dynamic.config
    dynamic.config = dataclasses.replace(original, demo_capacity=capacity)
    try:
        update = dynamic.update(agent, learner.bc, training.TrainingState(episode=8, bc_fits=1), 0, 0)
    finally:
        dynamic.config = original

    assert update["new_returns"] == [ret(e) for e in new]
    everything = before + new
    kept = [ret(e) for e in dynamic.episodes]
    ranked = sorted((ret(e) for e in everything), reverse=True)
    assert len(kept) < len(everything)
    assert kept == ranked[: len(kept)]  # the highest returns stay
    total = sum(len(e) for e in dynamic.episodes)
    assert total <= capacity
    assert int(agent.replay.demo_size.numpy()) == total == update["demo_transitions"]
    best_dropped = next(e for e in everything if ret(e) == ranked[len(kept)])
    assert total + len(best_dropped) > capacity  # nothing was dropped that would have fit


def test_dynamic_update_from_training_episodes_inserts_those_reaching_the_new_best(demos):
    """`episodes` mode: no roll-out, no interaction; the recent episodes at or above the new best
    average go into D_demo and the window is emptied."""
    learner, _ = training.build(tiny(max_steps=50, dynamic_window=3))
    dynamic, agent = learner.dynamic, learner.agent
    recorder = demo_io.EpisodeRecorder(learner.interaction.env, task="cartpole", source="agent")
    for length in (10, 40, 30):  # returns 10 − 1 − 100 (falls) or a full … : build episodes by hand
        recorder.clear()
        recorder.reset(np.zeros(4, np.float32), None)
        for t in range(length):
            recorder.step(0, np.full(4, t, np.float32), 1.0, False, t == length - 1, {"plain_reward": 1.0})
        dynamic.observe(recorder.dataset())
    episodes0, size0, tally0 = len(dynamic.episodes), int(agent.replay.demo_size.numpy()), learner.interactions
    state = training.TrainingState(episode=3, best_average=30.0)
    update = dynamic.update(agent, learner.bc, state, 0, 0)
    assert sorted(update["new_returns"]) == [30.0, 40.0] and update["new_transitions"] == 70
    assert update["mode"] == "episodes" and len(dynamic.episodes) == episodes0 + 2
    assert int(agent.replay.demo_size.numpy()) == size0 + 70 and learner.interactions == tally0
    assert dynamic.recent == [] and dynamic.update(agent, learner.bc, state, 0, 0) is None  # nothing new


class CountSteps:
    """An independent count of env.step calls on every env `training` builds."""

    def __init__(self, monkeypatch) -> None:
        self.calls = 0
        monkeypatch.setattr(training, "make_task", self.make)

    def make(self, *args, **kwargs):
        env = make_task(*args, **kwargs)
        step, counter = env.step, self

        def counted(action):
            counter.calls += 1
            return step(action)

        env.step = counted
        return env


@pytest.mark.parametrize("mode", ["rollouts", "episodes"])
def test_every_interaction_is_counted_and_evaluations_sit_on_the_exact_grid(tmp_path, monkeypatch, mode):
    """20-step episodes, W = 2, M = 3 roll-outs: D_demo grows many times within 300 steps, and
    roll-outs (60 interactions each) jump over several 25-interaction grid points at once."""
    counter = CountSteps(monkeypatch)
    config = tiny(
        max_steps=20, demo_episodes=4, dynamic_window=2, dynamic_rollouts=3, dynamic_demos=mode, eval_every=25
    )
    result = runs.train(config, tmp_path / "run", quiet=True)
    updates = json.loads((tmp_path / "run" / "dynamic_demos.json").read_text())
    assert updates and all(u["mode"] == mode for u in updates)
    assert result.interactions == counter.calls  # the training env's and the roll-out env's steps
    extra = sum(u["new_transitions"] for u in updates) if mode == "rollouts" else 0
    assert result.interactions == result.env_steps + extra and (extra > 0) == (mode == "rollouts")
    _, rows = read_csv(tmp_path / "run" / "metrics.csv")
    assert int(rows[-1]["interactions"]) <= result.interactions
    _, evals = read_csv(tmp_path / "run" / "evals.csv")
    points = [int(e["interactions"]) for e in evals]
    grid = list(range(0, result.interactions + 1, 25))
    # an early stop adds the next grid point, where the final network (it learns no more) acts
    assert points == grid + [grid[-1] + 25] * result.stopped_early
    assert result.stopped_early  # the 20-step episodes reach 0.98 × 20 ten times in a row


def test_plain_dqns_random_scaling_play_counts_as_interactions(tmp_path, monkeypatch):
    counter = CountSteps(monkeypatch)
    result = runs.train(tiny("none", eval_every=1000), tmp_path / "run", quiet=True)
    assert result.interactions == counter.calls == result.env_steps + 2000  # training.random_obs_scale
    _, evals = read_csv(tmp_path / "run" / "evals.csv")
    assert [int(e["interactions"]) for e in evals] == [0, 1000, 2000]
    assert len({e["mean_return"] for e in evals}) == 1  # one network (no learning yet) at all three


# --- runs.train end to end -----------------------------------------------------------------------


def read_csv(path):
    with open(path, newline="") as file:
        reader = csv.DictReader(file)
        return reader.fieldnames, list(reader)


def tb_tags(directory) -> set[str]:
    tags = set()
    for events in directory.glob("events.out.tfevents.*"):
        for event in tf.compat.v1.train.summary_iterator(str(events)):
            tags.update(value.tag for value in event.summary.value)
    return tags


@pytest.fixture(scope="module")
def bayes_run(tmp_path_factory):
    config = tiny()
    out = tmp_path_factory.mktemp("bayes") / "run"
    return config, out, runs.train(config, out, quiet=True)


@pytest.mark.slow
def test_train_writes_config_and_one_metrics_row_per_episode(bayes_run):
    config, out, result = bayes_run
    assert Config.from_dict(json.loads((out / "config.json").read_text())) == config
    fields, rows = read_csv(out / "metrics.csv")
    assert fields == list(EpisodeRow.columns())
    assert result.out == out and result.episodes == len(rows) >= 1
    assert [int(r["episode"]) for r in rows] == list(range(1, len(rows) + 1))
    steps = [int(r["env_step"]) for r in rows]
    lengths = [int(r["length"]) for r in rows]
    assert all(b > a for a, b in itertools.pairwise(steps))
    assert not result.stopped_early  # 10 episodes ≥ 490 cannot fit in 300 steps
    assert steps[-1] == result.env_steps == config.total_steps
    assert steps == list(np.cumsum(lengths))  # every env step belongs to one episode
    for row, length in zip(rows[:-1], lengths, strict=False):  # all but the last (cut by the budget) fell
        assert float(row["return"]) == length - 101 and float(row["plain_return"]) == length
    assert float(rows[-1]["plain_return"]) == lengths[-1]
    for row, step in zip(rows, steps, strict=True):
        assert float(row["epsilon"]) == pytest.approx(max(0.01, 0.1 - 0.09 * step / 30), abs=1e-6)
        assert all(np.isfinite(float(row[k])) for k in LOSS_TERMS)
    recorded = training.demonstrations(config, None)
    assert int(rows[0]["demo_size"]) == len(recorded)  # no dynamic update before W = 10 episodes
    summary = DemoSummary.from_row(json.loads((out / "demonstrations.json").read_text()))
    assert (summary.source, summary.expert, summary.transitions) == ("recorded", config.expert, len(recorded))
    assert summary.plain_returns == recorded.meta.plain_returns and summary.pretrain_steps == config.pretrain_steps


@pytest.mark.slow
def test_train_evaluates_at_exactly_every_eval_every_interactions(bayes_run):
    config, out, result = bayes_run
    fields, evals = read_csv(out / "evals.csv")
    assert fields == list(EvalRow.columns())
    assert (evals[0]["env_step"], evals[0]["interactions"], evals[0]["episode"]) == ("0", "0", "0")
    # 300 steps, E = 150, no roll-outs (no new best within W = 10 episodes): 0, 150, 300, whatever
    # the episode boundaries; an episode running across 150 was paused there and went on.
    assert [int(e["interactions"]) for e in evals] == [0, 150, 300] and result.interactions == 300
    assert [int(e["env_step"]) for e in evals] == [0, 150, 300]
    assert {
        "train/return",
        "train/epsilon",
        "train/expert",
        "train/demo_size",
        "train/env_step",
        "eval/plain_return",
        "eval/env_step",
    } <= tb_tags(out / "tb")


@pytest.mark.slow
def test_evaluating_more_often_leaves_training_unchanged(bayes_run, tmp_path):
    """Evaluations use their own env seeds and a NumPy copy of the network: the CartPole presets'
    eval grid (1,000 steps) can change without changing a single training number."""
    config, out, _ = bayes_run
    often = dataclasses.replace(config, eval_every=50)
    runs.train(often, tmp_path / "often", quiet=True)
    columns = [f for f in EpisodeRow.columns() if f != "wall_time"]  # interactions included
    rows = [[[r[f] for f in columns] for r in read_csv(d / "metrics.csv")[1]] for d in (out, tmp_path / "often")]
    assert rows[0] == rows[1]
    assert len(read_csv(tmp_path / "often" / "evals.csv")[1]) > len(read_csv(out / "evals.csv")[1])


@pytest.mark.slow
def test_train_saves_models_demos_evaluation_curve_and_checkpoint(bayes_run):
    config, out, result = bayes_run
    q = load_model(out / "q_network.keras")
    assert q.output_shape == (None, 2)
    load_model(out / "bc_model.keras")
    saved = demo_io.load(out / "demos.npz", task="cartpole")
    updates = out / "dynamic_demos.json"
    if updates.exists():
        assert len(saved) == json.loads(updates.read_text())[-1]["demo_transitions"]
    else:
        recorded = training.demonstrations(config, None)
        np.testing.assert_array_equal(saved.obs, recorded.obs)
        assert saved.meta.episode_returns == recorded.meta.episode_returns
    evaluation = json.loads((out / "eval.json").read_text())
    assert {"task", "policy", "episodes", "returns", "mean_return", "std_return"} <= set(evaluation)
    assert evaluation == result.evaluation.to_dict()
    assert (evaluation["task"], evaluation["policy"], evaluation["episodes"]) == ("cartpole", "q", 1)
    assert len(evaluation["returns"]) == 1 and evaluation["mean_return"] == evaluation["returns"][0]
    assert evaluation["std_return"] == 0.0
    assert (out / "learning_curve.png").read_bytes()[:8] == PNG_SIGNATURE
    latest = json.loads((out / "checkpoints" / "latest.json").read_text())
    # Periodic saves follow episode ends (the first at step ≥ checkpoint_every, each next one
    # checkpoint_every after the last); when one lands on the final step, the final save gets a
    # new directory, then the switch.
    _, rows = read_csv(out / "metrics.csv")
    due, periodic = config.checkpoint_every, None
    for step in (int(r["env_step"]) for r in rows):
        if step >= due:
            due, periodic = step + config.checkpoint_every, step
    suffix = ".1" if periodic == config.total_steps else ""
    assert latest == {"dir": f"ckpt-{config.total_steps}{suffix}"}
    assert [p.name for p in (out / "checkpoints").iterdir() if p.is_dir()] == [latest["dir"]]
    checkpoint = out / "checkpoints" / latest["dir"]
    assert json.loads((checkpoint / "state.json").read_text())["episode"] == result.episodes
    assert (checkpoint / "tf.index").is_file() and (checkpoint / "demos.npz").is_file()
    assert sorted(p.name for p in (out / "checkpoints").iterdir()) == sorted(
        ["latest.json", latest["dir"], runs.GIVEN_DEMOS]
    )


def test_existing_run_dir_is_refused_kept_and_replaced_only_with_force(tmp_path):
    out = tmp_path / "busy"
    out.mkdir()
    (out / "notes.txt").write_text("keep me")
    with pytest.raises(OutputExistsError) as error:
        runs.train(tiny("none"), out, quiet=True)
    assert "is not a run directory" in str(error.value) and "--force" not in str(error.value)
    assert [p.name for p in out.iterdir()] == ["notes.txt"] and (out / "notes.txt").read_text() == "keep me"
    with pytest.raises(ConfigError, match="checkpoint"):
        runs.train(tiny("none"), out, resume=True, quiet=True)
    with pytest.raises(ConfigError, match="checkpoint"):
        runs.train(tiny("none"), tmp_path / "missing", resume=True, quiet=True)
    assert [p.name for p in out.iterdir()] == ["notes.txt"] and not (tmp_path / "missing").exists()

    # force replaces only a run (here one stopped before its first checkpoint), keeping the user's file; a
    # plain-DQN run replaces it (and writes nothing of demonstrations or BC)
    with pytest.raises(OutputExistsError, match="is not a run directory"):
        runs.train(tiny("none"), out, force=True, quiet=True)
    (out / "config.json").write_text(json.dumps(tiny().to_dict()))
    result = runs.train(tiny("none"), out, force=True, quiet=True)
    assert (out / "notes.txt").read_text() == "keep me"
    assert result.env_steps == 300
    assert (out / "q_network.keras").is_file() and (out / "eval.json").is_file()
    assert not (out / "bc_model.keras").exists() and not (out / "demos.npz").exists()
    assert not (out / "dynamic_demos.json").exists()
    _, rows = read_csv(out / "metrics.csv")
    assert len(rows) == result.episodes and all(r["demo_size"] == "0" for r in rows)
    first = int(rows[0]["env_step"])
    assert float(rows[0]["epsilon"]) == pytest.approx(max(0.01, 1.0 - 0.99 * first / 30), abs=1e-6)
    checkpoint = out / "checkpoints" / json.loads((out / "checkpoints" / "latest.json").read_text())["dir"]
    assert not (checkpoint / "demos.npz").exists()
    assert json.loads((out / "config.json").read_text())["expert_loss"] == "none"


# --- Config --------------------------------------------------------------------------------------


def test_with_overrides_types_each_value():
    config = tiny().with_overrides(
        [
            "hidden=32,32",
            "max_steps=none",
            "dynamic_demos=off",
            "mc_dropout=false",
            "gamma=0.9",
            "n-step=3",
            "epsilon_start=0.2",
            "expert_loss=ce",
        ]
    )
    assert (
        config.hidden == (32, 32)
        and config.max_steps is None
        and config.dynamic_demos == "off"
        and config.mc_dropout is False
    )
    assert config.gamma == 0.9 and config.n_step == 3 and config.epsilon_start == 0.2
    assert config.expert_loss == "ce" and config.total_steps == 300  # the rest is kept
    assert tiny(max_steps=50).with_overrides(["max_steps=none"]).max_steps is None
    assert tiny().with_overrides(["max_steps=80"]).max_steps == 80
    kept = Config.for_task("mountaincar").with_overrides(["seed=3"])  # the preset's defaults, not the shared ones
    assert (kept.seed, kept.demo_episodes, kept.total_steps, kept.early_stop_window) == (3, 10, 100_000, 0)


@pytest.mark.parametrize(
    "assignment, match",
    [
        ("nope=1", "unknown Config field 'nope'"),
        ("hidden", "key=value"),
        ("batch_size=abc", "batch_size='abc': expected int"),
        ("mc_dropout=maybe", "expected bool"),
        ("dynamic_demos=maybe", "dynamic_demos='maybe' is not one of"),
        ("hidden=a,b", "expected tuple"),
        ("gamma=2", "gamma must be in"),
        ("expert_loss=magic", "expert_loss='magic' is not one of"),
        ("task=mountaincar", "--task"),
        ("task=", "--task"),
    ],
)
def test_with_overrides_rejects_bad_keys_values_and_the_task(assignment, match):
    with pytest.raises(ConfigError, match=match):
        tiny().with_overrides([assignment])


def test_task_presets_and_from_dict():
    car = Config.for_task("mountaincar")
    assert (car.demo_episodes, car.total_steps, car.early_stop_window) == (10, 100_000, 0)
    assert Config.for_task("mountaincar-goals").total_steps == 100_000
    pole = Config.for_task("cartpole")
    assert (pole.demo_episodes, pole.total_steps, pole.early_stop_window) == (5, 50_000, 10)
    with pytest.raises(ConfigError, match="unknown task"):
        Config.for_task("pong")
    fields = json.loads(json.dumps(car.to_dict()))
    assert Config.from_dict(fields) == car
    with pytest.raises(ConfigError, match="bogus"):
        Config.from_dict({**fields, "bogus": 1})
    del fields["torso"], fields["gamma"]  # a file of an older version: its values are not known, not defaults
    with pytest.raises(ConfigError, match=r"^no \['gamma', 'torso'\]: written by an older version\?"):
        Config.from_dict(fields)
