"""The five-game MinAtar study: DQfD (`bayes`, `ce`) and DQN (`none`) against SB3's DQN on every
MinAtar game (its rules are docs/PREREGISTRATION.md §13, committed before its runs).

Ours: each game's preset as `train.py --task minatar-GAME` runs it (10 episodes of the imperfect
teacher, MinAtar's network and DQN settings, one update per step), BUDGET interactions. SB3: its DQN
with the same network and rl-zoo3's Atari schedule (`sb3_pixels.py`), one `learn()` of BUDGET steps.
Every arm is evaluated on one grid (10 greedy episodes of the plain env at 0 and every 5,000
interactions, the seed's fixed evaluation seeds); a run's score is its evaluation at BUDGET,
normalised per game so that the uniform random policy is 0 and the imperfect teacher 1 (ANCHORS).
The runs go seed by seed (every arm of every game for seed 0, then seed 1, …), so an interrupted
study has whole seeds; with `--archive`, every finished run is exported there as it finishes and a
new machine starts from that archive, so nothing is computed twice.

    python -m studies.minatar_study --out runs/minatar --archive runs/minatar.tar.xz
    python -m studies.minatar_study --out docs/data/minatar.tar.xz --no-run \\
        --report docs/MINATAR.md --figures docs/figures
    python -m studies.minatar_study --out /tmp/minatar --quick   # a minute: tiny budgets

Writes only under --out, into --archive, and, with --report and --figures, that file and the
figures `minatar_*.png` in that directory.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from dqfd_bc_keras.commands.cli import ArgumentParser, positive_int, run
from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.experiments.data import ARCHIVE_SUFFIX, export_archive, load_runs, open_suite
from dqfd_bc_keras.experiments.efficiency import SB3_METHOD, interaction_evals, teacher_verdict
from dqfd_bc_keras.experiments.figures import _colors, _figure
from dqfd_bc_keras.experiments.metrics import first_reaching
from dqfd_bc_keras.experiments.run_files import FinishedRun
from dqfd_bc_keras.experiments.stats import (
    beyond,
    bootstrap_ci,
    equivalent,
    holm,
    iqm,
    mann_whitney,
    score_distribution,
    stratified_bootstrap_ci,
    stratified_bootstrap_diff_ci,
)
from dqfd_bc_keras.experiments.suites import Arm, arm
from dqfd_bc_keras.experiments.sweep import SweepOptions, run_jobs, sweep_jobs
from dqfd_bc_keras.files import write_text
from studies.pixels import QUICK_MAX_STEPS, Sb3Job, quick_settings, run_sb3

GAMES = ("minatar-asterix", "minatar-breakout", "minatar-freeway", "minatar-seaquest", "minatar-space-invaders")
LOSSES = ("bayes", "ce", "none")
METHODS = (*LOSSES, SB3_METHOD)
DQFD = ("bayes", "ce")
BUDGET = 100_000
PROTOCOL = {"eval_every": 5_000, "eval_episodes": 10}
SEEDS = 10
"""Per arm and game, by power (PREREGISTRATION §13)."""
NUMBERS = ("no", "one", "two", "three", "four", "five", "six", "seven", "eight", "nine", "ten")
ANCHORS = {
    "minatar-asterix": (0.60, 28.58),
    "minatar-breakout": (0.37, 8.56),
    "minatar-freeway": (0.28, 15.72),
    "minatar-seaquest": (0.03, 11.11),
    "minatar-space-invaders": (4.56, 22.56),
}
"""Game → (uniform random policy, imperfect teacher): mean plain returns over 100 episodes, seeds 0–99
(`demos.recording.expert_returns(game, "imperfect", 100, 0, epsilon)` with ε = 1 and 0; pinned by
tests/test_minatar_study.py). A normalised score is (return − random) ÷ (teacher − random)."""
MARGIN = 0.15
"""bayes − ce in IQM of normalised scores: a difference within ±MARGIN is no difference (§13)."""
TAUS = np.linspace(0.0, 2.0, 81)
"""The performance profile's thresholds (normalised score)."""
RESAMPLES, RNG_SEED = 10_000, 0
ONE_SEED = "one seed: no interval"
"""What a rule reads instead of a verdict while an arm has one seed (a bootstrap of one is a point)."""
QUICK_GAMES = ("minatar-breakout", "minatar-freeway")
"""`--quick`'s games: two of the five (the pilot's), as every step of the pipeline runs on two as on five."""
QUICK_STEPS = {"ours": 300, "sb3": 500, "every": 150}
"""`--quick`: interactions of each run of ours and of SB3's, and the evaluation grid: seconds, for the tests."""

Seeds = dict[int, list[tuple[float, float]]]
"""Seed → its (interactions, mean greedy return) evaluations."""


def arms(quick: bool = False, losses: Sequence[str] = LOSSES) -> list[Arm]:
    """Our arms of `losses`, game by game (with `quick`: on tiny budgets)."""
    if quick:
        settings = quick_settings(QUICK_STEPS["ours"], QUICK_STEPS["every"])
        return [Arm(game, "bootstrap", loss, settings, "minatar-quick", 1) for game in QUICK_GAMES for loss in losses]
    return [arm(game, "bootstrap", loss, SEEDS, total_steps=BUDGET, **PROTOCOL) for game in GAMES for loss in losses]


def sb3_jobs(seeds: int, out: Path, quick: bool = False) -> list[Sb3Job]:
    """SB3's runs, seed by seed, one file per game and seed under out/sb3-dqn/GAME/."""
    budget, every = (QUICK_STEPS["sb3"], QUICK_STEPS["every"]) if quick else (BUDGET, PROTOCOL["eval_every"])
    episodes = 2 if quick else PROTOCOL["eval_episodes"]
    suffix, max_steps = ("-quick", QUICK_MAX_STEPS) if quick else ("", None)
    return [
        Sb3Job(game, seed, budget, every, episodes, out / "sb3-dqn" / game / f"seed{seed}{suffix}.json", max_steps)
        for seed in range(seeds)
        for game in (QUICK_GAMES if quick else GAMES)
    ]


def unpack_missing(archive: Path, out: Path, arms: Collection[str] | None = None) -> None:
    """The archive's files that `out` lacks (of the arms named `arms` only, if given), so a study resumed
    on another machine runs only what the archive does not hold (an archived run has no checkpoints: the
    sweep counts it complete)."""
    if not archive.is_file():
        return
    with open_suite(archive) as unpacked:
        wanted = (p for p in unpacked.rglob("*") if arms is None or p.relative_to(unpacked).parts[0] in arms)
        for path in sorted(p for p in wanted if p.is_file()):
            target = out / path.relative_to(unpacked)
            if not target.exists():
                target.parent.mkdir(parents=True, exist_ok=True)
                target.write_bytes(path.read_bytes())


def measure(
    seeds: int,
    workers: int,
    out: Path,
    archive: Path | None = None,
    quick: bool = False,
    progress: Callable[[str], None] = print,
    losses: Sequence[str] = LOSSES,
    sb3: bool = True,
) -> None:
    """Run what is missing, seed by seed: every arm of ours (`losses`) on every game, then SB3's (unless
    not `sb3`); with `archive`, start from what it holds and export the study there after each finished run."""
    seeds = 1 if quick else seeds
    if archive is not None:
        unpack_missing(archive, out)

    def export(_: object) -> None:
        if archive is not None:
            export_archive(out, archive)

    ours, theirs = arms(quick, losses), sb3_jobs(seeds, out, quick) if sb3 else []
    for seed in range(seeds):
        progress(f"minatar study: seed {seed} of 0–{seeds - 1}")
        jobs = [job for job in sweep_jobs(ours, seed + 1, out) if job.seed == seed]
        run_jobs(jobs, out, "minatar", seed + 1, SweepOptions(workers, progress=progress, finished=export))
        run_sb3([job for job in theirs if job.seed == seed], workers, progress, finished=export)


@dataclass(frozen=True)
class Study:
    """Every finished run's evaluations, by game and method; what the report is computed from."""

    runs: dict[tuple[str, str], Seeds]
    budget: int
    seeds: int
    commits: tuple[str, ...] = ()
    """The code commits our runs were made by (their provenance.json): one, if the study keeps its rule."""
    methods: tuple[str, ...] = METHODS
    """The arms, in the report's order."""
    dqfd: tuple[str, ...] = DQFD
    """The arms that learn from demonstrations: the ones the questions judge (the others are described)."""
    anchors: Mapping[str, tuple[float, float]] = field(default_factory=lambda: ANCHORS)
    """Task → (uniform random policy, teacher): the tasks, in order, and their normalisation."""
    unit: str = "game"
    """What a task is called in the report."""

    @property
    def games(self) -> tuple[str, ...]:
        return tuple(self.anchors)

    @property
    def every_game(self) -> str:
        """ "all five games": what a complete seed has run on."""
        count = len(self.games)
        return (
            f"both {self.unit}s"
            if count == 2
            else f"all {NUMBERS[count] if count < len(NUMBERS) else count} {self.unit}s"
        )

    def normalised(self, game: str, value: float | np.ndarray) -> float | np.ndarray:
        return normalised(game, value, self.anchors)

    def final(self, game: str, method: str) -> dict[int, float]:
        """Seed → the mean greedy return at the budget (the run's last grid point)."""
        return {seed: evals[-1][1] for seed, evals in self.runs.get((game, method), {}).items()}

    def complete_seeds(self, method: str) -> list[int]:
        """The seeds that `method` has finished on every game (the rows of its score matrix)."""
        have = [set(self.runs.get((game, method), {})) for game in self.games]
        return sorted(set.intersection(*have))

    def scores(self, method: str) -> np.ndarray:
        """(complete seeds, games) normalised scores at the budget."""
        seeds = self.complete_seeds(method)
        return np.array(
            [[self.normalised(game, self.final(game, method)[s]) for game in self.games] for s in seeds]
        ).reshape(len(seeds), len(self.games))

    @property
    def complete(self) -> bool:
        return all(len(self.runs.get((g, m), {})) >= self.seeds for g in self.games for m in self.methods)


def normalised(
    game: str, value: float | np.ndarray, anchors: Mapping[str, tuple[float, float]] = ANCHORS
) -> float | np.ndarray:
    random, teacher = anchors[game]
    return (value - random) / (teacher - random)


def made_by(finished: FinishedRun) -> str:
    """The short commit of the code a run was made by (its provenance.json), marked if the tree was dirty."""
    origin = finished.provenance
    return (origin.code_commit or "unknown")[:7] + " (dirty)" * bool(origin.dirty)


def collect(out: Path, seeds: int, quick: bool = False, losses: Sequence[str] = LOSSES) -> Study:
    """The runs under `out` that reached the budget: ours (complete runs of the arms of `losses`) and SB3's
    (current files)."""
    budget = QUICK_STEPS["ours"] if quick else BUDGET
    runs: dict[tuple[str, str], Seeds] = {}
    commits = set()
    for a in arms(quick, losses):
        for seed in range(seeds):
            directory = out / a.name / f"seed{seed}"
            for finished in load_runs(directory) if directory.is_dir() else []:  # none while it is still finishing
                evals = interaction_evals(finished)
                if evals[-1][0] >= budget:
                    runs.setdefault((a.task, a.expert_loss), {})[seed] = evals
                    commits.add(made_by(finished))
    for job in sb3_jobs(seeds, out, quick):
        if job.current():
            evaluations = json.loads(job.path.read_text())["evaluations"]
            runs.setdefault((job.task, SB3_METHOD), {})[job.seed] = [
                (e["interactions"], e["mean_return"]) for e in evaluations
            ]
    anchors = {game: ANCHORS[game] for game in (QUICK_GAMES if quick else GAMES)}
    return Study(runs, budget, seeds, tuple(sorted(commits)), anchors=anchors)


def check_out(out: Path, archive: Path | None, no_run: bool) -> None:
    """A study's --out and --archive as it can use them: an archive is only read; --archive is an archive."""
    if str(out).endswith(ARCHIVE_SUFFIX) and not no_run:
        raise ConfigError(f"--out {out}: an archive is read, never run into: add --no-run")
    if archive is not None and not str(archive).endswith(ARCHIVE_SUFFIX):
        raise ConfigError(f"--archive {archive}: expected a {ARCHIVE_SUFFIX} file")


def run_or_read(
    out: Path,
    seeds: int,
    quick: bool,
    no_run: bool,
    archive: Path | None = None,
    workers: int = 2,
    losses: Sequence[str] = LOSSES,
    sb3: bool = True,
) -> Study:
    """The study under `out` as the command's flags ask: an archive is read (never run into); a directory
    gets what it lacks run first (unless `no_run`), starting from `archive` and exporting to it."""
    check_out(out, archive, no_run)
    if str(out).endswith(ARCHIVE_SUFFIX):
        with open_suite(out) as directory:
            return collect(directory, seeds, quick, losses)
    if not no_run:
        measure(seeds, workers, out, archive, quick, losses=losses, sb3=sb3)
    return collect(out, seeds, quick, losses)


def steps_to_teacher(study: Study, game: str, method: str) -> dict[int, float]:
    """Seed → the first grid point whose mean greedy return reaches the teacher's (inf: never)."""
    teacher = study.anchors[game][1]
    return {
        seed: np.inf if (first := first_reaching(evals, teacher)) is None else first
        for seed, evals in study.runs.get((game, method), {}).items()
    }


def number(value: float, digits: int = 2) -> str:
    return "∞" if np.isinf(value) else f"{value:,.{digits}f}"


def _interval(low: float, high: float, digits: int = 2) -> str:
    return f"[{number(low, digits)}, {number(high, digits)}]"


def arm_label(method: str) -> str:
    return "none (DQN, no demonstrations)" if method == "none" else method


def teacher_rows(study: Study, judged: bool) -> list[str]:
    """Q1, per game: each arm's median return at the budget with its 95% CI, against the teacher (§7's rule)."""
    lines = [
        f"| {study.unit} | random | teacher | arm | runs | median return at the budget [95% CI] | normalised | "
        "against the teacher |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for game in study.games:
        random, teacher = study.anchors[game]
        for method in study.methods:
            final = list(study.final(game, method).values())
            if not final:
                lines.append(f"| {game} | {random:g} | {teacher:g} | {arm_label(method)} | 0 | not run | | |")
                continue
            median, low, high, verdict = teacher_verdict(final, teacher)
            verdict = "does not beat it" if verdict == "does not" else verdict
            verdict = ONE_SEED if len(final) < 2 else verdict
            if method not in study.dqfd:
                verdict = f"({verdict}; described, not judged)"
            elif not judged:
                verdict = f"interim: {verdict}"
            lines.append(
                f"| {game} | {random:g} | {teacher:g} | {arm_label(method)} | {len(final)} | {median:.2f} "
                f"{_interval(low, high)} | {study.normalised(game, median):.2f} | {verdict} |"
            )
    return lines


def aggregate_rows(study: Study, judged: bool) -> list[str]:
    """Across games: each arm's IQM of normalised scores with its 95% stratified bootstrap CI."""
    lines = [
        f"| arm | seeds on {study.every_game} | IQM of normalised scores [95% CI] | mean | runs above the teacher | "
        f"across {study.unit}s |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for method in study.methods:
        scores = study.scores(method)
        if scores.size == 0:
            lines.append(f"| {arm_label(method)} | 0 | no seed on {study.every_game} yet | | | |")
            continue
        low, high = stratified_bootstrap_ci(scores, iqm, 0.95, RESAMPLES, RNG_SEED)
        above = float(score_distribution(scores, [1.0])[0])
        verdict = "beats its teachers" if low > 1 else "below its teachers" if high < 1 else "inconclusive"
        verdict = ONE_SEED if scores.shape[0] < 2 else verdict
        verdict = (
            verdict
            if method in study.dqfd and judged
            else f"({verdict}; {'interim' if method in study.dqfd else 'described'})"
        )
        lines.append(
            f"| {arm_label(method)} | {scores.shape[0]} | {iqm(scores.reshape(-1)):.2f} {_interval(low, high)} | "
            f"{scores.mean():.2f} | {above:.0%} | {verdict} |"
        )
    return lines


def sooner_rows(study: Study, judged: bool) -> list[str]:
    """Q2, per game: interactions to the teacher's return; each DQfD arm against DQN and SB3 (Mann–Whitney,
    never reached ranked last, Holm over every DQfD arm × 2 × 5 games: §13's 20 comparisons)."""
    steps_of = {
        (g, m): np.array(list(steps_to_teacher(study, g, m).values()), dtype=float)
        for g in study.games
        for m in study.methods
    }
    tests = {
        (game, method, other): mann_whitney(steps_of[game, method], steps_of[game, other])[1]
        for game in study.games
        for method in study.dqfd
        for other in ("none", SB3_METHOD)
        if steps_of[game, method].size and steps_of[game, other].size
    }
    adjusted = dict(zip(tests, holm(list(tests.values()), len(study.dqfd) * 2 * len(study.games)), strict=True))
    lines = [
        f"| {study.unit} | arm | reached the teacher | median interactions [95% CI] | against DQN (none): Holm p | "
        "against SB3: Holm p |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for game in study.games:
        for method in study.methods:
            steps = steps_of[game, method]
            if steps.size == 0:
                lines.append(f"| {game} | {arm_label(method)} | not run | | | |")
                continue
            low, high = bootstrap_ci(steps, np.median, 0.95, RESAMPLES, RNG_SEED)
            cells = []
            for other in ("none", SB3_METHOD):
                p = adjusted.get((game, method, other))
                if p is None:
                    cells.append("")
                    continue
                sooner = np.median(steps) < np.median(steps_of[game, other])
                word = ("sooner" if sooner else "later") if p < 0.05 else "no measurable difference"
                cells.append(f"{p:.3f}: {word if judged else 'interim: ' + word}")
            lines.append(
                f"| {game} | {arm_label(method)} | {int(np.isfinite(steps).sum())}/{steps.size} | "
                f"{number(np.median(steps), 0)} {_interval(low, high, 0)} | {' | '.join(cells)} |"
            )
    return lines


def difference(study: Study, judged: bool, first: str = "bayes", second: str = "ce") -> list[str]:
    """§13's Q3 rule: IQM(first) − IQM(second) of normalised scores with its 95% and 90% stratified CIs,
    against ±MARGIN; and per game, Mann–Whitney with Holm over the 5 games."""
    a, b = study.scores(first), study.scores(second)
    if a.size == 0 or b.size == 0:
        return ["Not run."]
    wide = stratified_bootstrap_diff_ci(a, b, iqm, 0.95, RESAMPLES, RNG_SEED)
    narrow = stratified_bootstrap_diff_ci(a, b, iqm, 0.90, RESAMPLES, RNG_SEED)
    significant = wide[0] > 0 or wide[1] < 0
    higher = first if wide[0] > 0 else second
    if equivalent(narrow, MARGIN):
        verdict = f"equivalent (the 90% CI lies within ±{MARGIN:g})"
        verdict += f"; {higher} is higher by a significant amount inside the margin" if significant else ""
    elif significant:
        verdict = f"{higher} is better" + (
            " markedly" if beyond(narrow, MARGIN) else f", not markedly (the 90% CI reaches inside ±{MARGIN:g})"
        )
    else:
        verdict = "inconclusive"
    verdict = ONE_SEED if min(a.shape[0], b.shape[0]) < 2 else verdict
    gap = iqm(a.reshape(-1)) - iqm(b.reshape(-1))
    lines = [
        f"IQM({first}) − IQM({second}) = {gap:+.3f}, 95% CI {_interval(*wide, 3)}, 90% CI {_interval(*narrow, 3)} "
        f"({a.shape[0]} and {b.shape[0]} seeds on {study.every_game}): "
        f"**{verdict if judged else 'interim, not judged: ' + verdict}**.",
        "",
        f"| {study.unit} | {first} median | {second} median | Mann–Whitney p (Holm over {len(study.games)} "
        f"{study.unit}s) |",
        "| --- | --- | --- | --- |",
    ]
    pairs = [(list(study.final(g, first).values()), list(study.final(g, second).values())) for g in study.games]
    ps = holm([mann_whitney(x, y)[1] if x and y else 1.0 for x, y in pairs], len(study.games))
    for game, (x, y), p in zip(study.games, pairs, ps, strict=True):
        if x and y:
            lines.append(f"| {game} | {np.median(x):.2f} | {np.median(y):.2f} | {p:.3f} |")
    return lines


def grid_scores(study: Study, method: str) -> tuple[np.ndarray, np.ndarray]:
    """The evaluation grid's interactions (as the runs record them), and a (points, complete seeds, games) array
    of normalised scores."""
    seeds = study.complete_seeds(method)
    points = np.array(sorted({x for game in study.games for seed in seeds for x, _ in study.runs[game, method][seed]}))
    cube = np.full((points.size, len(seeds), len(study.games)), np.nan)
    for g, game in enumerate(study.games):
        for s, seed in enumerate(seeds):
            evals = dict(study.runs[game, method][seed])
            for p, point in enumerate(points):
                if point in evals:
                    cube[p, s, g] = study.normalised(game, evals[point])
    return points, cube


def _legend(ax, study: Study) -> None:
    """A legend where something is drawn; an empty axis (no seed on all games yet) says so."""
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7)
    else:
        ax.text(0.5, 0.5, f"no seed on {study.every_game} yet", ha="center", va="center", transform=ax.transAxes)


def figures(study: Study, directory: Path, prefix: str = "minatar") -> list[str]:
    """The performance profile and the IQM over interactions (rliable's two pictures), and each game's
    mean curves, as PREFIX_*.png; returns the markdown that shows them (paths relative to the report's folder)."""
    profile, curve, games = (directory / f"{prefix}_{name}.png" for name in ("profile", "iqm", "games"))
    colors = dict(zip(study.methods, _colors(), strict=False))
    with _figure(profile, figsize=(6, 4)) as (_, ax):
        for method in study.methods:
            scores = study.scores(method)
            if scores.size:
                band = stratified_bootstrap_ci(
                    scores, lambda x, axis=None: score_distribution(x, TAUS, axis), 0.95, RESAMPLES, RNG_SEED
                )
                ax.plot(TAUS, score_distribution(scores, TAUS), color=colors[method], label=f"{arm_label(method)}")
                ax.fill_between(TAUS, band[0], band[1], color=colors[method], alpha=0.2, linewidth=0)
        ax.axvline(1.0, color="grey", linestyle=":", linewidth=1)
        ax.set(xlabel="normalised score τ (random 0, teacher 1)", ylabel="share of runs with score > τ")
        _legend(ax, study)
    with _figure(curve, figsize=(6, 4)) as (_, ax):
        for method in study.methods:
            points, cube = grid_scores(study, method)
            if cube.shape[1]:
                mean = [iqm(c.reshape(-1)) for c in cube]
                bands = np.array([stratified_bootstrap_ci(c, iqm, 0.95, 2_000, RNG_SEED) for c in cube])
                ax.plot(points, mean, color=colors[method], label=arm_label(method))
                ax.fill_between(points, bands[:, 0], bands[:, 1], color=colors[method], alpha=0.2, linewidth=0)
        ax.axhline(1.0, color="grey", linestyle=":", linewidth=1)
        ax.set(xlabel="interactions", ylabel="IQM of normalised scores")
        _legend(ax, study)
    with _figure(games, nrows=1, ncols=len(study.games), figsize=(3 * len(study.games), 3)) as (_, axes):
        for ax, game in zip(axes, study.games, strict=True):
            for method in study.methods:
                seeds = study.runs.get((game, method), {})
                if seeds:
                    xs = [x for x, _ in next(iter(seeds.values()))]
                    ys = np.mean([[y for _, y in evals][: len(xs)] for evals in seeds.values()], axis=0)
                    ax.plot(xs, ys, color=colors[method], label=arm_label(method))
            ax.axhline(study.anchors[game][1], color="grey", linestyle=":", linewidth=1)
            ax.set(title=game.removeprefix("minatar-"), xlabel="interactions")
        axes[0].set_ylabel("mean greedy return over seeds\n(dotted: the teacher)")
        _legend(axes[0], study)
    return [
        f"![{name}](figures/{path.name})"
        for name, path in (("performance profile", profile), ("IQM", curve), ("games", games))
    ]


def status(study: Study) -> str:
    """Complete (the verdicts are read), or how far the runs are."""
    if study.complete:
        return (
            f"**Complete: {study.seeds} seeds of every arm on every {study.unit}; the verdicts below are the "
            "pre-registered ones.**"
        )
    counts = {m: min(len(study.runs.get((g, m), {})) for g in study.games) for m in study.methods}
    finished = sum(len(study.runs.get((g, m), {})) for g in study.games for m in study.methods)
    return (
        f"**Interim: {finished} of {study.seeds * len(study.games) * len(study.methods)} runs finished (seeds finished "
        f"on {study.every_game}: "
        + ", ".join(f"{arm_label(m)} {counts[m]}" for m in study.methods)
        + f", of {study.seeds}). Numbers are described; no pre-registered verdict is given until every arm has "
        f"every seed on every {study.unit}.**"
    )


def report(study: Study, figure_dir: Path | None = None) -> str:
    """The study as markdown: status, protocol, the three questions, the figures."""
    judged = study.complete
    anchors = ", ".join(f"{g.removeprefix('minatar-')} {r:g} / {t:g}" for g, (r, t) in ANCHORS.items())
    return "\n".join(
        [
            "# Five MinAtar games: DQfD against DQN and SB3's DQN",
            "",
            "Generated by `python -m studies.minatar_study --out docs/data/minatar.tar.xz --no-run "
            "--report docs/MINATAR.md --figures docs/figures` from the per-run files in docs/data/minatar.tar.xz "
            "(rules: docs/PREREGISTRATION.md §13).",
            "",
            status(study),
            "",
            f"Our runs' code: {', '.join(study.commits) or 'none yet'} (each run's provenance.json).",
            "",
            f"Protocol: each game's preset (`train.py --task minatar-GAME`: 10 episodes of the imperfect teacher, "
            f"MinAtar's network, one update per step), {study.budget:,} interactions per run, arms `bayes`, `ce`, "
            f"`none` (DQN without demonstrations) and SB3's DQN with the same network (rl-zoo3's Atari schedule, one "
            f"`learn()` of {study.budget:,} steps). Score: the mean of 10 greedy episodes at the budget, normalised "
            f"per game (random 0, teacher 1; random / teacher: {anchors}). Across games: the interquartile mean (IQM) "
            "with 95% stratified-bootstrap intervals (each game's seeds resampled on their own) and the performance "
            "profile, as rliable reports them (our `stats` module, tested against rliable's numbers).",
            "",
            "## Does DQfD beat its teacher?",
            "",
            *aggregate_rows(study, judged),
            "",
            *teacher_rows(study, judged),
            "",
            "## Does it reach the teacher's score sooner than DQN and SB3?",
            "",
            *sooner_rows(study, judged),
            "",
            "## Do bayes and ce differ?",
            "",
            *difference(study, judged),
            "",
            *(["## Figures", "", *figures(study, figure_dir), ""] if figure_dir is not None else []),
        ]
    )


def study_arguments(parser: ArgumentParser, runs: str, per: str, figures: str, out_required: bool = False) -> None:
    """The flags a study shares: its runs' directory (or archive) and the archive it exports to, the seeds,
    workers, --quick and --no-run, the report and its figures (`figures`_*.png)."""
    parser.add_argument(
        "--out", type=Path, required=out_required, help=f"directory of {runs} (or its archive, with --no-run)"
    )
    parser.add_argument(
        "--archive", type=Path, help=f"start from this {ARCHIVE_SUFFIX} archive and export to it as runs finish"
    )
    parser.add_argument("--seeds", type=positive_int, default=SEEDS, help=f"seeds per {per} (default %(default)s)")
    parser.add_argument("--workers", type=positive_int, default=2, help="parallel runs (default %(default)s)")
    parser.add_argument("--quick", action="store_true", help="one seed, tiny budgets: checks the command runs")
    parser.add_argument("--no-run", action="store_true", help="report the runs under --out, run nothing")
    parser.add_argument("--report", type=Path, help="write the markdown report to this file")
    parser.add_argument(
        "--figures", type=Path, help=f"write the report's figures ({figures}_*.png) into this directory"
    )


def emit(text: str, report_path: Path | None) -> int:
    """Print a study's report, and write it to `report_path` if asked."""
    print(text)
    if report_path is not None:
        write_text(report_path, text + "\n")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    parser = ArgumentParser(prog="python -m studies.minatar_study", description=__doc__.split("\n\n")[0])
    study_arguments(parser, "the study's runs", "arm and game", "minatar", out_required=True)
    args = parser.parse_args(argv)
    study = run_or_read(args.out, 1 if args.quick else args.seeds, args.quick, args.no_run, args.archive, args.workers)
    return emit(report(study, args.figures), args.report)


if __name__ == "__main__":
    raise SystemExit(run(main))
