"""Algorithm 1 of the paper end to end (ALGORITHM.md §4–§5), one function per phase:

    demonstrations → fit π_bc → pre-train k steps on D_demo (θ_prior ← θ) →
    episodes of ε-greedy interaction, one prioritized update per `train_freq` env steps,
    θ' ← θ every τ updates → dynamic demonstrations after each episode →
    stop at the step budget or the task's early-stopping rule.

Every env step whose transition the learner may train on is an interaction, counted in one
place (`wrappers.CountInteractions` on every env of the learner); greedy evaluations happen at
exactly every `eval_every` interactions, pausing an episode at the grid point if need be.

An episode is one TensorFlow graph call (`interaction.Interaction.play`: act, step the env,
store, learn, all in the graph). Per-episode work (logging, evaluation, dynamic
demonstrations, checkpoints) stays in Python: `training/state.py` keeps its bookkeeping, each
episode ends in a `records.EpisodeRow`, and `runs/directory.py` writes the files of a run.
D_demo and π_bc's fits are `training/demonstrations.py`'s, dynamic demonstrations
`training/dynamic.py`'s.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import cast

import gymnasium as gym
import keras
import numpy as np
import tensorflow as tf

from dqfd_bc_keras.core.agent import DQfDAgent, make_agent
from dqfd_bc_keras.core.bc import BCModel, build_bc_model
from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.core.expert_terms import next_expert_scale
from dqfd_bc_keras.demos.dataset import DemoDataset
from dqfd_bc_keras.envs.make import checked_spaces, make_task
from dqfd_bc_keras.envs.wrappers import CountInteractions, Tally
from dqfd_bc_keras.errors import DivergedError
from dqfd_bc_keras.evaluation import EvalResult, GreedyPolicy, evaluate
from dqfd_bc_keras.seeds import episode_seed, eval_seed
from dqfd_bc_keras.training.demonstrations import demonstrations, fit_bc
from dqfd_bc_keras.training.dynamic import DynamicDemos
from dqfd_bc_keras.training.interaction import Interaction
from dqfd_bc_keras.training.records import EpisodeRow, EvalRow, Losses
from dqfd_bc_keras.training.state import TrainingState, early_stop

METRIC_FIELDS = EpisodeRow.columns()
"""metrics.csv's columns, as the record spells them."""


def random_obs_scale(env: gym.Env, seed: int, steps: int = 2000) -> tuple[np.ndarray, np.ndarray]:
    """Input scaling for plain DQN, which has no demonstrations: states of a random policy."""
    rng = np.random.default_rng(seed)
    states, (obs, _) = [], env.reset(seed=seed)
    for _ in range(steps):
        obs, _, terminated, truncated, _ = env.step(int(rng.integers(discrete_actions(env))))
        states.append(obs)
        if terminated or truncated:
            obs, _ = env.reset(seed=int(rng.integers(2**31)))
    return np.mean(states, axis=0), np.std(states, axis=0)


def discrete_actions(env: gym.Env) -> int:
    """n of the env's Discrete(n) actions (`checked_spaces` refused any other action space)."""
    return int(cast(gym.spaces.Discrete, env.action_space).n)


def build_learner(
    config: Config, data: DemoDataset | None, env: gym.Env, fit: bool
) -> tuple[DQfDAgent, BCModel | None]:
    """π_bc fitted on D_demo (BC-based losses; only built when `fit` is False, for a resume that
    restores its weights), and the agent with D_demo loaded."""
    keras.utils.set_random_seed(config.seed)
    net_input = checked_spaces(config).network_input(config.torso, config.timeout)
    n_actions = discrete_actions(env)
    bc = None
    if config.uses_bc:
        assert data is not None, "a BC-based loss has demonstrations (Config checks it)"
        bc = build_bc_model(config, net_input, n_actions, None if net_input.image else data.obs_scale())
        if fit:
            fit_bc(config, bc, data, config.bc_epochs, fit_index=0)
        else:
            bc.optimizer.build(bc.trainable_variables)
    scale = None if data is not None or net_input.image else random_obs_scale(env, config.seed)
    return make_agent(config, data, bc, obs_scale=scale, spaces=(net_input, n_actions)), bc


def run_evaluation(config: Config, agent: DQfDAgent, episodes: int, seed: int) -> EvalResult:
    """Greedy episodes of the current Q-network on the plain env (and goal counts where that applies)."""
    return evaluate(
        GreedyPolicy.from_model(agent.q_network),
        config.task,
        episodes,
        seed,
        timeout=config.timeout,
        max_steps=config.max_steps,
        env_kwargs=config.env_kwargs,
    )


def evaluate_at(learner: Learner, state: TrainingState, points: list[int]) -> list[EvalRow]:
    """One greedy evaluation of the current network, as a row at each grid point in `points`
    (appended to `state.evals`)."""
    config = learner.config
    result = run_evaluation(config, learner.agent, config.eval_episodes, eval_seed(config.seed))
    env_step = int(learner.interaction.env_steps.numpy())
    rows = [
        EvalRow(
            env_step=env_step,
            interactions=point,
            episode=state.episode,
            mean_return=result.mean_return,
            std_return=result.std_return,
            mean_goals=float(np.mean(result.goals)) if result.goals is not None else None,
        )
        for point in points
    ]
    state.evals.extend(rows)
    return rows


@dataclass
class Learner:
    """Everything a run trains: the agent, π_bc, the interaction loop, D_demo's episodes and
    the tally of interactions its data came from."""

    config: Config
    agent: DQfDAgent
    bc: BCModel | None
    interaction: Interaction
    dynamic: DynamicDemos | None
    tally: Tally
    demos: DemoDataset | None
    """D_demo as given, before any interaction (None for plain DQN)."""

    @property
    def interactions(self) -> int:
        return self.tally.count

    @property
    def teacher_return(self) -> float:
        """The teacher's mean return: that of D_demo's episodes as given."""
        assert self.demos is not None, "a method with a teacher-relative weight learns from demonstrations"
        return self.demos.mean_return

    def extend(self, total_steps: int) -> None:
        """Raise the step budget to `total_steps`: the run goes on, ε's schedule stretched to the new budget."""
        self.config = dataclasses.replace(self.config, total_steps=total_steps)
        self.interaction.config = self.config
        self.interaction.decay_steps.assign(self.config.epsilon_fraction * total_steps)
        if self.dynamic is not None:
            self.dynamic.config = self.config

    def checkpoint(self) -> tf.train.Checkpoint:
        extra = {"bc_optimizer": self.bc.optimizer} if self.bc is not None else {}
        return tf.train.Checkpoint(
            agent=self.agent.checkpoint(), env_steps=self.interaction.env_steps, rng=self.interaction.rng, **extra
        )


def build(config: Config, dataset: DemoDataset | None = None, fresh: bool = True) -> tuple[Learner, dict]:
    """Steps 1–2: demonstrations, π_bc, the pre-trained agent; returns the learner and
    pre-training's losses. `fresh=False` skips the fits: a resume restores their results."""
    if config.deterministic:
        tf.config.experimental.enable_op_determinism()
    tally = Tally()
    env = CountInteractions(task_env(config), tally)
    data = demonstrations(config, dataset)
    agent, bc = build_learner(config, data, env, fit=fresh)
    pretrain = fresh and data is not None and config.pretrain_steps > 0
    losses = agent.pretrain(config.pretrain_steps) if pretrain else {}
    check_finite(losses, "pre-training")
    agent.reset_metrics()
    dynamic = None
    if bc is not None and data is not None and config.dynamic_demos != "off":
        rollout_env = CountInteractions(task_env(config), tally)
        dynamic = DynamicDemos(config, data, rollout_env)
    keep_episodes = dynamic is not None and config.dynamic_demos == "episodes"
    return Learner(config, agent, bc, Interaction(agent, env, config, keep_episodes), dynamic, tally, data), losses


def task_env(config: Config) -> gym.Env:
    """The task env of `config`: its env kwargs, time-limit mode and step limit."""
    return make_task(config.task, timeout=config.timeout, max_steps=config.max_steps, env_kwargs=config.env_kwargs)


def check_finite(losses: dict[str, float], where: str) -> None:
    """Stop at the first non-finite loss term: a non-finite Q-value makes the TD terms
    non-finite too, and nothing learned after it can be trusted or saved."""
    bad = {name: value for name, value in losses.items() if not math.isfinite(float(value))}
    if bad:
        raise DivergedError(f"training diverged in {where}: " + ", ".join(f"{k} = {v}" for k, v in bad.items()))


Evaluate = Callable[[list[int]], list[EvalRow]]
"""Evaluates the current Q-network once and logs it at each of the given grid points (its rows)."""
OnEpisode = Callable[[Learner, TrainingState, EpisodeRow], None]
Callback = Callable[[EpisodeRow | EvalRow], object]
"""A user's callback: given each episode's and each evaluation's row; `False` stops training."""


class StopTraining(Exception):
    """A user's callback returned False: training ends where it is (`train_episodes`' callers catch it)."""


def train_with_callback(
    learner: Learner, state: TrainingState, on_episode: OnEpisode, on_eval: Evaluate, callback: Callback | None
) -> None:
    """`train_episodes`, each episode's and evaluation's rows given to `callback` as well, until a
    False from it stops training there (the Python API's and a run directory's one stopping rule)."""
    on_episode, on_eval = _with_callback(on_episode, on_eval, callback)
    with contextlib.suppress(StopTraining):
        train_episodes(learner, state, on_episode, on_eval)


def _with_callback(on_episode: OnEpisode, on_eval: Evaluate, callback: Callback | None) -> tuple[OnEpisode, Evaluate]:
    """`on_episode` and `on_eval`, each then giving its rows to `callback` (raising StopTraining at a False)."""
    if callback is None:
        return on_episode, on_eval

    def tell(rows: list) -> None:
        for row in rows:
            if callback(row) is False:
                raise StopTraining

    def episode(learner: Learner, state: TrainingState, row: EpisodeRow) -> None:
        on_episode(learner, state, row)
        tell([row])

    def evaluate(points: list[int]) -> list[EvalRow]:
        rows = on_eval(points)
        tell(rows)
        return rows

    return episode, evaluate


def evaluate_due(learner: Learner, state: TrainingState, on_eval: Evaluate) -> None:
    """Evaluations at every grid point k·E the tally has reached. The network is the one that
    acted at each of them: it learns only inside `Interaction.play`, which stops at the next
    point, so several points crossed at once (demo roll-outs) share one evaluation."""
    due = []
    while state.next_eval <= learner.interactions:
        due.append(state.next_eval)
        state.next_eval += learner.config.eval_every
    if due:
        on_eval(due)


def train_episodes(learner: Learner, state: TrainingState, on_episode: OnEpisode, on_eval: Evaluate) -> TrainingState:
    """Steps 3–5: episodes until the budget or the early stop; `on_episode` logs and saves,
    `on_eval` evaluates at exactly every `eval_every` interactions."""
    c, agent, interaction = learner.config, learner.agent, learner.interaction
    steps = lambda: int(interaction.env_steps.numpy())
    agent.expert_scale.assign(state.expert_scale)  # w_E (§8) as the run left it
    while steps() < c.total_steps and not state.stopped_early:
        started = time.perf_counter()
        obs, done = interaction.obs, False  # an episode an exception stopped between two graph calls goes on
        if obs is None:
            obs = interaction.reset(episode_seed(c.seed, state.episode))
        while not done and steps() < c.total_steps:
            interaction.obs = obs  # where a callback at an evaluation may stop it
            evaluate_due(learner, state, on_eval)
            budget = min(c.total_steps - steps(), state.next_eval - learner.interactions)
            interaction.obs = None  # stopped inside the graph call, the env's state is unknown: a new episode
            obs, done = interaction.play(tf.constant(obs, agent.net_input.dtype), tf.constant(budget, tf.int64))
            obs, done = obs.numpy(), bool(done)
        interaction.obs = None  # the episode ends here (its row is next), whole or at the budget
        stats = interaction.episode
        losses = {name: float(value) for name, value in agent.take_losses().items()}
        check_finite(losses, f"episode {state.episode + 1} (env step {steps()})")
        state.returns.append(stats.ret)
        if c.method.decay is not None:  # w_E of the next learning steps (§8)
            state.expert_scale = next_expert_scale(
                state.expert_scale, state.returns, learner.teacher_return, c.dynamic_window, c.method.decay
            )
            agent.expert_scale.assign(state.expert_scale)
        state.episode += 1
        state.wall_time += time.perf_counter() - started
        on_demos, off_demos = agent.imitation_weights()
        row = EpisodeRow(
            episode=state.episode,
            env_step=steps(),
            interactions=learner.interactions,
            return_=stats.ret,
            plain_return=stats.plain,
            length=stats.length,
            goals=stats.goals,
            epsilon=float(interaction.epsilon()),
            losses=Losses(**losses),
            demo_size=int(agent.replay.demo_size.numpy()),
            wall_time=state.wall_time,
            imitation_weight_demo=on_demos,
            imitation_weight_agent=off_demos,
        )
        state.metrics.append(row)
        if learner.dynamic is not None:
            if interaction.recorder is not None and done:
                learner.dynamic.observe(interaction.recorder.dataset())
            if learner.dynamic.due(state):
                started = time.perf_counter()
                bc = learner.bc
                assert bc is not None, "dynamic demonstrations refit π_bc"
                update = learner.dynamic.update(agent, bc, state, row.env_step, learner.interactions)
                if update is not None:
                    state.demo_updates.append(update)
                state.wall_time += time.perf_counter() - started
        state.stopped_early = early_stop(c, state.returns)
        on_episode(learner, state, row)
    evaluate_due(learner, state, on_eval)
    if state.stopped_early and state.next_eval - c.eval_every <= learner.interactions:
        # It learns nothing after the stop: the next grid point sees the final network (once: a
        # resumed finished run has already evaluated past its tally).
        point, state.next_eval = state.next_eval, state.next_eval + c.eval_every
        on_eval([point])
    return state
