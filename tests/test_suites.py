"""The experiment runner: suites as declared, the quick suite end to end on both backends, and a run
it finds broken, or in another config than its arm's, reported and restarted only when asked."""

import csv
import dataclasses
import json
import os
import shutil

import pytest

from dqfd_bc_keras.core.config import QUICK
from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.experiments.__main__ import main
from dqfd_bc_keras.experiments.claims import PAPER
from dqfd_bc_keras.experiments.plans import planned_seeds
from dqfd_bc_keras.experiments.suites import ALL, SUITES, Arm, suite_arms
from dqfd_bc_keras.experiments.sweep import Job, SweepOptions, run_suite, sweep_jobs
from dqfd_bc_keras.runs import directory as runs


def test_paper_suite_pits_ce_against_bayes_with_the_planned_seeds_and_both_readings_of_c2():
    arms = SUITES["paper"]
    names = [arm.name for arm in arms]
    assert names[:8] == [
        f"{setting}-{loss}"
        for setting in ("cartpole-naive", "cartpole-200-naive", "cartpole-bootstrap", "mountaincar-goals-bootstrap")
        for loss in ("ce", "bayes")
    ]
    assert (
        [arm.seeds for arm in arms[:8:2]]
        == [
            planned_seeds(claim, setting)
            for claim, setting in (
                ("C1", "cartpole/naive"),
                ("C1", "cartpole-200/naive"),
                ("C3", "cartpole/bootstrap"),
                ("C4", "mountaincar-goals/*"),
            )
        ]
        == [36, 24, 26, 10]
    )
    paper_reading = [arm.config(0) for arm in arms[8:]]
    assert [
        (c.task, c.timeout, c.expert_loss, c.early_stop_window, c.total_steps // c.limit) for c in paper_reading
    ] == [("cartpole-200", "naive", loss, 0, 300) for loss in ("ce", "bayes")]
    # §11: 7 of 10 collapsed in each arm, p = 0.7: ⌈2 (1.645 + 1.282)² · 0.21 / 0.2²⌉ = 90 seeds per arm
    assert [arm.seeds for arm in arms[8:]] == [90, 90] == [planned_seeds("C2", PAPER)] * 2
    baselines = {arm.expert_loss for arm in SUITES["baselines"]}
    assert baselines == {"none", "margin", "bc_margin"}
    config = arms[2].config(seed=7)
    assert (config.task, config.timeout, config.expert_loss, config.seed, config.max_steps) == (
        "cartpole-200",
        "naive",
        "ce",
        7,
        None,
    )


def test_dynamic_efficiency_and_ablation_suites_share_the_protocol_and_their_arms():
    for suite in ("dynamic", "efficiency"):
        for a in SUITES[suite]:
            c = a.config(0)
            assert (c.eval_every, c.eval_episodes, c.timeout) == (1000, 10, "bootstrap")
    modes = {(a.task, a.expert_loss, a.config(0).dynamic_demos) for a in SUITES["dynamic"]}
    assert len(modes) == 8 == len(SUITES["dynamic"])
    default = {a.name for a in SUITES["dynamic"] if a.config(0).dynamic_demos == "episodes"}
    assert default <= {a.name for a in SUITES["efficiency"]}  # the preset's mode is the efficiency arm
    ablations = {
        (a.task, a.expert_loss, c.dynamic_demos, c.bayes_prior, c.mc_dropout)
        for a in SUITES["ablations"]
        for c in [a.config(0)]
    }
    for task in ("cartpole", "mountaincar-goals"):
        assert {
            (task, "bayes", "off", True, True),
            (task, "ce", "off", True, True),
            (task, "bayes", "episodes", False, True),
            (task, "bayes", "episodes", True, False),
        } <= ablations


def test_sensitivity_suite_sweeps_sigma0_and_the_demonstrator():
    configs = [a.config(0) for a in SUITES["sensitivity"]]
    cells = {(c.task, c.expert_loss, c.sigma0_sq if c.expert_loss == "bayes" else None, c.expert) for c in configs}
    for task in ("cartpole", "mountaincar-goals"):
        for expert in ("imperfect", "strong"):
            assert {(task, "bayes", s, expert) for s in (0.05, 0.5, 2.0)} <= cells
            assert (task, "ce", None, expert) in cells
    assert len(cells) == len(configs) == 16
    assert all(a.seeds >= 5 for a in SUITES["sensitivity"]) and set(ALL) <= set(SUITES)


def test_arms_equal_in_config_share_a_name_across_suites():
    """The sensitivity suite's preset cells are the paper's arms: with one --out they share runs."""
    names = {a.name for a in SUITES["sensitivity"]}
    assert {
        "cartpole-bootstrap-bayes",
        "cartpole-bootstrap-ce",
        "mountaincar-goals-bootstrap-bayes",
        "mountaincar-goals-bootstrap-ce",
    } <= names & {a.name for a in SUITES["paper"]}
    assert {
        "cartpole-bootstrap-bayes-sigma0.05",
        "cartpole-bootstrap-bayes-strong-sigma2",
        "mountaincar-goals-bootstrap-ce-strong",
    } <= names


def test_a_sweep_runs_seed_major_so_a_cut_off_leaves_arms_balanced(tmp_path):
    a, b = Arm("cartpole", "bootstrap", "ce", seeds=3), Arm("cartpole", "bootstrap", "bayes", seeds=1)
    order = [(job.arm.expert_loss, job.seed) for job in sweep_jobs([a, b], None, tmp_path)]
    assert order == [("ce", 0), ("bayes", 0), ("ce", 1), ("ce", 2)]
    assert [(job.arm.expert_loss, job.seed) for job in sweep_jobs([a, b], 2, tmp_path)] == [
        ("ce", 0),
        ("bayes", 0),
        ("ce", 1),
        ("bayes", 1),
    ]


@pytest.mark.slow
def test_a_sweep_cut_off_is_logged_as_interrupted(tmp_path, monkeypatch):
    from dqfd_bc_keras.experiments import sweep

    def cut_after_one(jobs, workers, runs_per_worker):
        yield sweep.Outcome(jobs[0], 3, 300, 10.0, 1.0)
        raise KeyboardInterrupt

    monkeypatch.setattr(sweep, "_local", cut_after_one)
    with pytest.raises(KeyboardInterrupt):
        run_suite("quick", 2, tmp_path, SweepOptions(progress=lambda line: None))
    [logged] = [json.loads(line) for line in (tmp_path / "sweeps.jsonl").read_text().splitlines()]
    assert (logged["suite"], logged["runs"], logged["interrupted"]) == ("quick", 1, True)


@pytest.mark.slow
def test_a_sweep_in_an_unpacked_archive_runs_only_what_it_lacks(tmp_path):
    """An exported run has eval.json and no checkpoints/: complete, never retrained or replaced. One
    with checkpoints/ started here and was cut off in its final phase: it is resumed."""
    from dqfd_bc_keras.experiments.sweep import run_jobs

    bayes, ce = SUITES["quick"]
    archived = Job(bayes, 0, tmp_path)
    archived.directory.mkdir(parents=True)
    (archived.directory / "eval.json").write_text("{}")
    cut_off = Job(ce, 0, tmp_path)
    (cut_off.directory / "checkpoints").mkdir(parents=True)
    (cut_off.directory / "eval.json").write_text("{}")
    assert archived.complete and not cut_off.complete
    lines = []
    assert run_jobs([archived], tmp_path, "unpacked", 1, SweepOptions(1, progress=lines.append)) == []
    assert lines == ["unpacked: 1 runs, 1 already complete, 0 to run on 1 local worker(s)"]
    assert [p.name for p in archived.directory.iterdir()] == ["eval.json"]


def test_unknown_suite_or_backend_is_refused(tmp_path):
    with pytest.raises(ConfigError, match="unknown suite 'everything'"):
        suite_arms("everything")
    with pytest.raises(ConfigError, match="unknown backend 'slurm'"):
        run_suite("quick", 1, tmp_path, SweepOptions(backend="slurm"))


@pytest.mark.slow
def test_a_reused_worker_gives_each_seed_the_results_of_a_fresh_process(tmp_path):
    """Two runs in one worker process, another method's first, then bayes seed 0, against bayes seed 0
    alone in a fresh process: the same episodes, losses and evaluations, to the bit."""
    from dqfd_bc_keras.experiments.sweep import run_jobs

    bayes, ce = SUITES["quick"]
    jobs = [Job(ce, 0, tmp_path / "reused"), Job(bayes, 0, tmp_path / "reused")]
    reused = run_jobs(
        jobs, tmp_path / "reused", "reused", 1, SweepOptions(1, runs_per_worker=2, progress=lambda _: None)
    )
    fresh = run_jobs(
        [Job(bayes, 0, tmp_path / "fresh")],
        tmp_path / "fresh",
        "fresh",
        1,
        SweepOptions(1, runs_per_worker=1, progress=lambda _: None),
    )
    assert len({o.pid for o in reused}) == 1 and fresh[0].pid not in {o.pid for o in reused}
    assert not any(o.error for o in reused + fresh)

    def results(root):
        run = root / bayes.name / "seed0"
        metrics = [
            {k: v for k, v in row.items() if k != "wall_time"} for row in csv.DictReader((run / "metrics.csv").open())
        ]
        return metrics, (run / "evals.csv").read_text(), json.loads((run / "eval.json").read_text())["returns"]

    metrics, evals, returns = results(tmp_path / "reused")
    assert len(metrics) > 1 and (metrics, evals, returns) == results(tmp_path / "fresh")


@pytest.mark.slow
def test_a_worker_that_dies_mid_run_is_reported_and_the_next_run_gets_a_fresh_one(tmp_path):
    from dqfd_bc_keras.experiments.sweep import run_jobs

    _, ce = SUITES["quick"]
    dying = dataclasses.replace(ce, overrides=(*ce.overrides, ("expert", "toy_envs:dies")), label="quick-dies")
    lines = []
    with pytest.raises(
        ConfigError,
        match=r"1 of 2 runs failed; first: .*quick-dies/seed0: its process died "
        r"\(exit code 3\)",
    ):
        run_jobs(
            [Job(dying, 0, tmp_path), Job(ce, 0, tmp_path)], tmp_path, "dies", 1, SweepOptions(1, progress=lines.append)
        )
    assert (tmp_path / ce.name / "seed0" / "complete.json").is_file()
    assert "its process died (exit code 3)" in lines[1] and "episodes" in lines[2]


@pytest.mark.slow
@pytest.mark.parametrize("backend", ["local", "ray"])
def test_quick_suite_runs_and_a_second_call_skips_finished_runs(backend, tmp_path):
    lines = []
    outcomes = run_suite("quick", 1, tmp_path, SweepOptions(2, backend, progress=lines.append))
    assert len(outcomes) == 2 and not any(o.error for o in outcomes)
    assert lines[0] == f"quick: 2 runs, 0 already complete, 2 to run on 2 {backend} worker(s)"
    for loss in ("bayes", "ce"):
        run_dir = tmp_path / f"cartpole-bootstrap-{loss}-quick" / "seed0"
        result = json.loads((run_dir / "eval.json").read_text())
        assert result["task"] == "cartpole" and len(result["returns"]) == QUICK["final_eval_episodes"]
        assert json.loads((run_dir / "config.json").read_text())["total_steps"] == QUICK["total_steps"]
    assert sum(line.startswith("[") for line in lines) == 2
    again = []
    assert run_suite("quick", 1, tmp_path, SweepOptions(backend=backend, progress=again.append)) == []
    assert again == [f"quick: 2 runs, 2 already complete, 0 to run on 2 {backend} worker(s)"]
    [logged] = [json.loads(line) for line in (tmp_path / "sweeps.jsonl").read_text().splitlines()]
    assert (logged["suite"], logged["runs"], logged["workers"], logged["backend"]) == ("quick", 2, 2, backend)
    assert logged["seconds"] > 0  # the second call ran nothing and logged nothing
    assert set(logged) >= {"code_commit", "rules_commit", "dirty", "versions"}
    assert (
        json.loads((tmp_path / "cartpole-bootstrap-bayes-quick" / "seed0" / "provenance.json").read_text())[
            "code_commit"
        ]
        == logged["code_commit"]
    )


@pytest.mark.slow
def test_a_local_ray_runs_its_workers_at_the_callers_priority():
    """As the local pool's do; at Ray's default (nice 15) a sweep beside any other work all but stops."""
    pytest.importorskip("ray")
    from dqfd_bc_keras.experiments.sweep import ray_session

    with ray_session(1, None) as ray:
        niceness = ray.get(ray.remote(lambda: os.nice(0)).remote())
    assert niceness == os.nice(0)


def test_cli_rejects_bad_arguments_in_one_line(capsys):
    from dqfd_bc_keras.commands.cli import run

    with pytest.raises(SystemExit) as exit_:
        run(main, ["run", "nope", "--out", "x"])
    assert exit_.value.code == 2
    assert "invalid choice: 'nope'" in capsys.readouterr().err
    assert run(main, ["report", "/no/such/dir"]) == 2
    assert "/no/such/dir: no such suite directory" in capsys.readouterr().err


@pytest.mark.slow
def test_report_on_the_quick_suite_writes_results_and_figures(tmp_path):
    from dqfd_bc_keras.experiments.report import report

    run_suite("quick", 2, tmp_path / "suite", SweepOptions(2, progress=lambda line: None))
    assert (
        main(
            [
                "report",
                str(tmp_path / "suite"),
                "--results",
                str(tmp_path / "RESULTS.md"),
                "--figures",
                str(tmp_path / "figures"),
            ]
        )
        == 0
    )
    text = (tmp_path / "RESULTS.md").read_text()
    assert "python -m dqfd_bc_keras.experiments report" in text
    assert "C1" in text and "C4" in text and "not run" in text  # the quick suite covers no paper setting
    assert sorted(p.suffix for p in (tmp_path / "figures").iterdir()) and all(
        p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for p in (tmp_path / "figures").iterdir()
    )
    assert len((tmp_path / "per_seed.csv").read_text().splitlines()) == 1 + 2 * 2  # a row per run
    # Real run directories (models, checkpoints, TensorBoard) exported: the archive holds all the report reads.
    assert main(["export", str(tmp_path / "suite"), "--out", str(tmp_path / "suite.tar.xz")]) == 0
    again = report(tmp_path / "suite.tar.xz", tmp_path / "again.md", tmp_path / "figures")
    assert again == (tmp_path / "again.md").read_text() and again.replace("suite.tar.xz", "suite") == text


@pytest.mark.slow
def test_the_runner_reports_a_broken_run_and_restarts_it_when_asked(finished, tmp_path):
    arm = Arm("cartpole", "bootstrap", "bayes", tuple(QUICK.items()), "quick", 1)
    run = tmp_path / "suite" / arm.name / "seed0"
    shutil.copytree(finished, run)
    (run / "eval.json").unlink()  # cut off before it finished …
    (run / runs.COMPLETE).unlink()
    (run / "checkpoints" / "latest.json").write_text("")  # … and its checkpoint is damaged
    lines = []
    with pytest.raises(ConfigError, match="1 of 1 runs failed"):
        run_suite([arm], None, tmp_path / "suite", SweepOptions(1, progress=lines.append))
    assert "failed: BrokenRunError" in lines[-1] and "--restart-broken" in lines[-1]
    [outcome] = run_suite([arm], None, tmp_path / "suite", SweepOptions(1, progress=lines.append), restart_broken=True)
    assert not outcome.error and (run / "eval.json").is_file()


@pytest.mark.slow
def test_the_runner_resumes_a_run_only_if_its_config_is_the_arms(finished, tmp_path):
    arm = Arm("cartpole", "bootstrap", "bayes", tuple({**QUICK, "learning_rate": 0.002}.items()), "quick", 1)
    run = tmp_path / "suite" / arm.name / "seed0"
    shutil.copytree(finished, run)  # trained with learning_rate 0.001, and cut off before its end
    (run / runs.COMPLETE).unlink()
    lines = []
    with pytest.raises(ConfigError, match="1 of 1 runs failed"):
        run_suite([arm], None, tmp_path / "suite", SweepOptions(1, progress=lines.append))
    assert "not the arm's config (learning_rate: 0.001 (was 0.002))" in lines[-1] and "--restart-broken" in lines[-1]
    [outcome] = run_suite([arm], None, tmp_path / "suite", SweepOptions(1, progress=lines.append), restart_broken=True)
    assert not outcome.error and json.loads((run / "config.json").read_text())["learning_rate"] == 0.002
