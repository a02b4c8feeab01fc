"""Every hyperparameter, with the paper's (or DQfD's) default, in one typed dataclass.

Where the paper is silent, ALGORITHM.md decides; where that is silent too, the value is ours
and the field's comment says so. `Config.for_task(name)` gives a task preset's defaults;
`validate` rejects settings the algorithm cannot use with a `ConfigError` naming the value.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from .envs import TIMEOUT_MODES, get_task
from .errors import ConfigError
from .losses import EXPERT_LOSSES, TARGETS, TD_LOSSES

PRIOR_CENTERS = ("pretrained", "zero")


@dataclass
class Config:
    """Hyperparameters of one run. Greek letters follow ALGORITHM.md."""

    # --- task -------------------------------------------------------------------------------
    task: str = "cartpole"
    """Task preset (envs.TASKS)."""
    timeout: str = "bootstrap"
    """Time-limit mode: bootstrap | naive | time-aware."""

    # --- the loss J = J_DQ + λ1·J_n + λ2·J_E + λ3·J_L2 (§2) ----------------------------------
    expert_loss: str = "bayes"
    """J_E: margin (DQfD) | bc_margin (DQfD-BC) | ce (DQfD-BC) | bayes (the paper) | none (plain DQN)."""
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

    # --- networks and optimisation (ours: the paper gives none) ----------------------------
    hidden: tuple[int, ...] = (64, 64)
    """Hidden ReLU layers of the Q-network."""
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

    seed: int = 0
    """Seed of every random generator of the run."""

    @classmethod
    def for_task(cls, task: str, **overrides: object) -> Config:
        """The defaults of task preset `task` with `overrides` applied, validated."""
        get_task(task)
        return cls(task=task, **overrides).validate()

    @property
    def uses_bc(self) -> bool:
        """Whether a BC model is fitted (every expert loss but DQfD's margin, and none)."""
        return self.expert_loss in ("bc_margin", "ce", "bayes")

    @property
    def bayesian_bc(self) -> bool:
        """The bayes loss fits the BC model by MAP with dropout; ce and bc_margin by MLE."""
        return self.expert_loss == "bayes"

    def validate(self) -> Config:
        """Raise ConfigError for the first value the algorithm cannot use; return self."""
        get_task(self.task)
        choices = {
            "timeout": TIMEOUT_MODES, "expert_loss": (*EXPERT_LOSSES, "none"), "target": TARGETS,
            "td_loss": TD_LOSSES, "prior_center": PRIOR_CENTERS,
        }
        for name, allowed in choices.items():
            if getattr(self, name) not in allowed:
                raise ConfigError(f"{name}={getattr(self, name)!r} is not one of {allowed}")
        checks = [
            ("gamma", 0.0 <= self.gamma <= 1.0, "in [0, 1]"),
            ("n_step", self.n_step >= 1, "≥ 1"),
            ("batch_size", self.batch_size >= 1, "≥ 1"),
            ("mc_passes", self.mc_passes >= 1, "≥ 1"),
            ("sigma0_sq", self.sigma0_sq > 0, "> 0"),
            ("temperature", self.temperature > 0, "> 0"),
            ("prior_scale", self.prior_scale > 0, "> 0"),
            ("bc_prior_scale", self.bc_prior_scale > 0, "> 0"),
            ("bc_dropout", 0.0 <= self.bc_dropout < 1.0, "in [0, 1)"),
            ("learning_rate", self.learning_rate > 0, "> 0"),
            ("bc_learning_rate", self.bc_learning_rate > 0, "> 0"),
            ("target_update_period", self.target_update_period >= 1, "≥ 1"),
            ("pretrain_steps", self.pretrain_steps >= 0, "≥ 0"),
            ("replay_capacity", self.replay_capacity >= self.n_step, "≥ n_step"),
            ("demo_capacity", self.demo_capacity >= 1, "≥ 1"),
            ("priority_alpha", self.priority_alpha >= 0, "≥ 0"),
            ("priority_beta0", 0.0 <= self.priority_beta0 <= 1.0, "in [0, 1]"),
            ("priority_eps_agent", self.priority_eps_agent > 0, "> 0"),
            ("priority_eps_demo", self.priority_eps_demo > 0, "> 0"),
            ("hidden", len(self.hidden) >= 1 and min(self.hidden) >= 1, "a non-empty list of positive sizes"),
            ("bc_hidden", len(self.bc_hidden) >= 1 and min(self.bc_hidden) >= 1, "a non-empty list of positive sizes"),
        ]
        for name, ok, expected in checks:
            if not ok:
                raise ConfigError(f"{name} must be {expected}, got {getattr(self, name)!r}")
        return self

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)
