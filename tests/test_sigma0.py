"""The σ0² study (PREREGISTRATION §10): its arms, Holm's adjustment by hand, and its verdicts and
weights on synthetic runs whose every number is known."""

import numpy as np
import pytest
from scipy import stats as sps
from test_claims import cartpole_rows, make_run

from dqfd_bc_keras.experiments.arms import group_arms
from dqfd_bc_keras.experiments.stats import holm
from dqfd_bc_keras.experiments.suites import ALL, SUITES, claim_seeds
from studies import sigma0


def test_holm_by_hand_and_a_family_larger_than_what_ran():
    # sorted 0.01, 0.03, 0.04: × 3, 2, 1 = 0.03, 0.06, 0.04 → monotone: 0.03, 0.06, 0.06
    assert holm([0.01, 0.04, 0.03]) == pytest.approx([0.03, 0.06, 0.06])
    # the same three in a family of 5: × 5, 4, 3 = 0.05, 0.12, 0.12
    assert holm([0.01, 0.04, 0.03], family=5) == pytest.approx([0.05, 0.12, 0.12])
    assert holm([0.5, 0.9], family=2) == [1.0, 1.0]
    with pytest.raises(ValueError, match="family of 1"):
        holm([0.1, 0.2], family=1)


def test_the_suite_runs_each_estimator_and_sigma0_on_every_setting_once():
    arms = [a for a in SUITES["sigma0"] if a.expert_loss == "bayes"]
    assert len({a.name for a in arms}) == len(arms) == 28  # 32 comparisons; the imperfect × 5 cell is C3's arms
    ce = [a for a in SUITES["sigma0"] if a.expert_loss == "ce"]  # rerun with the study, one per setting
    assert len(ce) == 7 and {a.seeds for a in ce} == {26, 5, 10} and "sigma0" not in ALL
    assert sigma0.FAMILY == 32
    c3 = [a for a in arms if dict(a.overrides).keys() <= {"uncertainty", "sigma0_sq"} and a.task == "cartpole"]
    assert len(c3) == 4 and all(a.seeds == claim_seeds("C3", "cartpole") for a in c3)
    assert {a.config(0).sigma0_sq for a in arms} == {0.02, 0.1}
    assert {a.config(0).uncertainty for a in arms} == {"distance", "mc_dropout"}
    # distance before mc_dropout on CartPole, MountainCar last (the pre-registered order)
    order = [(a.task, a.config(0).uncertainty) for a in arms]
    assert order.index(("cartpole", "mc_dropout")) > max(
        i for i, o in enumerate(order) if o == ("cartpole", "distance")
    )
    assert all(task == "mountaincar" for task, _ in order[-4:])


def c3_runs(tmp_path, loss, lengths_by_seed, weights=None, **fields):
    runs = []
    for seed, lengths in enumerate(lengths_by_seed):
        rows = cartpole_rows(lengths)
        if weights:
            rows = [{**r, "imitation_weight_demo": weights[0], "imitation_weight_agent": weights[1]} for r in rows]
        runs.append(
            make_run(
                tmp_path / f"{loss}{fields}{seed}",
                rows,
                task="cartpole",
                timeout="bootstrap",
                expert_loss=loss,
                seed=seed,
                **fields,
            )
        )
    return runs


def test_a_clear_win_survives_holm_over_the_family_and_a_tie_does_not(tmp_path):
    """10 seeds a side on C3's setting: bayes (distance, σ0² = 0.02) above every ce seed, U = 100 of
    100 pairs; scipy's normal approximation (n > 8) with continuity correction gives
    p = 2(1 − Φ((100 − 50 − ½)/√(10·10·21/12))) = 1.83e-4, × 32 = 5.8e-3 < 0.05: better. bayes at
    σ0² = 0.1 draws the same returns as ce: p = 1, no measurable difference."""
    ce = c3_runs(tmp_path, "ce", [[100 + s] * 5 for s in range(10)])
    win = c3_runs(
        tmp_path,
        "bayes",
        [[400 + s] * 5 for s in range(10)],
        weights=(25.0, 5.0),
        uncertainty="distance",
        sigma0_sq=0.02,
    )
    tie = c3_runs(
        tmp_path, "bayes", [[100 + s] * 5 for s in range(10)], weights=(5.0, 4.0), uncertainty="distance", sigma0_sq=0.1
    )
    everything = sigma0.results(group_arms(ce + win + tie))
    found = [r for r in everything if r.setting == "C3"]
    assert [(r.sigma0_sq, r.verdict) for r in found] == [(0.02, "better"), (0.1, "no measurable difference")]
    # C3's arms are also the grid's imperfect × 5 cell: seeds 0-4 on interactions to 475 (never: all ∞, p = 1)
    grid = [r for r in everything if r.setting != "C3"]
    assert [(r.setting, len(r.bayes.runs), r.verdict) for r in grid] == [
        ("grid imperfect ε=0 × 5", 5, "no measurable difference")
    ] * 2
    expected = 2 * (1 - sps.norm.cdf(49.5 / np.sqrt(175)))
    assert found[0].p == pytest.approx(expected, rel=1e-6) and found[0].p_holm == pytest.approx(32 * expected)
    assert found[1].p == pytest.approx(1.0) and found[1].p_holm == 1.0
    assert "markedly better" in found[0].margin_rule() and "equivalent" in found[1].margin_rule()
    assert sigma0.weights(found[0].bayes) == (25.0, 5.0)
    text = "\n".join(sigma0.sigma0_section(group_arms(ce + win + tie)))
    assert "25.00 · 5.00 · ×5.00 (acts)" in text and "5.00 · 4.00 · ×1.25 |" in text
    assert "measurably better than ce in any setting? yes**: 1 of 4" in text and "28 of 32 not run" in text
    assert "reaches 1.5 (*acts*) in: distance 2 of 4; mc_dropout 0 of 0 arms." in text


def test_runs_from_before_the_weights_were_logged_show_none_and_nothing_ran_says_so(tmp_path):
    ce = c3_runs(tmp_path, "ce", [[100] * 5] * 3)
    old = c3_runs(tmp_path, "bayes", [[100] * 5] * 3, weights=(None, None), uncertainty="distance", sigma0_sq=0.02)
    result, *_ = sigma0.results(group_arms(ce + old))
    assert sigma0.weights(result.bayes) is None
    assert sigma0.sigma0_section(group_arms(ce))[0].startswith("Not run:")
    assert np.isnan(old[0].column("imitation_weight_demo")).all()


@pytest.mark.slow
def test_the_study_report_command_writes_its_markdown_and_refuses_a_bad_source(tmp_path):
    import subprocess
    import sys
    from pathlib import Path

    from test_claims import write_run

    suite = tmp_path / "suite"
    for run in c3_runs(suite, "ce", [[100 + s] * 5 for s in range(3)]) + c3_runs(
        suite, "bayes", [[300 + s] * 5 for s in range(3)], weights=(25.0, 5.0), uncertainty="distance", sigma0_sq=0.02
    ):
        write_run(run)
    repo = Path(__file__).resolve().parents[1]
    command = [sys.executable, "-m", "studies.sigma0"]
    done = subprocess.run(
        [*command, suite, "--report", tmp_path / "SIGMA0.md"], capture_output=True, text=True, cwd=repo, timeout=300
    )
    assert done.returncode == 0, done.stderr
    text = (tmp_path / "SIGMA0.md").read_text()
    assert text.startswith("# The Bayesian loss where it can act") and "Provenance" in text
    assert "| C3 | distance | 0.02 | 3 | 301.0 · 101.0 |" in text and "25.00 · 5.00 · ×5.00 (acts)" in text
    assert text in done.stdout
    done = subprocess.run([*command, tmp_path / "nothing"], capture_output=True, text=True, cwd=repo, timeout=300)
    assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1, done.stderr
