"""Suites of training runs: declared arms × seeds (run by sweep.py on a process pool or Ray).

    python -m dqfd_bc_keras.experiments run paper --out results          # each arm its planned seeds
    python -m dqfd_bc_keras.experiments run all --out results            # every suite of RESULTS.md
    python -m dqfd_bc_keras.experiments run quick --seeds 2 --backend ray --out /tmp/quick

A suite is a list of `Arm`s (arm_config.py: task, time-limit mode, expert loss, any other Config
field, and how many seeds it gets); each (arm, seed) is one `train.py`-equivalent run in
`OUT/<arm>/seed<N>/`. Arms equal in config get one name, so suites sharing an `--out` share runs.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TypedDict, cast

from dqfd_bc_keras.core.config import QUICK, Config, parse_assignments
from dqfd_bc_keras.envs.make import checked_spaces
from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.experiments.arm_config import Arm, arm, on_shared_defaults, quick
from dqfd_bc_keras.experiments.claims import CLAIMS, PAPER_READING_STEPS
from dqfd_bc_keras.experiments.claims import PAPER as PAPER_READING
from dqfd_bc_keras.experiments.lab_settings import LAB_SETTINGS
from dqfd_bc_keras.experiments.plans import planned_seeds
from dqfd_bc_keras.plugins import load, parse


def on_task(arms: Sequence[Arm], task: str | None, assignments: Sequence[str] = ()) -> list[Arm]:
    """`arms` moved to `task` (a preset or any Gymnasium env id; None: their own) with the Config
    `key=value` `assignments` added (e.g. `expert=module:function`); arms that become equal run once."""
    keys = [text.partition("=")[0].strip().replace("-", "_") for text in assignments]
    for key in set(keys) & {"timeout", "expert_loss", "seed"}:
        raise ConfigError(f"--set {key}: {key} is an arm's own (seeds: --seeds)")
    moved = []
    for a in arms:
        target = a.task if task is None else task
        config = Config.for_task(target, **{**dict(a.overrides), **parse_assignments(list(assignments))})
        checked_spaces(config)  # an env the networks cannot take is refused here, before any run starts
        parsed = config.to_dict()
        moved.append(
            arm(target, a.timeout, a.expert_loss, a.seeds, **{**dict(a.overrides), **{k: parsed[k] for k in keys}})
        )
    return list(dict.fromkeys(moved))


PAPER_SETTINGS = (
    ("C1", "cartpole", "naive"),
    ("C1", "cartpole-200", "naive"),
    ("C3", "cartpole", "bootstrap"),
    ("C4", "mountaincar-goals", "bootstrap"),
)
"""The paper's settings (ALGORITHM.md §7) and the claim whose power plan sets each one's seeds."""


def claim_seeds(claim_id: str, task: str) -> int:
    """The planned seeds per arm of `claim_id` on its setting of `task` (plans.PLANNED_SEEDS)."""
    setting = next(s for c in CLAIMS if c.id == claim_id for s in c.settings if s.task == task)
    return planned_seeds(claim_id, setting)


PROTOCOL = {"eval_every": 1_000, "eval_episodes": 10}
"""The sample-efficiency protocol, ours and SB3's alike: 10 greedy episodes on the plain env with
fixed seeds (`seeds.eval_seed`) at exactly every 1,000 interactions."""


def efficiency_tasks() -> dict[str, int]:
    """Sample-efficiency tasks → demonstration episodes of the imperfect expert (each task's
    `efficiency_demos`, lab_settings.py), a user's registered tasks included."""
    return {task: lab.efficiency_demos for task, lab in LAB_SETTINGS.items() if lab.efficiency_demos}


PAPER_TASKS = ("cartpole", "mountaincar")
"""The paper's two envs: the dynamic-demonstration readings and every expert loss run on them."""
C2_PAPER_READING = {"early_stop_window": 0, "total_steps": PAPER_READING_STEPS}
"""C2 as the paper runs it: "average ≥ 490, 10 times in a row" with 200-step episodes can never
fire, so no early stop, and a budget of at least 300 episodes (300 × 200 steps)."""


def _paper() -> list[Arm]:
    """C1–C4 (ALGORITHM.md §7): ce vs bayes in the paper's settings, each with its planned seeds,
    and C2 also under the paper's own reading (its seeds planned on the archive's collapse rate,
    PREREGISTRATION §11)."""
    arms = [arm(t, m, loss, claim_seeds(claim, t)) for claim, t, m in PAPER_SETTINGS for loss in ("ce", "bayes")]
    return arms + [
        arm("cartpole-200", "naive", loss, planned_seeds("C2", PAPER_READING), **C2_PAPER_READING)
        for loss in ("ce", "bayes")
    ]


def _dynamic() -> list[Arm]:
    """The two readings of dynamic demonstrations, measured with every interaction counted; the
    rule that picks `Config.dynamic_demos`'s default from them is in docs/PREREGISTRATION.md."""
    return [
        arm(task, "bootstrap", loss, 10, dynamic_demos=mode, **PROTOCOL)
        for task in PAPER_TASKS
        for loss in ("bayes", "ce")
        for mode in ("episodes", "rollouts")
    ]


def efficiency_arm(task: str, loss: str, episodes: int) -> Arm:
    """`loss` on `task` as the efficiency suite (§7) runs it: on the preset's shared defaults, as its
    committed runs are; a method's tuned set on a preset is measured by PREREGISTRATION §16's check."""
    return on_shared_defaults(arm(task, "bootstrap", loss, 10, demo_episodes=episodes, **PROTOCOL))


def _efficiency() -> list[Arm]:
    """Interactions to the plain env's threshold, against SB3's DQN (`experiments efficiency`, baselines.py):
    bayes, ce, DQfD's margin and DQN on the paper's envs; the default (bayes) alone on the others."""
    return [
        efficiency_arm(task, loss, episodes)
        for task, episodes in efficiency_tasks().items()
        for loss in (("bayes", "ce", "margin", "none") if task in PAPER_TASKS else ("bayes",))
    ]


def _ablations() -> list[Arm]:
    """What the Bayesian machinery contributes, on C3's and C4's settings: dynamic demonstrations
    off (bayes and ce), the prior term off, σ² fixed at σ0² (no MC dropout)."""
    arms = []
    for task in ("cartpole", "mountaincar-goals"):
        arms += [arm(task, "bootstrap", loss, 10, dynamic_demos="off") for loss in ("bayes", "ce")]
        arms += [
            arm(task, "bootstrap", "bayes", 10, bayes_prior=False),
            arm(task, "bootstrap", "bayes", 10, mc_dropout=False),
        ]
    return arms


def _sensitivity() -> list[Arm]:
    """σ0² of the Bayesian loss and the demonstrator's quality, where the paper fixes neither."""
    arms = []
    for task, timeout in (("cartpole", "bootstrap"), ("mountaincar-goals", "bootstrap")):
        for expert in ("imperfect", "strong"):
            arms += [arm(task, timeout, "bayes", 5, expert=expert, sigma0_sq=s) for s in (0.05, 0.5, 2.0)]
            arms.append(arm(task, timeout, "ce", 5, expert=expert))
    return arms


BEST_OTHER_ESTIMATOR = "distance"
"""`calibration.best_other` of docs/data/calibration.json (PREREGISTRATION §8), picked before any run with it."""
OTHER_ESTIMATORS = (BEST_OTHER_ESTIMATOR, "ensemble")
GRID_TASKS = ("cartpole", "mountaincar")
"""The grid's tasks (PREREGISTRATION §8, §12); each one's `grid_teachers` (lab_settings.py) holds its
teachers' means."""
GRID_TEACHERS = (("strong", 0.0), ("imperfect", 0.0), ("strong", 0.2), ("strong", 0.5))
"""(expert, ε): the strong and imperfect scripted experts, and the strong one acting at random w.p. ε."""
GRID_EPISODES = (1, 5, 20)
GRID_SEEDS = 5
GRID_METHODS = (
    ("margin", ()),
    ("ce", ()),
    ("bayes", ()),
    ("bayes", (("uncertainty", BEST_OTHER_ESTIMATOR),)),
    ("sqil", ()),
)
"""(expert loss, further Config fields) of the grid's learners with demonstrations."""


QUICK_GRID = ((("strong", 0.5),), (1,))
"""`--quick`: one cell (a bad teacher, one episode) of the first task, one seed, the QUICK budget (the tests' grid)."""


class GridCell(TypedDict):
    """The Config fields of one cell of the grid."""

    expert: str
    expert_epsilon: float
    demo_episodes: int


def grid_cells(quick: bool = False) -> list[GridCell]:
    """The Config fields of each cell: teacher × demonstrated episodes."""
    teachers, episodes = QUICK_GRID if quick else (GRID_TEACHERS, GRID_EPISODES)
    return [
        {"expert": expert, "expert_epsilon": epsilon, "demo_episodes": n}
        for expert, epsilon in teachers
        for n in episodes
    ]


def grid_tasks(quick: bool = False) -> tuple[str, ...]:
    return GRID_TASKS[:1] if quick else GRID_TASKS


def grid_arms(task: str, quick_budget: bool = False) -> list[Arm]:
    """When demonstrations help or hurt on `task` (PREREGISTRATION §8, §12): every method on every
    cell, and plain DQN once; BC alone is `imitation.py`'s, without RL."""
    arms = [arm(task, "bootstrap", "none", GRID_SEEDS, **PROTOCOL)]
    arms += [
        arm(task, "bootstrap", loss, GRID_SEEDS, **cell, **dict(extra), **PROTOCOL)
        for cell in grid_cells(quick_budget)
        for loss, extra in GRID_METHODS
    ]
    return [quick(a) for a in arms] if quick_budget else arms


def all_grid_arms(quick_budget: bool = False) -> list[Arm]:
    """Suite `demos`: the grid's arms on each of its tasks (`--quick`: the first task's quick cell)."""
    return [a for task in grid_tasks(quick_budget) for a in grid_arms(task, quick_budget)]


def _estimators() -> list[Arm]:
    """bayes with the other estimators on the verdicts' settings (C3, C4, MountainCar's efficiency),
    in the pre-registered order: the best one first."""
    return [
        a
        for u in OTHER_ESTIMATORS
        for a in (
            arm("cartpole", "bootstrap", "bayes", claim_seeds("C3", "cartpole"), uncertainty=u),
            arm("mountaincar-goals", "bootstrap", "bayes", claim_seeds("C4", "mountaincar-goals"), uncertainty=u),
            arm(
                "mountaincar",
                "bootstrap",
                "bayes",
                10,
                uncertainty=u,
                demo_episodes=efficiency_tasks()["mountaincar"],
                **PROTOCOL,
            ),
        )
    ]


SIGMA0_VALUES = (0.02, 0.1)
"""σ0² below the variance cap (1 − 1/A)/A, where 1/(2σ²) can vary 3.5–13.5× between states (§10)."""
SIGMA0_ESTIMATORS = (BEST_OTHER_ESTIMATOR, "mc_dropout")
BAD_TEACHERS = (("imperfect", 0.0), ("strong", 0.5))
"""The grid's teachers whose demonstrations an unsure expert loss should down-weight (§10)."""


def sigma0_settings() -> list[tuple[str, str, int, dict[str, object]]]:
    """(setting, task, seeds, Config fields) of the σ0² study (PREREGISTRATION §10), in its order:
    C3's, the CartPole grid's bad-teacher cells, MountainCar's efficiency setting."""
    cells = [cell for cell in grid_cells() if (cell["expert"], cell["expert_epsilon"]) in BAD_TEACHERS]
    return [
        ("C3", "cartpole", claim_seeds("C3", "cartpole"), {}),
        *(
            (
                f"grid {c['expert']} ε={c['expert_epsilon']:g} × {c['demo_episodes']}",
                "cartpole",
                GRID_SEEDS,
                {**c, **PROTOCOL},
            )
            for c in cells
        ),
        ("MountainCar efficiency", "mountaincar", 10, {"demo_episodes": efficiency_tasks()["mountaincar"], **PROTOCOL}),
    ]


def _sigma0() -> list[Arm]:
    """ce and bayes at each low σ0² with each estimator on every setting of the study, in its
    pre-registered order: on CartPole ce and the distance estimator, then MC dropout; then
    MountainCar. ce is rerun with the study (the archive's ce runs are from older code, which
    the current code does not reproduce seed for seed), so the study lives in its own directory."""

    def arms(settings: list, losses: list[tuple[str, dict]]) -> list[Arm]:
        return [
            arm(task, "bootstrap", loss, seeds, **extra, **fields)
            for _, task, seeds, fields in settings
            for loss, extra in losses
        ]

    bayes = {u: [("bayes", {"uncertainty": u, "sigma0_sq": s}) for s in SIGMA0_VALUES] for u in SIGMA0_ESTIMATORS}
    first, second = SIGMA0_ESTIMATORS
    *cartpole, mountaincar = sigma0_settings()
    ordered = [
        *arms(cartpole, [("ce", {}), *bayes[first]]),
        *arms(cartpole, bayes[second]),
        *arms([mountaincar], [("ce", {}), *bayes[first], *bayes[second]]),
    ]
    unique: dict[str, Arm] = {}
    for a in ordered:  # the grid's imperfect × 5 cell is C3's setting: its arms run once, at C3's seeds
        unique.setdefault(a.name, a)
    return list(unique.values())


SUITES: dict[str, list[Arm]] = {
    "dynamic": _dynamic(),
    "efficiency": _efficiency(),
    "paper": _paper(),
    "ablations": _ablations(),
    "baselines": [arm(t, m, loss) for _, t, m in PAPER_SETTINGS for loss in ("none", "margin", "bc_margin")],
    "sensitivity": _sensitivity(),
    "demos": all_grid_arms(),
    "estimators": _estimators(),
    "sigma0": _sigma0(),
    "quick": [Arm("cartpole", "bootstrap", loss, tuple(QUICK.items()), "quick", 2) for loss in ("bayes", "ce")],
}
ALL = ("dynamic", "efficiency", "paper", "ablations", "baselines", "sensitivity", "estimators", "demos")
"""`run all`: every suite of RESULTS.md, in this order, into one directory (shared arms run once)."""


def suite_arms(suite: str) -> list[Arm]:
    """The arms of suite `suite`: one of `SUITES`, or a user's `module:NAME`, a list of `Arm`s
    (built with `arm(...)`) in an importable module."""
    if suite in SUITES:
        return SUITES[suite]
    if parse(suite) is None:
        raise ConfigError(f"unknown suite {suite!r}; expected one of {sorted(SUITES)} or module:NAME")
    return list(
        cast("list[Arm]", load(suite, f"suite {suite!r}", _is_arms, "non-empty list of experiments.suites.Arm"))
    )


def _is_arms(value: object) -> bool:
    return isinstance(value, (list, tuple)) and bool(value) and all(isinstance(a, Arm) for a in value)
