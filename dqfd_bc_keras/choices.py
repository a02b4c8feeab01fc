"""The names a string setting may take, in a module that imports nothing: config.py validates
against them, wrappers and network_input branch on them, and the command lines offer them in
`--help` before TensorFlow (or Gymnasium) loads. losses.py takes the names it is given."""

from __future__ import annotations

TIMEOUT_MODES = ("bootstrap", "naive", "time-aware")
"""How the step limit reaches the learner (`Config.timeout`, wrappers.TimeLimitMode): `bootstrap`
truncates (Gymnasium semantics, the paper's fix: learners bootstrap from Q(s')); `naive` reports
it as a termination (old Gym, the problem the paper starts from); `time-aware` appends the
remaining-time fraction to the observation and then a termination is the truth (Pardo et al. 2018)."""
TARGETS = ("dqn", "double")
"""The bootstrap targets (`Config.target`, losses.bootstrap_value)."""
TD_LOSSES = ("squared", "huber")
"""The per-sample TD losses (`Config.td_loss`, losses.td_loss)."""
ESTIMATORS = ("mc_dropout", "ensemble", "distance")
"""The estimators of the BC model's epistemic variance v(s) (uncertainty.py), which the lab compares."""
UNCERTAINTIES = (*ESTIMATORS, "local")
"""What `Config.uncertainty` may name: an estimator, σ²(s) = σ0² + v(s); or `local`, the distance
estimator's v(s) read as σ²(s) = σ0²/(1 − v(s)/v_max) (`bayes_local`, ALGORITHM.md §8)."""
PRIOR_CENTERS = ("pretrained", "zero")
"""θ_prior of the Bayesian loss (`Config.prior_center`)."""
DYNAMIC_MODES = ("episodes", "rollouts", "off")
"""How D_demo grows (`Config.dynamic_demos`, §5): the agent's own training episodes, M extra greedy
roll-outs, or not at all."""
TORSOS = ("auto", "mlp", "minatar", "nature")
"""What reads the observation (`Config.torso`, network_input.py)."""
EXPERT_NAMES = ("strong", "imperfect")
"""The scripted experts every package preset has (`Config.expert`, tasks/): a strong one and an imperfect one."""
POLICY_FILES = {"q": "q_network.keras", "bc": "bc_model.keras"}
"""What `evaluate.py --policy` names: a run directory's model file."""
LOSS_TERMS = ("loss", "td", "n_step", "expert", "l2")
"""J(Q) and its terms by name (ALGORITHM.md §2): what the agent's `train_step` reports and
training.records.Losses logs, one column each."""
