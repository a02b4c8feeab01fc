"""The claims analysis on synthetic run directories whose every number is known by hand."""

import csv
import dataclasses
import json
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import stats as sps

from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.evaluation import EvalResult
from dqfd_bc_keras.experiments import ablations, metrics
from dqfd_bc_keras.experiments import arms as grouping
from dqfd_bc_keras.experiments import claims as analysis
from dqfd_bc_keras.experiments import plans as planning
from dqfd_bc_keras.experiments import report as results
from dqfd_bc_keras.experiments.arms import ArmRuns, Setting
from dqfd_bc_keras.experiments.data import load_runs
from dqfd_bc_keras.experiments.efficiency import ArmSteps
from dqfd_bc_keras.experiments.lab_settings import (
    LAB_SETTINGS,
    NO_SETTINGS,
    LabSettings,
    lab_settings,
    register_lab_settings,
)
from dqfd_bc_keras.experiments.run_files import FinishedRun, Provenance
from dqfd_bc_keras.experiments.stats import mann_whitney, tost_ci
from dqfd_bc_keras.experiments.summary import summary
from dqfd_bc_keras.runs.directory import EVAL_FIELDS
from dqfd_bc_keras.runs.writers import write_demonstrations
from dqfd_bc_keras.tasks import TASKS
from dqfd_bc_keras.training.loop import METRIC_FIELDS
from dqfd_bc_keras.training.records import DemoSummary

# cartpole-200 naive: an episode of length L < 200 is a fall, task return L − 1 − 100, plain L
SOLVER = [50] * 5 + [200] + [80] + [200] * 10  # peak at 6, collapse at 7, rule fires at 17
UNFINISHED = ([200] * 9 + [60]) * 2  # never 10 in a row; 2 collapses (the 60s) after the first peak
SOLVER_MEAN = (5 * 50 + 200 + 80 + 10 * 200) / 17


def cartpole_rows(lengths: list[int]) -> list[dict]:
    return [
        {"return": 200.0 if n >= 200 else n - 101.0, "plain_return": float(n), "length": n, "goals": 0} for n in lengths
    ]


def goal_rows(goals: list[int]) -> list[dict]:
    return [
        {"return": 100.0 * g - (200 - g), "plain_return": -150.0 if g else -200.0, "length": 200, "goals": g}
        for g in goals
    ]


def make_run(path: Path, rows: list[dict], evals: list[float] = (0.0,), final: float = 0.0, **fields) -> FinishedRun:
    """A run of `rows` (episode, env_step, wall_time and losses filled in); evals every 5k interactions
    (at 4k loop steps each: roll-outs played the rest)."""
    config = Config.for_task(**fields)
    steps = np.cumsum([r["length"] for r in rows])
    metrics = [
        {
            **{f: 0.0 for f in METRIC_FIELDS},
            **r,
            "episode": i + 1,
            "env_step": int(steps[i]),
            "interactions": int(steps[i]),
            "wall_time": 60.0 * (i + 1) / len(rows),
        }
        for i, r in enumerate(rows)
    ]
    evaluations = [
        {
            "env_step": 4000 * i,
            "interactions": 5000 * i,
            "episode": 0,
            "mean_return": m,
            "std_return": 0.0,
            "mean_goals": None,
        }
        for i, m in enumerate(evals)
    ]
    demos = DemoSummary(
        transitions=1000,
        episodes=5,
        expert=config.expert,
        episode_returns=[100.0] * 5,
        plain_returns=[100.0] * 5,
        pretrain_steps=config.pretrain_steps,
        source="recorded",
    )
    return FinishedRun(
        path,
        config,
        metrics,
        evaluations,
        EvalResult(config.task, "q", 0, [final], [1], timeout=config.timeout),
        demos if config.uses_demos else None,
        [],
        Provenance(None, None, None, {}),
    )


def write_run(run: FinishedRun) -> None:
    run.path.mkdir(parents=True)
    (run.path / "config.json").write_text(json.dumps(run.config.to_dict()))
    for name, fields, rows in (("metrics.csv", METRIC_FIELDS, run.metrics), ("evals.csv", EVAL_FIELDS, run.evals)):
        with (run.path / name).open("w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=fields)
            writer.writeheader()
            writer.writerows(rows)
    (run.path / "eval.json").write_text(json.dumps(run.final.to_dict()))
    (run.path / "provenance.json").write_text(json.dumps(dataclasses.asdict(run.provenance)))
    if run.demonstrations is not None:
        write_demonstrations(run.path, run.demonstrations)


def arm(runs: list[FinishedRun]) -> ArmRuns:
    return grouping.group_arms(runs)[0]


CP = {"task": "cartpole-200", "timeout": "naive"}
MC = {"task": "mountaincar-goals"}


@pytest.fixture(scope="module")
def suite(tmp_path_factory) -> Path:
    """cartpole-200/naive: bayes, ce (3 seeds each, one unfinished run each) and none (2 seeds);
    mountaincar-goals: bayes and ce (4 seeds) and bayes σ0² = 0.05 (4 seeds, fewer goals than ce).
    Directory names are shuffled on purpose: the analysis must group by config.json."""
    root = tmp_path_factory.mktemp("suite")
    runs = []
    for loss in ("bayes", "ce"):
        for seed, lengths in enumerate((SOLVER, UNFINISHED, SOLVER)):
            runs.append(
                (cartpole_rows(lengths), [20.0, 300.0, 480.0, 500.0], 500.0, {**CP, "expert_loss": loss, "seed": seed})
            )
    runs += [(cartpole_rows([30] * 20), [20.0], 25.0, {**CP, "expert_loss": "none", "seed": s}) for s in (0, 1)]
    for loss, sigma, base in (("bayes", 0.5, 2), ("ce", 0.5, 1), ("bayes", 0.05, 0)):
        for seed in range(4):
            goals = [base + 1] * seed + [base] * (30 - seed) + [3] * 10  # goals_first30 = base + seed/30
            runs.append(
                (
                    goal_rows(goals),
                    [-200.0, -120.0],
                    -130.0,
                    {**MC, "expert_loss": loss, "sigma0_sq": sigma, "seed": seed},
                )
            )
    order = np.random.default_rng(0).permutation(len(runs))
    for i, (rows, evals, final, fields) in zip(order, runs, strict=True):
        write_run(make_run(root / f"x{i:02d}" / "run", rows, evals, final, **fields))
    (root / "incomplete").mkdir()
    (root / "incomplete" / "config.json").write_text(json.dumps(Config.for_task("cartpole").to_dict()))
    return root


def test_per_run_metrics_by_hand(tmp_path):
    solver = make_run(tmp_path, cartpole_rows(SOLVER), [20.0, 300.0, 480.0, 500.0], **CP)
    assert metrics.episodes_to_solve(solver) == 17 and metrics.finished(solver)
    assert metrics.collapses(solver) == 1
    assert metrics.PER_RUN["mean_train_return"](solver) == pytest.approx(SOLVER_MEAN)
    assert metrics.interactions_to_threshold(solver) == 10_000  # 480 ≥ 475 at the third evaluation
    unfinished = make_run(tmp_path, cartpole_rows(UNFINISHED), [20.0, 400.0], **CP)
    assert metrics.episodes_to_solve(unfinished) is None and not metrics.finished(unfinished)
    assert metrics.PER_RUN["episodes_to_solve"](unfinished) == np.inf  # censored
    assert metrics.PER_RUN["unfinished"](unfinished) == 1.0
    assert metrics.collapses(unfinished) == 2 and metrics.PER_RUN["collapsed"](unfinished) == 1.0
    assert metrics.interactions_to_threshold(unfinished) == np.inf
    goals = make_run(tmp_path, goal_rows([1] * 30 + [3] * 10), [-200.0, -110.0], **MC)
    assert metrics.PER_RUN["goals_first30"](goals) == 1.0
    assert metrics.PER_RUN["goals_all"](goals) == pytest.approx(60 / 40)
    assert metrics.interactions_to_threshold(goals) == 5000  # −110 reaches MountainCar-v0's threshold
    assert metrics.episodes_to_solve(goals) is None  # no early-stopping rule on MountainCar


def test_a_censored_run_ranks_after_every_finished_run(tmp_path):
    """A run that never solved in 20 episodes ranks after one that solved at episode 30: its own
    episode count + 1 (21) would have ranked it first."""
    censored = make_run(tmp_path, cartpole_rows(UNFINISHED), expert_loss="bayes", **CP)
    slow = make_run(tmp_path, cartpole_rows([50] * 20 + [200] * 10), expert_loss="ce", **CP)
    values = [metrics.PER_RUN["episodes_to_solve"](r) for r in (censored, slow)]
    assert values == [np.inf, 30.0] and list(sps.rankdata(values)) == [2.0, 1.0]
    never = arm([make_run(tmp_path, cartpole_rows(UNFINISHED), expert_loss="bayes", seed=s, **CP) for s in range(3)])
    slower = arm(
        [
            make_run(tmp_path, cartpole_rows([50] * (20 + s) + [200] * 10), expert_loss="ce", seed=s, **CP)
            for s in range(3)
        ]
    )
    comparison = analysis.compare("episodes_to_solve", never, slower)
    assert comparison.diff is None and comparison.tost is None and comparison.interval() == "—"  # no mean over inf
    assert (comparison.bayes.median, comparison.bayes.censored, comparison.ce.median) == (np.inf, 3, 31.0)
    u, p = mann_whitney(never.values("episodes_to_solve"), slower.values("episodes_to_solve"))
    assert u == 9.0 and comparison.p == p  # every censored run ranks after every finished one: U = 3 · 3


def test_early_stop_rule_follows_the_config(tmp_path):
    run = make_run(tmp_path, cartpole_rows([200] * 3 + [150] + [200] * 3), early_stop_window=3, **CP)
    assert metrics.episodes_to_solve(run) == 3
    run = make_run(
        tmp_path,
        cartpole_rows([200] * 3 + [150] + [200] * 3),
        early_stop_window=3,
        early_stop_fraction=0.5,
        max_steps=400,
        **CP,
    )  # limit 400: 200 ≥ 0.5 × 400
    assert metrics.episodes_to_solve(run) == 3
    assert metrics.collapses(run) == 0  # never ≥ 0.98 × 400


def test_runs_are_grouped_into_arms_by_config(suite):
    runs = load_runs(suite)
    assert len(runs) == 20  # the run without eval.json is left out
    arms = grouping.group_arms(runs)
    assert [(a.label, len(a.runs)) for a in arms] == [
        ("cartpole-200/naive · bayes", 3),
        ("cartpole-200/naive · ce", 3),
        ("cartpole-200/naive · none", 2),
        ("mountaincar-goals/bootstrap · bayes sigma0_sq=0.05", 4),
        ("mountaincar-goals/bootstrap · bayes sigma0_sq=0.5", 4),
        ("mountaincar-goals/bootstrap · ce", 4),
    ]
    assert sorted(r.config.seed for r in arms[0].runs) == [0, 1, 2]
    pairs = grouping.bayes_ce_pairs(arms, "mountaincar-goals", None)
    assert [(b.name, c.name) for b, c in pairs] == [("bayes sigma0_sq=0.5", "ce"), ("bayes sigma0_sq=0.05", "ce")]


def cartpole_arm(tmp_path, loss: str, lengths: list[list[int]]) -> ArmRuns:
    return arm([make_run(tmp_path, cartpole_rows(n), expert_loss=loss, seed=s, **CP) for s, n in enumerate(lengths)])


def return_arm(tmp_path, loss: str, returns, **fields) -> ArmRuns:
    """One single-episode run per seed whose mean training return is the given value."""
    return arm(
        [
            make_run(
                tmp_path,
                [{"return": r, "plain_return": r, "length": 1, "goals": 0}],
                expert_loss=loss,
                seed=s,
                **fields,
            )
            for s, r in enumerate(returns)
        ]
    )


SPREAD = np.arange(1.0, 11.0)
"""10 seeds 1..10: for k · SPREAD against itself the bootstrap puts Δ's 90% CI at ±2.1 k, its 95% CI at ±2.5 k."""


@pytest.mark.parametrize(
    "judge, fields, margin",
    [(analysis.judge_c1, CP, 10.0), (analysis.judge_c3, {"task": "cartpole", "timeout": "bootstrap"}, 25.0)],
)
@pytest.mark.parametrize(
    "spread, shift, expected",
    [
        (0.005, 0.5, "holds"),  # half a margin apart, seeds wholly separated: significant, yet inside the margin
        (0.44, 1.0, "inconclusive"),  # Δ = margin: the CI straddles it
        (0.005, 2.0, "does not hold"),  # twice the margin apart: wholly outside it
        (1.0, 0.0, "inconclusive"),  # equal means and Mann–Whitney p = 1, but too spread to show sameness
    ],
)
def test_no_difference_is_judged_by_tost(tmp_path, judge, fields, margin, spread, shift, expected):
    """Spread and shift in units of the margin (±5% of the limit)."""
    ce = 100.0 + spread * margin * SPREAD
    result = judge(
        return_arm(tmp_path / "b", "bayes", ce + shift * margin, **fields),
        return_arm(tmp_path / "c", "ce", ce, **fields),
    )
    assert result.verdict == expected
    returns = result.comparisons[0]
    assert returns.metric == "mean_train_return"
    assert returns.tost == pytest.approx(tost_ci(ce + shift * margin, ce, analysis.ALPHA))
    assert (returns.p < analysis.ALPHA) is (spread < 0.1)
    assert result.sd == pytest.approx(np.std(ce, ddof=1))
    assert result.power == pytest.approx(analysis.rule_power(result.sd, margin, 10))


@pytest.mark.parametrize(
    "judge, fields, margin",
    [(analysis.judge_c1, CP, 10.0), (analysis.judge_c3, {"task": "cartpole", "timeout": "bootstrap"}, 25.0)],
)
def test_tost_reads_the_90_not_the_95_percent_ci(tmp_path, judge, fields, margin):
    """At 0.44 margins of spread Δ's 95% CI reaches ±1.1 margins, its 90% CI ±0.92: equivalent."""
    ce = 100.0 + 0.44 * margin * SPREAD
    result = judge(return_arm(tmp_path / "b", "bayes", ce, **fields), return_arm(tmp_path / "c", "ce", ce, **fields))
    returns = result.comparisons[0]
    assert returns.diff[0] < -margin < returns.tost[0] and returns.tost[1] < margin < returns.diff[1]
    assert result.verdict == "holds"


def test_c1_reports_episodes_to_solve_beside_the_returns(tmp_path):
    solving = [[100 + i] + [200] * 10 for i in range(4)]  # mean returns 190.9 … 191.2: within ±10
    result = analysis.judge_c1(cartpole_arm(tmp_path, "bayes", solving), cartpole_arm(tmp_path, "ce", solving[::-1]))
    assert result.verdict == "holds"
    assert [c.metric for c in result.comparisons] == ["mean_train_return", "episodes_to_solve"]
    assert result.comparisons[1].bayes.median == 11.0
    failing = [[50] * 20] * 4
    result = analysis.judge_c1(cartpole_arm(tmp_path, "bayes", solving), cartpole_arm(tmp_path, "ce", failing))
    assert result.verdict == "does not hold" and result.comparisons[0].tost[0] > 100
    assert result.comparisons[1].p < analysis.ALPHA  # 11 episodes against never (∞)
    # fewer episodes to solve, significantly, yet the same returns: C1 is judged on returns alone
    quick = [[200] * 10 + [100] * 10 + [200] * 3] * 4
    late = [[100] * 10 + [200] * 13] * 4
    result = analysis.judge_c1(cartpole_arm(tmp_path, "bayes", quick), cartpole_arm(tmp_path, "ce", late))
    assert result.verdict == "holds" and result.comparisons[1].bayes.median < result.comparisons[1].ce.median


def goals_arm(tmp_path, loss: str, first30) -> ArmRuns:
    return arm([make_run(tmp_path, goal_rows([g] * 30), expert_loss=loss, seed=s, **MC) for s, g in enumerate(first30)])


@pytest.mark.parametrize(
    "bayes, ce, significant, expected",
    [
        (1.5 + 0.01 * SPREAD, 1.0 + 0.01 * SPREAD, True, "holds"),  # Δ = 0.5: its 90% CI wholly above +0.25
        (1.06 + 0.005 * SPREAD, 1.0 + 0.005 * SPREAD, True, "does not hold"),  # +0.06: significant, shown < +0.25
        (1.0 + 0.1 * SPREAD, 0.75 + 0.1 * SPREAD, False, "inconclusive"),  # Δ = 0.25: the CI straddles the margin
        (1.0 + 0.01 * SPREAD, 1.5 + 0.01 * SPREAD, True, "does not hold"),  # ce reaches the flag more often
        (np.full(4, 2.0), np.full(4, 2.0), False, "does not hold"),
    ],
)
def test_markedly_more_has_to_clear_the_margin(tmp_path, bayes, ce, significant, expected):
    result = analysis.judge_c4(goals_arm(tmp_path / "b", "bayes", bayes), goals_arm(tmp_path / "c", "ce", ce))
    assert result.verdict == expected
    early = result.comparisons[0]
    assert [c.metric for c in result.comparisons] == ["goals_first30", "goals_all"]
    assert (early.p < analysis.ALPHA) is significant
    assert result.power == pytest.approx(analysis.rule_power(result.sd, analysis.GOALS_MARGIN, len(bayes), True))


PAPER_FIELDS = {**CP, "early_stop_window": 0, "total_steps": analysis.PAPER_READING_STEPS}


def c2_arm(tmp_path, loss: str, lengths: list[list[int]], **fields) -> ArmRuns:
    return arm(
        [
            make_run(tmp_path / f"{loss}{s}", cartpole_rows(n), expert_loss=loss, seed=s, **{**CP, **fields})
            for s, n in enumerate(lengths)
        ]
    )


@pytest.mark.parametrize("fields", [{}, PAPER_FIELDS], ids=["today", "paper"])
def test_c2_without_perturbations_is_not_reproduced(tmp_path, fields):
    steady = [[50] * 5 + [200] * 15] * 4  # peaks and never falls back
    result = analysis.judge_c2(c2_arm(tmp_path, "bayes", steady, **fields), c2_arm(tmp_path, "ce", steady, **fields))
    assert result.verdict == "not reproduced"
    assert result.comparisons[0].metric == ("collapsed" if fields else "unfinished")


def test_c2_today_holds_on_equal_unfinished_shares_with_collapses_in_both(tmp_path):
    result = analysis.judge_c2(c2_arm(tmp_path, "bayes", [SOLVER] * 4), c2_arm(tmp_path, "ce", [SOLVER] * 4))
    assert result.verdict == "holds"  # every run finished after one collapse: shares 0 and 0
    unfinished, falls = result.comparisons
    assert (unfinished.metric, unfinished.tost, unfinished.p) == ("unfinished", (0.0, 0.0), 1.0)
    assert falls.bayes.mean == 1.0


def test_c2_paper_reading_is_selected_and_judged_on_collapses(tmp_path):
    """Without early stop every run is unfinished: C2 compares the share of runs with a collapse."""
    falling, steady = [[200] * 5 + [60] + [200] * 300] * 4, [[200] * 306] * 4
    runs = [
        r
        for a in (
            c2_arm(tmp_path / "p", "bayes", falling, **PAPER_FIELDS),
            c2_arm(tmp_path / "p", "ce", falling, **PAPER_FIELDS),
            c2_arm(tmp_path / "t", "bayes", [SOLVER] * 2),
            c2_arm(tmp_path / "t", "ce", [SOLVER] * 2),
        )
        for r in a.runs
    ]
    arms = grouping.group_arms(runs)
    c1_200, today, paper = analysis.CLAIMS[0].settings[1], *analysis.CLAIMS[1].settings
    assert paper.reading.startswith("the paper's reading") and today.reading.startswith("today's reading")
    [(bayes, ce)] = paper.pairs(arms)
    assert (bayes.config.early_stop_window, bayes.config.total_steps) == (0, 60_000)
    assert ce.config.expert_loss == "ce"
    [(bayes_today, _)] = today.pairs(arms)
    assert bayes_today.config.early_stop_window == 10
    assert [p[0] for p in c1_200.pairs(arms)] == [bayes_today, bayes]  # the preset pair is C1's reference
    result = analysis.judge(analysis.CLAIMS[1], bayes, ce)
    collapsed, falls = result.comparisons
    assert result.verdict == "holds" and collapsed.metric == "collapsed" and collapsed.tost == (0.0, 0.0)
    assert bayes.values("unfinished").tolist() == [1.0] * 4  # unfinished by construction
    assert falls.bayes.mean == 1.0
    never = c2_arm(tmp_path / "n", "ce", steady, **PAPER_FIELDS)
    assert analysis.judge_c2(bayes, never).verdict == "does not hold"  # shares 1 against 0
    assert (
        analysis.judge_c2(c2_arm(tmp_path / "m", "bayes", falling[:2] + steady[:2], **PAPER_FIELDS), never).verdict
        == "inconclusive"
    )  # one arm never collapses, shares ½ and 0


def test_c2_and_n_below_two(suite):
    arms = grouping.group_arms(load_runs(suite))
    bayes, ce = grouping.bayes_ce_pairs(arms, "cartpole-200", "naive")[0]
    result = analysis.judge_c2(bayes, ce)
    unfinished, falls = result.comparisons
    assert result.verdict == "inconclusive"  # 1 of 3 unfinished in each arm: too few seeds to show equal shares
    assert unfinished.bayes.mean == pytest.approx(1 / 3) and unfinished.p == 1.0
    assert not analysis.equivalent(unfinished.tost, analysis.SHARE_MARGIN)
    assert falls.bayes.mean == pytest.approx((1 + 2 + 1) / 3)
    lone = ArmRuns(bayes.config, bayes.runs[:1], "bayes")
    assert analysis.judge(analysis.CLAIMS[1], lone, ce).verdict == "inconclusive (n < 2)"
    assert analysis.judge(analysis.CLAIMS[1], bayes, None).verdict == "not run (no ce arm)"


def test_rules_state_the_constants():
    rules = {c.id: c.rule for c in analysis.CLAIMS}
    assert all("90% CI" in rule and "TOST_LEVEL" not in rule and "_MARGIN" not in rule for rule in rules.values())
    assert "±0.05 × limit" in rules["C1"] and "episodes_to_solve is reported, not judged" in rules["C1"]
    assert "not reproduced: no run of either arm collapses" in rules["C2"] and "±0.2" in rules["C2"]
    assert "above +0.25 and Mann–Whitney p < 0.05" in rules["C4"] and "below +0.25" in rules["C4"]


def test_planned_seeds():
    """Seeds per arm n = ⌈2 (z_0.95 + z_0.90)² sd² / margin²⌉ (z_0.80 for C4's one bound), at least 10."""
    settings = {(c.id, s.name) for c in analysis.CLAIMS for s in c.settings}
    assert set(planning.PLANNED_SEEDS) == settings
    plans = {key: (plan.sd, plan.margin, plan.seeds) for key, plan in planning.PLANNED_SEEDS.items()}
    today, paper = (s.name for s in analysis.CLAIMS[1].settings)
    assert plans[("C1", "cartpole/naive")] == (pytest.approx(36.13, abs=0.01), 25.0, 36)  # 17.128 · 36.13² / 25²
    assert plans[("C1", "cartpole-200/naive")] == (pytest.approx(11.73, abs=0.01), 10.0, 24)  # 17.128 · 1.3755
    assert plans[("C2", today)] == (pytest.approx(0.4), 0.2, 69)  # 17.128 · 4 = 68.51
    assert plans[("C2", paper)] == (pytest.approx(0.4583, abs=1e-4), 0.2, 90)  # 17.128 · 0.21 / 0.04 = 89.92
    assert plans[("C3", "cartpole/bootstrap")] == (pytest.approx(30.21, abs=0.01), 25.0, 26)  # 25.01
    assert plans[("C4", "mountaincar-goals/*")] == (pytest.approx(0.0767, abs=1e-4), 0.25, 10)  # 12.37 · 0.094 → 2
    assert planning.planned_seeds("C2", analysis.CLAIMS[1].settings[1]) == planning.planned_seeds("C2", paper) == 90
    with pytest.raises(planning.ConfigError, match="no planned seeds for claim 'C2' on setting 'cartpole/naive'"):
        planning.planned_seeds("C2", Setting("cartpole", "naive"))


def claim_rows(text: str) -> list[list[str]]:
    """The claims table's rows as cells (the sensitivity table has 6 columns, this one 8)."""
    rows = [line.split("|")[1:-1] for line in text.splitlines() if line.startswith("| C")]
    return [[cell.strip() for cell in row] for row in rows if len(row) == 8]


@pytest.mark.slow
def test_report_writes_markdown_and_figures(suite, tmp_path):
    out = tmp_path / "docs" / "RESULTS.md"
    text = results.report(suite, out, tmp_path / "docs" / "figures")
    assert out.read_text() == text
    claims = claim_rows(text)
    assert [(r[0], r[1].split("<br>")[0]) for r in claims] == [
        ("C1", "cartpole/naive"),
        ("C1", "cartpole-200/naive"),
        ("C2", "cartpole-200/naive early_stop_window=10"),
        ("C2", "cartpole-200/naive early_stop_window=0 total_steps=60000"),
        ("C3", "cartpole/bootstrap"),
        ("C4", "mountaincar-goals/*"),
    ]
    assert [r[-1] for r in claims] == [
        "not run",
        "**inconclusive**",
        "**inconclusive**",
        "not run",
        "not run",
        "**holds**",
    ]
    assert "today's reading" in claims[2][1] and "the paper's reading" in claims[3][1]
    assert "Fisher exact p = 1" in claims[2][5] and claims[2][6].startswith("3, 3 · sd ")
    assert "p = 0.0286" in claims[5][5]  # 4 vs 4 separated: exact p = 2/70
    assert "(90%: " in claims[5][4] and claims[5][6].startswith("4, 4 · sd ") and "power 1.00" in claims[5][6]
    assert "episodes_to_solve: bayes median 17.00 [17.00, ∞] (1 of 3 censored)" in claims[1][3]
    assert "Seeds planned for C1 on cartpole/naive: sd 36.1 of `mean_train_return`" in text
    assert (
        "- C2 (cartpole-200/naive early_stop_window=10; cartpole-200/naive early_stop_window=0 "
        f"total_steps=60000): {analysis.CLAIMS[1].rule}"
    ) in text
    rows = [line for line in text.splitlines() if line.startswith("| C")]
    sensitivity = [r for r in rows if "sigma0_sq=0.05" in r]
    assert len(sensitivity) == 1 and sensitivity[0].endswith("| does not hold | yes |")
    assert "total training wall time 20.0 min" in text
    assert all(line in text for line in results.REGENERATE)
    assert "| cartpole-200/naive | none | 2 | — | 0 | — | 25.0 [25.0, 25.0] (IQM 25.0) |" in text
    assert "| 500.0 [500.0, 500.0] (IQM 500.0) | " in text and "10,000 (3/3)" in text
    for setting in ("cartpole-200-naive", "mountaincar-goals-bootstrap"):
        for kind in ("curves", "cases"):
            png = tmp_path / "docs" / "figures" / f"{setting}-{kind}.png"
            assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
            assert f"(figures/{setting}-{kind}.png)" in text


def test_report_on_an_empty_suite_says_not_run(tmp_path):
    text = results.report(tmp_path, tmp_path / "RESULTS.md", tmp_path / "figures")
    rows = claim_rows(text)
    assert [r[0] for r in rows] == ["C1", "C1", "C2", "C2", "C3", "C4"]
    assert all(r[-1] == "not run" for r in rows)
    assert "0 complete runs" in text and not (tmp_path / "figures").exists()


def test_a_bad_config_names_its_file(tmp_path):
    write_run(make_run(tmp_path / "run", cartpole_rows([30]), **CP))
    (tmp_path / "run" / "config.json").write_text(json.dumps({"task": "cartpole", "colour": "red"}))
    with pytest.raises(ConfigError, match=r"run/config.json: unknown config field\(s\) \['colour'\]"):
        load_runs(tmp_path)


def test_a_run_repeated_in_another_suite_directory_counts_once(tmp_path):
    """Suites sharing arms (paper, sensitivity, the benchmark) may hold the same run twice."""
    for where in ("paper", "sensitivity"):
        write_run(make_run(tmp_path / where / "run", cartpole_rows([30]), expert_loss="ce", seed=3, **CP))
    write_run(make_run(tmp_path / "paper" / "other", cartpole_rows([30]), expert_loss="ce", seed=4, **CP))
    [only] = grouping.group_arms(load_runs(tmp_path))
    assert [r.config.seed for r in only.runs] == [3, 4]


def test_the_reference_pair_is_the_one_at_the_preset(tmp_path):
    """A variant with more seeds (a shorter budget, σ0² …) never displaces the preset pair."""
    runs = []
    for loss in ("bayes", "ce"):
        runs.append(make_run(tmp_path / loss, goal_rows([1]), expert_loss=loss, **MC))
        runs += [
            make_run(tmp_path / f"{loss}{s}", goal_rows([1]), expert_loss=loss, total_steps=20_000, seed=s, **MC)
            for s in range(3)
        ]
    arms = grouping.group_arms(runs)
    assert sorted(grouping.preset_distance(a) for a in arms) == [0, 0, 1, 1]
    bayes, ce = grouping.bayes_ce_pairs(arms, "mountaincar-goals", "bootstrap")[0]
    assert (bayes.config.total_steps, ce.config.total_steps, len(bayes.runs)) == (100_000, 100_000, 1)


def test_report_quotes_the_sweep_log(tmp_path):
    (tmp_path / "sweeps.jsonl").write_text(
        "".join(
            json.dumps(
                {
                    "suite": suite,
                    "seeds": 10,
                    "runs": runs,
                    "workers": 2,
                    "backend": "local",
                    "seconds": seconds,
                    "ended": "2026-11-26 08:00:00",
                }
            )
            + "\n"
            for suite, runs, seconds in (("paper", 80, 600.0), ("baselines", 9, 300.0))
        )
    )
    text = results.report(tmp_path, tmp_path / "RESULTS.md", tmp_path / "figures")
    assert "| paper | 10 | 80 | 2 × local | 10.0 min | 2026-11-26 08:00:00 |" in text
    assert "| baselines | 10 | 9 | 2 × local | 5.0 min |" in text and "Sum: 15.0 min" in text


def test_regenerating_the_report_keeps_the_hand_written_notes(tmp_path):
    out = tmp_path / "RESULTS.md"
    notes = f"{results.NOTES[0]}\n## Summary\nC4 does not hold: see below.\n{results.NOTES[1]}"
    out.write_text(f"# old report\n\n{notes}\n\n| stale | table |\n")
    text = results.report(tmp_path, out, tmp_path / "figures")
    assert text.count(notes) == 1 and "stale" not in text
    assert text.index(notes) < text.index("## Claims")
    assert results.report(tmp_path, out, tmp_path / "figures") == text  # stable on a second pass


def test_trailing_mean_by_hand():
    from dqfd_bc_keras.experiments.figures import trailing_mean

    np.testing.assert_allclose(trailing_mean(np.array([2.0, 4.0, 0.0, 8.0]), 2), [2.0, 3.0, 2.0, 4.0])
    np.testing.assert_allclose(trailing_mean(np.array([1.0, 2.0]), 1), [1.0, 2.0])


def _arm_of(tmp_path, name: str, values: list[list[int]], **fields) -> ArmRuns:
    """cartpole/bootstrap runs whose plain returns per episode are `values` (one list per seed)."""
    runs = [
        make_run(tmp_path / name / str(seed), cartpole_rows(lengths), seed=seed, task="cartpole", **fields)
        for seed, lengths in enumerate(values)
    ]
    return ArmRuns(runs[0].config, runs, name)


def test_ablations_pair_with_the_full_arm_and_are_judged_against_the_margin(tmp_path):
    """Mean training returns by hand: full 400 every seed; the prior-off arm 400 ± 2 (within ±25:
    no measurable contribution), dynamic demos off 300 (contributes: 100 beyond +25), MC dropout
    off 480 (hurts)."""
    full = _arm_of(tmp_path, "full", [[400] * 5] * 4)
    prior = _arm_of(tmp_path, "prior", [[398] * 5, [402] * 5] * 2, bayes_prior=False)
    dynamic = _arm_of(tmp_path, "dyn", [[300] * 5] * 4, dynamic_demos="off")
    dropout = _arm_of(tmp_path, "mc", [[480] * 5] * 4, mc_dropout=False)
    rollouts = _arm_of(tmp_path, "roll", [[420] * 5] * 4, dynamic_demos="rollouts")  # not the preset's mode
    pairs = ablations.ablation_pairs([full, prior, dynamic, dropout, rollouts])
    assert sorted((key, a.name, f.name) for key, a, f in pairs) == [
        ("bayes_prior", "prior", "full"),
        ("dynamic_demos", "dyn", "full"),
        ("mc_dropout", "mc", "full"),
    ]
    verdicts = {a.name: ablations.judge_ablation(a, f).verdict for _, a, f in pairs}
    assert verdicts == {"prior": "no measurable contribution", "dyn": "contributes", "mc": "hurts"}
    line = "- Ablations (one part of the Bayesian machinery off, against the full arm): contributes in 1, hurts in 1, "
    assert line + "no measurable contribution in 1, of 3." in summary([full, prior, dynamic, dropout], tmp_path)


USERS_TASK = """
from dqfd_bc_keras.experiments.lab_settings import LabSettings, register_lab_settings
from dqfd_bc_keras.tasks import TaskSpec, register_task

register_task(TaskSpec("lab-pole", "CartPole-v1", max_steps=60))
register_lab_settings("lab-pole", LabSettings(target_ratio=3.0, ablation_metric="mean_train_return"))
"""


@pytest.fixture
def users_task(tmp_path, monkeypatch):
    """A user's preset with lab settings, registered by their module; forgotten afterwards."""
    (tmp_path / "my_lab_tasks.py").write_text(USERS_TASK)
    monkeypatch.syspath_prepend(str(tmp_path))
    yield "my_lab_tasks:lab-pole"
    TASKS.pop("lab-pole", None)
    LAB_SETTINGS.pop("lab-pole", None)
    sys.modules.pop("my_lab_tasks", None)


def test_a_task_has_the_lab_settings_registered_under_its_name_else_none(users_task, tmp_path):
    """`module:preset` imports the module, which registers them; a preset without any (cartpole-200)
    has NO_SETTINGS, so its ablations are not judged."""
    assert lab_settings(users_task) == LabSettings(target_ratio=3.0, ablation_metric="mean_train_return")
    assert ArmSteps(users_task, "bayes", [None], [0.0], 55.0).target == 3.0
    assert lab_settings("cartpole-200") is NO_SETTINGS and lab_settings("Acrobot-v1") is NO_SETTINGS
    full, prior = (
        ArmRuns(run.config, [run], name)
        for name, run in (
            ("full", make_run(tmp_path / "full", cartpole_rows([100] * 5), task="cartpole-200")),
            ("prior", make_run(tmp_path / "prior", cartpole_rows([100] * 5), task="cartpole-200", bayes_prior=False)),
        )
    )
    assert ablations.ablation_pairs([full, prior]) == []
    with pytest.raises(ConfigError, match="register_lab_settings\\(\\) takes LabSettings, got dict"):
        register_lab_settings("lab-pole", {"target_ratio": 3.0})


def test_the_summary_counts_how_sensitivity_arms_move_the_verdict(tmp_path):
    """C3 at cartpole/bootstrap, 10 seeds: the reference pair equal and narrow (holds); σ0² = 0.05 two
    margins above ce (does not hold: a flip), σ0² = 2 as ce on average but spread by a margin per seed (inconclusive),
    σ0² = 0.1 equal to ce (holds: the same verdict)."""
    c3 = {"task": "cartpole", "timeout": "bootstrap"}
    ce = 100.0 + 0.005 * 25.0 * SPREAD
    arms = [
        return_arm(tmp_path / "c", "ce", ce, **c3),
        return_arm(tmp_path / "b", "bayes", ce, **c3),
        return_arm(tmp_path / "s1", "bayes", ce + 50.0, sigma0_sq=0.05, **c3),
        return_arm(tmp_path / "s2", "bayes", ce + 25.0 * (SPREAD - SPREAD.mean()), sigma0_sq=2.0, **c3),
        return_arm(tmp_path / "s3", "bayes", ce, sigma0_sq=0.1, **c3),
    ]
    assert [analysis.flips(v, "holds") for v in ("does not hold", "inconclusive", "holds")] == ["yes", "unclear", "no"]
    line = (
        "- Sensitivity (each further bayes arm of a claim's setting against its ce arm): the verdict flips between "
        "holds and does not hold in 1 of 3, moves to or from inconclusive in 1, stays in 1."
    )
    assert line in summary(arms, tmp_path)


def test_dynamic_default_follows_three_of_four_pairs_and_episodes_at_a_tie(tmp_path):
    """Evaluations every 5k interactions: a seed reaching 500 at the second evaluation solves at 5,000,
    one never reaching it at ∞."""

    def arm(name, mode, loss, evals):
        runs = [
            make_run(
                tmp_path / name / str(seed),
                cartpole_rows([500] * 3),
                e,
                seed=seed,
                task="cartpole",
                expert_loss=loss,
                dynamic_demos=mode,
                max_steps=400 + i,
            )
            for seed, e in enumerate(evals)
            for i in [int(name[-1])]
        ]
        return ArmRuns(runs[0].config, runs, name)

    fast, slow = [[0.0, 500.0]] * 3, [[0.0, 0.0, 500.0]] * 3
    arms = [
        arm("e1", "episodes", "bayes", slow),
        arm("r1", "rollouts", "bayes", fast),
        arm("e2", "episodes", "ce", slow),
        arm("r2", "rollouts", "ce", fast),
        arm("e3", "episodes", "bayes", fast),
        arm("r3", "rollouts", "bayes", slow),
    ]
    assert ablations.dynamic_default(arms)[0] is None  # 3 of the 4 pairs have run
    four = arms + [arm("e4", "episodes", "ce", slow), arm("r4", "rollouts", "ce", fast)]
    choice, pairs = ablations.dynamic_default(four)
    assert choice == "rollouts" and [w for *_, w in pairs].count("rollouts") == 3
    tie = arms + [arm("e4", "episodes", "ce", fast), arm("r4", "rollouts", "ce", slow)]
    assert ablations.dynamic_default(tie)[0] == "episodes"  # 2–2
    # Seeds one mode ran elsewhere (C3's 26 seeds of the episodes arm) do not enter the comparison:
    # seeds 0–2 tie (fast, fast); seeds 3–6 of the episodes arm alone (slow) would make rollouts win.
    e5, r5 = arm("e5", "episodes", "bayes", fast + slow + slow + slow + slow), arm("r5", "rollouts", "bayes", fast)
    [(first, second, winner)] = ablations.dynamic_default([e5, r5])[1]
    assert winner == "tie" and len(first.runs) == len(second.runs) == 3


def test_fields_a_loss_does_not_read_do_not_name_its_arm(tmp_path):
    """dynamic_demos varies between the bayes arms of the setting, but margin has no BC model."""
    runs = [
        make_run(tmp_path / name, cartpole_rows([500] * 3), task="cartpole", expert_loss=loss, dynamic_demos=mode)
        for name, loss, mode in (("a", "bayes", "episodes"), ("b", "bayes", "rollouts"), ("c", "margin", "episodes"))
    ]
    names = sorted(a.name for a in grouping.group_arms(runs))
    assert names == ["bayes dynamic_demos=episodes", "bayes dynamic_demos=rollouts", "margin"]


def test_a_replication_compares_the_metrics_its_claim_is_judged_by(tmp_path):
    from dqfd_bc_keras.experiments.replicate import METRICS, claim_metrics, compare

    goals = [goals_arm(tmp_path / "g" / loss, loss, 1.0 + 0.1 * SPREAD) for loss in ("bayes", "ce")]
    paper = [c2_arm(tmp_path / "p", loss, [UNFINISHED] * 2, **PAPER_FIELDS) for loss in ("bayes", "ce")]
    today = [c2_arm(tmp_path / "t", loss, [SOLVER] * 2) for loss in ("bayes", "ce")]
    alone = return_arm(tmp_path / "a", "bayes", [1.0, 2.0], task="acrobot", timeout="bootstrap")
    arms = [*goals, *paper, *today, alone]
    assert list(claim_metrics(arms, goals[0])) == list(claim_metrics(arms, goals[1])) == ["goals_first30", "goals_all"]
    assert list(claim_metrics(arms, paper[1])) == ["collapsed", "collapses"]  # C2, the paper's reading
    # C1 and C2 (today's reading) read the same pair
    assert list(claim_metrics(arms, today[0])) == ["episodes_to_solve", "unfinished", "collapses"]
    assert claim_metrics(arms, alone) == {}  # in no claim's setting: METRICS only
    rows = compare(paper[0], paper[1].runs, arms)
    assert [c.metric for c in rows] == [*METRICS, "collapsed", "collapses"]
    assert rows[-1].archived == rows[-1].fresh == [2.0, 2.0] and rows[-1].p == 1.0
