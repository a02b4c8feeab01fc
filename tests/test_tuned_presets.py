"""W's tuning of the presets (PREREGISTRATION §16): its rule by hand, its checks reusing the studies' runs
of the defaults (the same arm names), and the command as a user runs it on the quick budget."""

import shutil
import tarfile
from types import SimpleNamespace

import pytest
from helpers import python as run

from dqfd_bc_keras.errors import ConfigError
from studies import minatar_study, past_teacher_vector, tuned_presets
from studies.minatar_study import unpack_missing
from studies.tuned_presets import DATA, METHODS, PLANS, judge, main, scored


def fake(task: str, reached: int, final: float, seed: int, every: int = 1_000, budget: int = 100_000):
    """A finished run whose evaluations reach `task`'s threshold at `reached` interactions and end at `final`."""
    evals = [
        {"interactions": step, "mean_return": -100.0 if step >= reached else -500.0}
        for step in range(0, budget + 1, every)
    ]
    config = SimpleNamespace(task=task, seed=seed, total_steps=budget, eval_every=every)
    return SimpleNamespace(evals=evals, final=SimpleNamespace(mean_return=final), config=config)


def test_a_preset_takes_tuned_params_only_if_better_beyond_the_margin_and_not_worse_at_the_end():
    acrobot = PLANS[0]
    assert acrobot.task == "acrobot" and acrobot.metric == "threshold"
    defaults = [fake("acrobot", 5_000 + 1_000 * (s % 3), -90.0, s) for s in range(10)]
    sooner = [fake("acrobot", 1_000 + 1_000 * (s % 2), -90.0, s) for s in range(10)]
    said = judge(acrobot, sooner, defaults)  # every tuned run first: p = 2/C(20, 10) · … < 0.05; 4,500 sooner
    assert said.startswith("threshold: **better**") and "+4,500 in the tuned params' favour" in said
    assert said.endswith("**the preset takes the tuned params**")
    # Sooner, but every final return 60 lower: the span is 387.28, its 0.15 is 58.09, so worse at the end.
    worse_end = [fake("acrobot", 1_000 + 1_000 * (s % 2), -150.0, s) for s in range(10)]
    said = judge(acrobot, worse_end, defaults)
    assert "final return: **worse**" in said and said.endswith("the preset keeps its defaults")
    # Half the seeds one evaluation sooner: medians 4,500 and 5,000, p = 0.014 (Mann–Whitney, ties), but 500
    # is inside the margin of one evaluation period (1,000): not better, however significant.
    at_5000 = [fake("acrobot", 5_000, -90.0, s) for s in range(10)]
    near = [fake("acrobot", 4_000 + 1_000 * (s % 2), -90.0, s) for s in range(10)]
    said = judge(acrobot, near, at_5000)
    assert said.startswith("threshold: a significant difference inside the margin (1000): not a better or worse")
    assert "(p = 0.0137, +500 in the tuned params' favour, margin 1,000)" in said
    assert said.endswith("the preset keeps its defaults")


def test_a_threshold_study_past_its_budget_says_so():
    acrobot, minigrid = PLANS[0], PLANS[2]
    assert (acrobot.tuning_steps, minigrid.metric) == (20_000, "auc")
    assert scored(acrobot, 21_000.0) == "21,000, past the 20,000 budget"  # every seed "never": the point after
    assert scored(acrobot, 1_500.0) == "1,500" and scored(acrobot, 20_000.0) == "20,000"  # reached at the end
    assert scored(minigrid, 0.8125) == "0.8125"  # an area is never past a budget


@pytest.mark.parametrize("plan", PLANS, ids=[p.task for p in PLANS])
def test_the_check_reads_the_studies_runs_of_the_defaults_by_their_arm_names(plan):
    for method in METHODS:
        if plan.task in past_teacher_vector.TASKS:
            theirs = past_teacher_vector.ours(plan.task, method)
        else:
            [theirs] = [a for a in minatar_study.arms(False, (method,)) if a.task == plan.task]
        ours = plan.defaults_arm(method)
        assert (ours.name, ours.overrides) == (theirs.name, theirs.overrides)
        assert plan.tuned_arm(method, {"n_step": 3}).overrides == (*theirs.overrides, ("n_step", 3))


@pytest.mark.slow
def test_the_quick_pipeline_tunes_scores_the_defaults_checks_exports_and_reports_again_from_its_archive(
    tmp_path, monkeypatch
):
    out, archive = tmp_path / "out", tmp_path / "presets.tar.xz"
    done = run(
        "-m", "studies.tuned_presets", "--out", out, "--quick", "--workers", 1, "--report", tmp_path / "a.md",
        "--archive", archive,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert (out / "tuning" / "acrobot-bayes" / "best.json").is_file()
    assert [p.name for p in (out / "tuning" / "acrobot-bayes-defaults").iterdir() if p.is_dir()]  # its runs
    checked = sorted(p.name for p in (out / "checks").iterdir() if p.is_dir())
    assert len(checked) == 2 and checked[1] == "acrobot-bootstrap-bayes-tuned"
    assert all((out / "checks" / arm / f"seed{s}" / "eval.json").is_file() for arm in checked for s in (0, 1))
    text = (tmp_path / "a.md").read_text()
    [row] = [line for line in text.splitlines() if line.startswith("| acrobot | bayes |")]
    assert "| threshold at 600 |" in row and ("keeps its defaults" in row or "takes the tuned params" in row)
    again = run("-m", "studies.tuned_presets", "--out", out, "--quick", "--no-run", "--report", tmp_path / "b.md")
    assert again.returncode == 0 and (tmp_path / "b.md").read_text() == text, again.stderr
    with tarfile.open(archive) as tar:
        names = tar.getnames()
    assert {"tuning/acrobot-bayes/study.db", "tuning/acrobot-bayes/best.json"} <= set(names)
    assert any(n.startswith("tuning/acrobot-bayes/trials/") and n.endswith("/eval.json") for n in names)
    assert any(n.startswith("tuning/acrobot-bayes-defaults/") and n.endswith("/eval.json") for n in names)
    assert {n.split("/")[1] for n in names if n.startswith("checks/")} == {"acrobot-bootstrap-bayes-tuned"}
    # the reused defaults' runs stay in their own archives; a study on another machine starts from this one
    elsewhere = tmp_path / "elsewhere"
    unpack_missing(archive, elsewhere)
    shutil.copytree(out / "checks" / checked[0], elsewhere / "checks" / checked[0])
    read = run(
        "-m", "studies.tuned_presets", "--out", elsewhere, "--quick", "--no-run", "--report", tmp_path / "c.md"
    )  # fmt: skip
    assert read.returncode == 0 and (tmp_path / "c.md").read_text() == text.replace(str(out), str(elsewhere))
    exports = []
    monkeypatch.setattr(tuned_presets, "export", lambda *args: exports.append(args))
    resumed = run("-m", "studies.tuned_presets", "--out", elsewhere, "--quick", "--workers", 1, "--archive", archive)
    assert resumed.returncode == 0, resumed.stderr
    assert len(exports) == 1  # the study, its defaults and its check all done: the archive is written once
    trials = [sorted(p.name for p in (o / "tuning" / "acrobot-bayes" / "trials").iterdir()) for o in (out, elsewhere)]
    assert trials[0] == trials[1] and "0 to run" in resumed.stdout  # nothing the archive held is run again


def test_an_archive_that_is_not_one_is_refused_before_anything_runs(tmp_path):
    with pytest.raises(ConfigError, match=r"--archive .*presets\.zip: expected a \.tar\.xz file"):
        main(["--out", str(tmp_path / "out"), "--archive", str(tmp_path / "presets.zip")])
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_the_committed_report_is_what_the_committed_archive_gives(tmp_path):
    """docs/TUNING_PRESETS.md from docs/data/tuned-presets.tar.xz alone (the checks' defaults from their studies')."""
    committed = DATA / "tuned-presets.tar.xz"
    done = run(
        "-m", "studies.tuned_presets", "--out", tmp_path / "out", "--no-run", "--archive",
        committed.relative_to(DATA.parents[1]), "--report", tmp_path / "r.md",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "r.md").read_text() == (DATA.parent / "TUNING_PRESETS.md").read_text()
