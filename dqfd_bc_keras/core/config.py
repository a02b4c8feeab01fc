"""Every hyperparameter, with the paper's (or DQfD's) default, in one typed dataclass.

Where the paper is silent, ALGORITHM.md decides; where that is silent too, the value is ours
and the field's comment says so. `Config.for_task(name)` gives a task preset's defaults (the
registry in `tasks/`; any other Gymnasium env id gets `tasks.ENV_DEFAULTS`); `validate`, run by
every Config made, rejects settings the algorithm cannot use (a wrong type, a name outside its
choices, a number out of range: `config_checks.py`) with a `ConfigError` naming the field, without
making an env: whether the env takes the config is `envs.checked_spaces`'s to say, where envs are
about to be made.
Nothing here imports TensorFlow: reading a config.json is cheap.
"""

from __future__ import annotations

import contextlib
import dataclasses
import warnings
from dataclasses import dataclass, field
from typing import Any

from dqfd_bc_keras.core.config_checks import check, parsed, typed
from dqfd_bc_keras.core.methods import Method, get_method, reading_saved_config
from dqfd_bc_keras.envs.kwargs import recorded
from dqfd_bc_keras.envs.make import get_task, step_limit
from dqfd_bc_keras.errors import OLDER, ConfigError, DqfdWarning
from dqfd_bc_keras.tasks import check_demonstrator

QUICK: dict[str, object] = {
    "total_steps": 600,
    "pretrain_steps": 50,
    "bc_epochs": 2,
    "bc_refit_epochs": 1,
    "demo_episodes": 2,
    "eval_every": 300,
    "eval_episodes": 2,
    "final_eval_episodes": 2,
    "checkpoint_every": 300,
    "replay_capacity": 2000,
    "demo_capacity": 5000,
}
"""A budget of seconds per run, for tests and smoke checks (`train.py --quick`, the quick suite)."""


@dataclass
class Config:
    """Hyperparameters of one run. Greek letters follow ALGORITHM.md."""

    # --- task -------------------------------------------------------------------------------
    task: str = "cartpole"
    """Task preset (tasks.TASKS, or `module:preset` registered by `module`), or the id of any
    Gymnasium env with Discrete actions and an observation that `observations` flattens
    (`module:Env-v0` imports `module` first)."""
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    """Keyword arguments of the env's constructor (`gym.make(id, **env_kwargs)`), JSON values; part
    of the task: every env of the run, its demonstrations and its evaluations are made with them."""
    timeout: str = "bootstrap"
    """Time-limit mode: bootstrap | naive | time-aware."""
    max_steps: int | None = None
    """Episode step limit; None: the task's (CartPole 500 or 200, MountainCar 200, an env's own)."""

    # --- the loss J = J_DQ + λ1·J_n + λ2·J_E + λ3·J_L2 (§2) ----------------------------------
    expert_loss: str = "bayes"
    """The method (methods.py): margin (DQfD) | bc_margin (DQfD-BC) | ce (DQfD-BC) | bayes (the
    paper) | none (plain DQN) | sqil (SQIL's rewards on our DQN), or a method of your own as
    `module:NAME`."""
    target: str = "dqn"
    """Bootstrap target: dqn (the paper's) | double (DQfD's)."""
    td_loss: str = "squared"
    """Per-sample TD loss: squared (the paper's) | huber."""
    gamma: float = 0.99
    """Discount γ."""
    n_step: int = 10
    """n of the n-step return (DQfD)."""
    lambda_n: float = 1.0
    """λ1, weight of the n-step loss (DQfD)."""
    lambda_expert: float = 1.0
    """λ2, weight of the expert loss (DQfD)."""
    lambda_l2: float = 1e-5
    """λ3, weight of the L2 loss on the Q-network's kernels (DQfD)."""
    margin: float = 0.8
    """l(a_E, a) for a ≠ a_E in the margin losses (DQfD)."""
    temperature: float = 1.0
    """T in p_Q = softmax(Q/T) for the ce and bayes losses."""

    # --- the Bayesian expert loss (§3) ------------------------------------------------------
    sigma0_sq: float = 0.5
    """Observation noise σ0²: a confident BC model's imitation weight is 1/(2σ0²) = 1."""
    mc_passes: int = 10
    """K, MC-dropout forward passes of the BC model for π̄_bc and σ²."""
    prior_scale: float = 1.0
    """s_p, standard deviation of the Gaussian prior around θ_prior."""
    prior_center: str = "pretrained"
    """θ_prior: the Q-network's weights at the end of pre-training, or zero."""
    bayes_prior: bool = True
    """The prior term ‖θ − θ_prior‖²/(2 s_p² N) of J_E (False: an ablation, the likelihood alone)."""
    mc_dropout: bool = True
    """σ²(s) from K MC-dropout passes of π_bc (False: an ablation, π̄_bc from one deterministic pass
    and σ² = σ0² everywhere)."""
    uncertainty: str = "mc_dropout"
    """The estimator of σ²(s) − σ0² (uncertainty.py): mc_dropout (the paper's) | ensemble (K BC
    members on bootstrap resamples of D_demo) | distance (to the nearest demonstrated state). Ours."""
    ensemble_members: int = 5
    """K of the `ensemble` estimator (Lakshminarayanan et al. 2017's 5)."""

    # --- networks and optimisation (ours: the paper gives none) ----------------------------
    torso: str = "auto"
    """What reads the observation before the hidden layers (networks.py): mlp | minatar (one 3×3
    conv of 16) | nature (Nature DQN's three convs) | auto (mlp for vectors, minatar for frames
    under 36×36, nature from there). Shared by the Q-network and the BC model."""
    hidden: tuple[int, ...] = (64, 64)
    """Hidden ReLU layers of the Q-network (after the torso)."""
    learning_rate: float = 1e-3
    """Adam step size of the Q-network."""
    batch_size: int = 64
    """Mini-batch size of every gradient step."""
    target_update_period: int = 250
    """τ: gradient steps between refreshes of the target network θ' ← θ."""
    pretrain_steps: int = 1000
    """k, gradient steps on D_demo alone before interacting (§4)."""

    # --- BC model π_bc (§3) -----------------------------------------------------------------
    bc_hidden: tuple[int, ...] = (64, 64)
    """Hidden ReLU layers of the BC classifier."""
    bc_dropout: float = 0.2
    """Dropout rate of the MAP BC model (bayes); the MLE model (ce, bc_margin) has none."""
    bc_prior_scale: float = 1.0
    """Standard deviation of the Gaussian weight prior of the MAP BC model."""
    bc_learning_rate: float = 1e-3
    """Adam step size of the BC model."""
    bc_epochs: int = 60
    """Epochs of the first BC fit on D_demo."""

    # --- prioritized replay (§1; DQfD's values) ---------------------------------------------
    replay_capacity: int = 100_000
    """Capacity of D_replay (self-generated transitions, FIFO)."""
    demo_capacity: int = 50_000
    """Capacity of D_demo in transitions (dynamic demonstrations grow it up to here)."""
    priority_alpha: float = 0.4
    """α, priority exponent."""
    priority_beta0: float = 0.6
    """β at the start; annealed linearly to 1 over `beta_anneal_steps` gradient steps."""
    beta_anneal_steps: int = 50_000
    """Gradient steps over which β reaches 1."""
    priority_eps_agent: float = 0.001
    """ε_a, added to |δ| for self-generated transitions."""
    priority_eps_demo: float = 1.0
    """ε_d, added to |δ| for demonstrations (the demo bonus)."""

    # --- demonstrations (§4, §5) ----------------------------------------------------------
    expert: str = "imperfect"
    """Who demonstrates when no dataset is given: a preset's scripted expert (strong | imperfect),
    a rule `module:function` (obs → action), or a saved `.keras` Q-network or BC model."""
    expert_epsilon: float = 0.0
    """Probability that the demonstrator acts uniformly at random instead (a noisy expert)."""
    demo_episodes: int = 5
    """Episodes recorded from `expert` (seeds seed·1000 + i); with demonstrations given, the episodes they hold."""
    dynamic_demos: str = "episodes"
    """DQfD-BC's dynamic demonstrations (BC-based expert losses only): at each new best moving
    average, `episodes` inserts the agent's own training episodes since the last update that
    reach that average (no extra interaction); `rollouts` plays M extra greedy episodes (counted
    as interactions); `off` never grows D_demo."""
    dynamic_window: int = 10
    """W: the moving average of the last W episode returns that must reach a new best."""
    dynamic_rollouts: int = 5
    """M: greedy episodes added to D_demo at each new best (`dynamic_demos="rollouts"`)."""
    bc_refit_epochs: int = 3
    """Epochs of each warm-started BC refit on the enlarged D_demo."""

    # --- Algorithm 1's loop (§4) -----------------------------------------------------------
    total_steps: int = 50_000
    """Budget of the learning loop's env steps (interactions also count demo roll-outs and the
    random play that scales plain DQN's inputs)."""
    train_freq: int = 1
    """Env steps per gradient step (the paper: 1)."""
    epsilon_start: float | None = None
    """ε-greedy at the start; None: 0.1 after pre-training, 1.0 without demonstrations."""
    epsilon_end: float = 0.01
    """ε after the decay."""
    epsilon_fraction: float = 0.1
    """Fraction of the step budget over which ε decays linearly."""
    early_stop_window: int = 10
    """Stop once this many consecutive episodes return ≥ early_stop_fraction × limit (CartPole; 0: never)."""
    early_stop_fraction: float = 0.98
    """The paper's 490 of 500."""
    eval_every: int = 5_000
    """Interactions between greedy evaluations on the plain env: exactly at 0, E, 2E, … (an
    episode is paused at a grid point, evaluated, and continues)."""
    eval_episodes: int = 10
    """Episodes per periodic evaluation."""
    final_eval_episodes: int = 20
    """Episodes of the evaluation written to eval.json at the end."""
    checkpoint_every: int = 10_000
    """Env steps between checkpoints (taken at the next episode end)."""

    seed: int = 0
    """Seed of every random generator of the run."""
    deterministic: bool = True
    """TensorFlow op determinism: the same seed gives the same run, resumed or not."""

    def __post_init__(self) -> None:
        if isinstance(self.env_kwargs, dict):  # a tuple as {"__tuple__": [...]}: JSON has none
            with contextlib.suppress(ConfigError):  # what JSON cannot hold is refused by `validate`, naming the field
                self.env_kwargs = recorded(self.env_kwargs)
        self.validate()

    @classmethod
    def for_task(cls, task: str, **overrides: object) -> Config:
        """Task `task`'s defaults (its preset's, or `ENV_DEFAULTS` for any other Gymnasium env) with
        `overrides`, validated. Use it rather than `Config(...)`, whose defaults are no task's."""
        task = typed("task", str, task)  # the preset is looked up by it before the fields are checked
        unknown = [key for key in overrides if key not in cls.__dataclass_fields__]
        if unknown:
            raise ConfigError(unknown_field(unknown[0]))
        spec = get_task(task)
        for where, defaults in [("defaults", spec.defaults), *spec.method_defaults.items()]:
            wrong = [key for key in defaults if key not in cls.__dataclass_fields__]
            if wrong:  # a user's preset (tasks.TaskSpec.defaults, .method_defaults)
                owner = "its defaults" if where == "defaults" else f"its defaults for {where!r}"
                raise ConfigError(f"task {task!r}: {owner} hold an {unknown_field(wrong[0])}")
        method = overrides.get("expert_loss")
        fields: dict[str, Any] = {**preset_defaults(task, method), **overrides}  # each checked by `validate`
        return cls(**fields)

    @classmethod
    def from_dict(cls, fields: dict) -> Config:
        """The inverse of `to_dict` (a saved config.json, whose derived `observation` record is
        skipped). Every field must be there: the value a file lacks is not known (a default may
        have changed since it was written). Unknown keys are an error too, and every value is
        checked as the constructor checks it (a list stands for a tuple)."""
        if not isinstance(fields, dict):
            raise ConfigError(f"expected a JSON object of config fields, got {fields!r:.100}")
        known = [f.name for f in dataclasses.fields(cls)]
        fields = {k: v for k, v in fields.items() if k not in DERIVED_KEYS}
        unknown = sorted(set(fields) - set(known))
        if unknown:
            raise ConfigError(f"unknown config field(s) {unknown}")
        missing = [name for name in known if name not in fields]
        if missing:
            raise ConfigError(f"no {missing}: {OLDER}")
        with reading_saved_config():  # its method (the user's) is imported to train, not to read its settings
            return cls.for_task(fields.pop("task"), **fields)

    def with_overrides(self, assignments: list[str]) -> Config:
        """A copy with `key=value` assignments applied (values typed by the field), validated."""
        fields = {**self.to_dict(), **parse_assignments(assignments)}
        return self.for_task(fields.pop("task"), **fields)

    @property
    def limit(self) -> int:
        """The episode step limit in force."""
        return step_limit(self.task, self.max_steps, self.env_kwargs)

    @property
    def method(self) -> Method:
        """The registered method `expert_loss` names (methods.py)."""
        return get_method(self.expert_loss)

    @property
    def uses_demos(self) -> bool:
        """Every method but plain DQN (`none`) learns from demonstrations."""
        return self.method.needs_demos

    @property
    def initial_epsilon(self) -> float:
        if self.epsilon_start is not None:
            return self.epsilon_start
        return 0.1 if self.uses_demos else 1.0

    @property
    def uses_bc(self) -> bool:
        """Whether a BC model is fitted (bc_margin, ce, bayes: the method's `bc_fit`)."""
        return self.method.uses_bc

    @property
    def bayesian_bc(self) -> bool:
        """The BC model is fitted by MAP with dropout (bayes), not by MLE (ce, bc_margin)."""
        return self.method.bc_fit == "map"

    def validate(self) -> Config:
        """Raise ConfigError for the first value the algorithm cannot use (a wrong type, a name
        outside its choices, a number out of range: config_checks.py); return self, each field
        holding its plain Python value."""
        check(self)
        check_demonstrator(self.expert, get_task(self.task))
        if not self.uses_demos and self.total_steps < self.batch_size:
            raise ConfigError(
                f"total_steps={self.total_steps} is below batch_size={self.batch_size}: without "
                "demonstrations there is no pre-training, so no gradient step would ever be taken"
            )
        if self.limit < self.n_step:
            warnings.warn(
                f"the episode limit {self.limit} is shorter than the n-step window n_step={self.n_step}: "
                "every n-step return is cut at the end of its episode",
                DqfdWarning,
                stacklevel=2,
            )
        return self

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


def preset_defaults(task: str, expert_loss: object = None) -> dict[str, object]:
    """The defaults of `task` for `expert_loss` (None: the preset's own method): `shared_defaults` with
    that method's own defaults on the preset over them (`TaskSpec.method_defaults`)."""
    preset = shared_defaults(task)
    method = preset["expert_loss"] if expert_loss is None else expert_loss
    own = get_task(task).method_defaults.get(method, {}) if isinstance(method, str) else {}
    return {**preset, **own, "task": task}


def shared_defaults(task: str) -> dict[str, object]:
    """The defaults every method shares on `task` (its preset's; for any env `ENV_DEFAULTS`, for an
    Atari env `atari.ATARI_DEFAULTS`), without validating them: an env without a time limit has no
    valid defaults until `max_steps` is given."""
    shared = {
        f.name: f.default_factory() if f.default_factory is not dataclasses.MISSING else f.default
        for f in dataclasses.fields(Config)
    }
    return {**shared, **get_task(task).defaults, "task": task}


DERIVED_KEYS = ("observation",)
"""Keys of a config.json that record what the run found (the observation layout), not settings."""


def parse_assignments(assignments: list[str]) -> dict[str, object]:
    """`key=value` assignments (`--set`) as Config fields, each value typed by its field.

    Tuples are comma lists (`hidden=128,128`); `none` sets an optional field to None;
    `env_kwargs` takes a JSON object. Applied before any validation, so an override can make a
    task usable (`max_steps` on an env without a time limit).
    """
    types = {f.name: str(f.type) for f in dataclasses.fields(Config)}  # already strings: annotations are postponed
    changes: dict[str, object] = {}
    for assignment in assignments:
        key, sep, text = assignment.partition("=")
        key = key.strip().replace("-", "_")
        if key == "task":
            raise ConfigError("the task is chosen with --task or --env: each has its own preset defaults")
        if not sep:
            raise ConfigError(f"--set {assignment!r}: expected key=value")
        if key not in types:
            raise ConfigError(f"--set {assignment!r}: {unknown_field(key)}")
        changes[key] = parsed(key, types[key], text.strip())
    return changes


def unknown_field(key: str) -> str:
    """What is said of `key`, which is no Config field: the nearest field's name, if any."""
    import difflib

    near = difflib.get_close_matches(key, [f.name for f in dataclasses.fields(Config)], n=1)
    hint = f"did you mean {near[0]}?" if near else "Config's fields are listed in dqfd_bc_keras/core/config.py"
    return f"unknown Config field {key!r}; {hint}"
