"""The presets W tunes (docs/PREREGISTRATION.md §16, committed before any of its trials or runs): for each
preset and method, an `experiments tune` study on tuning seeds, the preset's own defaults scored the same
way, and, where the study's best beats them, its params on seeds 0–9 at the studies' budget against the
studies' runs of the defaults (§7, §13, §14, §15: reused, unpacked from their archives, so only what they
lack is run). A method's params become its preset's defaults only by §16's rule (`judge`).

    python -m studies.tuned_presets --out runs/presets [--workers 2]                # in §16's order; resumes
    python -m studies.tuned_presets --out runs/presets --archive docs/data/tuned-presets.tar.xz   # and exports
    python -m studies.tuned_presets --out runs/presets --no-run --report FILE.md    # the verdicts so far
    python -m studies.tuned_presets --out /tmp/presets --quick                      # a minute: the pipeline

Writes only under --out (OUT/tuning/TASK-METHOD/ a study, OUT/tuning/TASK-METHOD-defaults/
the preset's defaults on its tuning seeds, OUT/checks/ the check's runs in the lab's
format) and, with --report, that one file; with --archive, that archive too (rewritten as each study,
its defaults' runs and each check run finish: what another machine, or the next session, resumes from).
"""

from __future__ import annotations

import contextlib
import json
import sqlite3
import sys
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from dqfd_bc_keras.commands.cli import ArgumentParser, positive_int, run
from dqfd_bc_keras.core.config import QUICK
from dqfd_bc_keras.core.params import read_params
from dqfd_bc_keras.envs.make import get_task
from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.experiments.arm_config import Arm, arm, on_shared_defaults
from dqfd_bc_keras.experiments.data import ARCHIVE_SUFFIX, lab_files, load_runs, write_archive
from dqfd_bc_keras.experiments.jobs import Job
from dqfd_bc_keras.experiments.run_files import FinishedRun
from dqfd_bc_keras.experiments.suites import PROTOCOL as VECTOR_PROTOCOL
from dqfd_bc_keras.experiments.sweep import SweepOptions, run_jobs, run_suite
from dqfd_bc_keras.tuning import TuneSettings, tune
from dqfd_bc_keras.tuning.objective import METRICS
from studies import minatar_study, past_teacher_vector
from studies.minatar_study import emit, unpack_missing
from studies.tuned import compare, run_score

DATA = Path(__file__).resolve().parents[1] / "docs" / "data"
METHODS = ("bayes", "ce_decay", "none")
TRIALS, TUNING_SEEDS, CHECK_SEEDS = 30, 2, 10
MARGIN = 0.15
"""Of the teacher − random span (§13's equivalence margin): `auc`'s margin, and the final return's."""


@dataclass(frozen=True)
class Plan:
    """One preset as §16 tunes it: the study's metric and proxy budget, the check's budget and protocol,
    and the archives holding the studies' runs of its defaults."""

    task: str
    metric: str
    tuning_steps: int
    budget: int
    protocol: tuple[tuple[str, object], ...]
    archives: tuple[Path, ...]
    anchors: tuple[float, float]
    """(uniform random policy, imperfect teacher): the margins' span."""

    def defaults_arm(self, method: str, seeds: int = CHECK_SEEDS) -> Arm:
        """The studies' arm of `method` on this preset (its name is theirs, so their runs are reused), on the
        preset's defaults before any tuned set of §16's."""
        return on_shared_defaults(
            arm(self.task, "bootstrap", method, seeds, total_steps=self.budget, **dict(self.protocol))
        )

    def tuned_arm(self, method: str, params: dict, seeds: int = CHECK_SEEDS) -> Arm:
        defaults = self.defaults_arm(method, seeds)
        return replace(defaults, overrides=(*defaults.overrides, *params.items()), label="tuned")


_VECTOR = (("demo_episodes", 10), *VECTOR_PROTOCOL.items())
_FROM_7_15 = (DATA / "results.tar.xz", DATA / "past-teacher-vector.tar.xz")
PLANS = (
    Plan("acrobot", "threshold", 20_000, 100_000, _VECTOR, _FROM_7_15, past_teacher_vector.ANCHORS["acrobot"]),
    Plan("lunarlander", "threshold", 30_000, 100_000, _VECTOR, _FROM_7_15, past_teacher_vector.ANCHORS["lunarlander"]),
    Plan(
        "minigrid-empty", "auc", 25_000, past_teacher_vector.MINIGRID_BUDGET, _VECTOR,
        (DATA / "past-teacher-vector.tar.xz",), past_teacher_vector.ANCHORS["minigrid-empty"],
    ),
    Plan(
        "minatar-breakout", "auc", 25_000, minatar_study.BUDGET, tuple(minatar_study.PROTOCOL.items()),
        (DATA / "minatar.tar.xz", DATA / "past-teacher.tar.xz"), minatar_study.ANCHORS["minatar-breakout"],
    ),
)  # fmt: skip
"""§16's presets, in its order."""


def quick_plan() -> Plan:
    """Acrobot on the quick budget, no archive: every step of the pipeline in seconds (the numbers mean nothing)."""
    protocol = tuple((k, v) for k, v in QUICK.items() if k != "total_steps")
    steps = int(QUICK["total_steps"])  # type: ignore[call-overload]
    return replace(PLANS[0], tuning_steps=steps, budget=steps, protocol=protocol, archives=())


def tuning(plan: Plan, method: str, quick: bool) -> dict:
    """The settings of the study of `method` on `plan` (`TuneSettings`' fields), for `tune` and the defaults alike."""
    seeds, trials = (1, 1) if quick else (TUNING_SEEDS, TRIALS)
    return {"expert_loss": method, "metric": plan.metric, "steps": plan.tuning_steps, "seeds": seeds,
            "trials": trials, "quick": quick}  # fmt: skip


def study(plan: Plan, method: str, out: Path, workers: int, quick: bool) -> Path | None:
    """The study of `method` on `plan`, run or continued: its best.json (None before a complete trial)."""
    where = out / "tuning" / f"{plan.task}-{method}"
    return tune(plan.task, out=where, workers=workers, **tuning(plan, method, quick)).best_file


def own_value(
    plan: Plan, method: str, out: Path, workers: int, quick: bool, run_missing: bool, finished: Callable | None = None
) -> float | None:
    """The preset's defaults scored as the study scores a trial: its runs' settings (`run_fields`) on its
    seeds, the mean of `tuning.objective.score`; run where missing unless not `run_missing`; None while a
    seed is missing."""
    where = out / "tuning" / f"{plan.task}-{method}-defaults"
    settings = TuneSettings(out=where, task=plan.task, **tuning(plan, method, quick))
    a = arm(plan.task, "bootstrap", method, len(settings.seed_list), **settings.run_fields())
    jobs = [Job(a, seed, where) for seed in settings.seed_list]
    if run_missing:
        run_jobs(jobs, where, "defaults", len(jobs), SweepOptions(workers, finished=finished))
    if not all(job.complete for job in jobs):
        return None
    return float(np.mean([run_score(r, plan.metric, settings.threshold) for j in jobs for r in load_runs(j.directory)]))


def better(metric: str, value: float | None, than: float | None) -> bool:
    """`value` beats `than` in the metric's direction (a study without a complete trial beats nothing)."""
    if value is None or than is None:
        return False
    return value < than if METRICS[metric].direction == "minimize" else value > than


def check(
    plan: Plan, method: str, best: Path, out: Path, workers: int, quick: bool, finished: Callable | None = None
) -> None:
    """The study's params on the check's seeds, beside the defaults' runs (reused where archived); `finished`
    is called after each run."""
    seeds = 2 if quick else CHECK_SEEDS
    arms = [plan.defaults_arm(method, seeds), plan.tuned_arm(method, read_params(best, plan.task), seeds)]
    reuse(plan, [method], out)
    options = SweepOptions(workers, finished=finished)
    run_suite(arms, seeds, out / "checks", options, name=f"tuned-{plan.task}-{method}")


def reuse(plan: Plan, methods: Sequence[str], out: Path) -> None:
    """The studies' runs of the defaults of `methods` on `plan` (§16's reuse), unpacked from their archives
    into OUT/checks/ where missing."""
    for archive in plan.archives:
        unpack_missing(archive, out / "checks", {plan.defaults_arm(method).name for method in methods})


def start_from(archive: Path, out: Path, plans: Sequence[Plan], methods: Sequence[str]) -> None:
    """What `out` lacks of §16's `archive` (`export`), and the defaults' runs its checks reuse from theirs."""
    if not archive.name.endswith(ARCHIVE_SUFFIX):
        raise ConfigError(f"--archive {archive}: expected a {ARCHIVE_SUFFIX} file")
    unpack_missing(archive, out)
    for plan in plans:
        studied = [m for m in methods if (out / "tuning" / f"{plan.task}-{m}" / "best.json").is_file()]
        if studied and plan.archives:
            reuse(plan, studied, out)


STUDY_FILES = ("study.db", "best.json", "study.json")
"""What a study leaves beside its trials' runs that the archive keeps (its figures are redrawn from study.db)."""


def export(out: Path, archive: Path, plans: Sequence[Plan], methods: Sequence[str]) -> None:
    """§16 so far into `archive`: each study's STUDY_FILES (its database copied by SQLite's backup, whole
    while trials write to it), every complete run under tuning/ (trials, the defaults on the tuning seeds)
    and the check's tuned runs; not the defaults' runs the check reuses, which their studies' archives hold."""
    reused = {plan.defaults_arm(method).name for plan in plans for method in methods}
    runs = [name for name in lab_files(out) if not (name.startswith("checks/") and name.split("/")[1] in reused)]
    files = {name: out / name for name in runs}
    with tempfile.TemporaryDirectory(prefix="tuned-presets-") as tmp:
        for path in sorted((out / "tuning").glob("*/*")):
            name = path.relative_to(out).as_posix()
            if path.name == "study.db":
                files[name] = Path(tmp) / name.replace("/", "-")
                with (
                    contextlib.closing(sqlite3.connect(path)) as db,
                    contextlib.closing(sqlite3.connect(files[name])) as copy,
                ):
                    db.backup(copy)
            elif path.name in STUDY_FILES:
                files[name] = path
        write_archive(files, archive)


def written(out: Path) -> frozenset[tuple[str, int]]:
    """Every file under `out` with its modification time: what changes when a run, a trial or a study ends."""
    return frozenset((p.as_posix(), p.stat().st_mtime_ns) for p in out.rglob("*") if p.is_file())


def judge(plan: Plan, tuned: list[FinishedRun], defaults: list[FinishedRun]) -> str:
    """§16's rule: better on the study's metric (Mann–Whitney p < 0.05 and the medians differing by at least
    one evaluation period for `threshold`, MARGIN of the teacher − random span for `auc`), and not worse at
    the end (the final greedy return, by the same test, MARGIN of the span)."""
    threshold = get_task(plan.task).solved_return
    span = plan.anchors[1] - plan.anchors[0]
    margin = dict(plan.protocol)["eval_every"] if plan.metric == "threshold" else MARGIN * span
    values = [np.array([run_score(r, plan.metric, threshold) for r in runs]) for runs in (tuned, defaults)]
    p, gain, said = compare(*values, METRICS[plan.metric].direction, float(margin))  # type: ignore[arg-type]
    finals = [np.array([r.final.mean_return for r in runs]) for runs in (tuned, defaults)]
    end_p, end_gain, end_said = compare(*finals, "maximize", MARGIN * span)
    changes = said == "**better**" and end_said != "**worse**"
    return (
        f"{plan.metric}: {said} (p = {p:.3g}, {number(gain, '+')} in the tuned params' favour, "
        f"margin {number(margin)}); "
        f"final return: {end_said} (p = {end_p:.3g}, {number(end_gain, '+')}) → "
        + ("**the preset takes the tuned params**" if changes else "the preset keeps its defaults")
    )


def finished_trials(settings: TuneSettings) -> int:
    """The study's complete and pruned trials (what `tune` counts towards its --trials)."""
    import optuna
    from optuna.trial import TrialState

    study = optuna.load_study(study_name=settings.name, storage=settings.storage_url)
    return len(study.get_trials(deepcopy=False, states=(TrialState.COMPLETE, TrialState.PRUNED)))


def number(x: float, sign: str = "") -> str:
    """A value as the report prints it: interactions whole (17,750, not 1.775e+04), returns to 4 figures."""
    return f"{x:{sign},.0f}" if abs(x) >= 1_000 else f"{x:{sign},.4g}"


def scored(plan: Plan, value: float) -> str:
    """A study's value as the report prints it: for `threshold`, a mean past the proxy budget says so (a run
    that never reaches the threshold scores the grid point after the budget)."""
    past = plan.metric == "threshold" and value > plan.tuning_steps
    return f"{number(value)}, past the {plan.tuning_steps:,} budget" if past else number(value)


def status(plan: Plan, method: str, out: Path, quick: bool) -> str:
    """One row of the report: the study, the defaults' value, and the check's verdict (or where it stands)."""
    best = out / "tuning" / f"{plan.task}-{method}" / "best.json"
    found = json.loads(best.read_text()) if best.is_file() else None
    own = own_value(plan, method, out, 1, quick, run_missing=False)
    cells = [plan.task, method, f"{plan.metric} at {plan.tuning_steps:,}"]
    cells += [f"{scored(plan, found['value'])} (trial {found['trial']})" if found else "not run"]
    cells += [scored(plan, own) if own is not None else "not run"]
    settings = TuneSettings(out=best.parent, task=plan.task, **tuning(plan, method, quick))
    if (best.parent / "study.db").is_file() and (done := finished_trials(settings)) < settings.trials:
        cells[3] = f"{cells[3] if found else 'none yet'} ({done} of {settings.trials} trials)"
        return "| " + " | ".join([*cells, "— (the study is under way)"]) + " |"
    if found is None or own is None:
        return "| " + " | ".join([*cells, "—"]) + " |"
    if not (quick or better(plan.metric, found["value"], own)):
        return "| " + " | ".join([*cells, "no check: the study's best is no better than the defaults"]) + " |"
    seeds = 2 if quick else CHECK_SEEDS
    tuned, defaults = (
        checked(out / "checks" / a.name, seeds)
        for a in (plan.tuned_arm(method, found["params"], seeds), plan.defaults_arm(method, seeds))
    )
    if min(len(tuned), len(defaults)) < seeds:
        return "| " + " | ".join([*cells, f"check under way: {len(tuned)} and {len(defaults)} of {seeds} seeds"]) + " |"
    return "| " + " | ".join([*cells, judge(plan, tuned, defaults)]) + " |"


def checked(directory: Path, seeds: int) -> list[FinishedRun]:
    """The complete runs of an arm's directory at the check's seeds (none while it has none)."""
    return [r for r in load_runs(directory) if r.config.seed < seeds] if directory.is_dir() else []


def report(plans: Sequence[Plan], methods: Sequence[str], out: Path, quick: bool, archive: Path | None = None) -> str:
    """§16's table; the command it names reads `archive` into any OUT when given (the committed report)."""
    source = f"--out OUT --no-run --archive {archive}` (OUT: any directory" if archive else f"--out {out} --no-run`"
    lines = [
        "# Tuning the presets (PREREGISTRATION §16)",
        "",
        f"Generated by `python -m studies.tuned_presets {source}{'; it is unpacked there)' if archive else ''}. "
        "Each study: TPE, the median "
        f"pruner, {TRIALS} trials on seeds 1,000,000 and 1,000,001; the check: seeds 0–{CHECK_SEEDS - 1} at "
        "the studies' budget against their runs of the preset's defaults.",
        "",
        "| preset | method | study | its best (trial) | the defaults, same seeds | check on fresh seeds |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    lines += [status(plan, method, out, quick) for plan in plans for method in methods]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = ArgumentParser(prog="python -m studies.tuned_presets", description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, required=True, help="the studies' and the checks' directory")
    parser.add_argument("--workers", type=positive_int, default=2, help="trials (and check runs) at once")
    parser.add_argument("--no-run", action="store_true", help="report what is under --out, run nothing")
    parser.add_argument("--report", type=Path, help="write the markdown here too (default: print it only)")
    parser.add_argument("--quick", action="store_true", help="acrobot, bayes, on the quick budget (a test)")
    parser.add_argument(
        "--archive",
        type=Path,
        help=f"start from this {ARCHIVE_SUFFIX} archive (what --out lacks of it) and export to it",
    )
    args = parser.parse_args(argv)
    plans, methods = ((quick_plan(),), METHODS[:1]) if args.quick else (PLANS, METHODS)
    if args.archive is not None:
        start_from(args.archive, args.out, plans, methods)

    exported: list[object] = [None]

    def finished(_: object = None) -> None:
        """Export what is new since the last export (a resumed study, its defaults and its check find all
        done and write the archive once, not once each)."""
        if args.archive is not None and not args.no_run and (now := written(args.out)) != exported[-1]:
            export(args.out, args.archive, plans, methods)
            exported.append(now)

    if not args.no_run:
        for plan in plans:
            for method in methods:
                best = study(plan, method, args.out, args.workers, args.quick)
                finished()
                own = own_value(plan, method, args.out, args.workers, args.quick, True, finished)
                value = json.loads(best.read_text())["value"] if best else None
                if best is not None and (args.quick or better(plan.metric, value, own)):
                    check(plan, method, best, args.out, args.workers, args.quick, finished)
    return emit(report(plans, methods, args.out, args.quick, args.archive if args.no_run else None), args.report)


if __name__ == "__main__":
    sys.exit(run(main))
