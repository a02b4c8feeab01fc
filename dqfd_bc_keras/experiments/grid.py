"""When do demonstrations help or hurt? The quality × quantity grid (PREREGISTRATION §8).

    python -m dqfd_bc_keras.experiments grid --out results          # runs, BC alone, GRID.md, heatmaps
    python -m dqfd_bc_keras.experiments grid --task mountaincar --out results   # one task's grid
    python -m dqfd_bc_keras.experiments grid --quick --out /tmp/g   # 1 cell, 1 seed, QUICK budget

On each task of `GRID_TASKS` (CartPole, MountainCar), per cell (teacher × demonstrated episodes) and
method: the median over seeds of counted interactions until a greedy evaluation reaches the solved
threshold (∞: never), and of the final evaluation minus the teacher's 100-episode mean. Against
plain DQN (no demonstrations) a method *helps* in a cell if the 95% bootstrap CI of DQN's median ÷
its median lies wholly above 1, *hurts* if wholly below; it *escapes* a teacher below the threshold
if its median final return lies above the teacher's mean with the CI of that median wholly above
(§7's teacher rule).
"""

from __future__ import annotations

import dataclasses
import functools
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.experiments.arm_config import Arm
from dqfd_bc_keras.experiments.arms import ArmRuns, group_arms
from dqfd_bc_keras.experiments.data import load_runs
from dqfd_bc_keras.experiments.efficiency import ratio_ci, teacher_verdict
from dqfd_bc_keras.experiments.figures import Heatmap, heatmap
from dqfd_bc_keras.experiments.imitation import imitation_arms, load_imitation, run_imitation
from dqfd_bc_keras.experiments.lab_settings import lab_settings
from dqfd_bc_keras.experiments.metrics import interactions_to_threshold, solved_return
from dqfd_bc_keras.experiments.suites import SUITES, all_grid_arms, grid_arms, grid_cells, grid_tasks
from dqfd_bc_keras.experiments.sweep import SweepOptions, run_suite
from dqfd_bc_keras.files import write_text

BC_ALONE, DQN = "BC alone", "DQN (no demos)"
GRID_FILE = "GRID.md"


@dataclass(frozen=True)
class Cell:
    task: str
    expert: str
    epsilon: float
    episodes: int

    @property
    def teacher(self) -> str:
        return self.expert if self.epsilon == 0 else f"{self.expert} ε={self.epsilon:g}"

    @property
    def name(self) -> str:
        return f"{self.teacher} × {self.episodes}"

    @property
    def teacher_return(self) -> float:
        """The teacher's mean plain return over 100 episodes (its task's `grid_teachers`, lab_settings.py)."""
        return lab_settings(self.task).grid_teachers[self.expert, self.epsilon]

    @property
    def threshold(self) -> float:
        return solved_return(self.task)


@dataclass
class Entry:
    """One method on one cell: per seed, interactions to threshold (inf: never) and final return."""

    steps: np.ndarray
    final: np.ndarray


def method_name(a: Arm) -> str:
    fields = dict(a.overrides)
    if a.expert_loss == "bayes":
        return f"bayes ({fields.get('uncertainty', 'mc_dropout')})"
    return {"none": DQN, "sqil": "SQIL", "bc-alone": BC_ALONE}.get(a.expert_loss, a.expert_loss)


def _cell(a: Arm) -> Cell:
    config = dataclasses.replace(a, expert_loss="ce").config(0)
    return Cell(config.task, config.expert, config.expert_epsilon, config.demo_episodes)


def collect(
    arms: list[ArmRuns], suite_dir: Path, task: str, quick: bool = False
) -> tuple[list[Cell], dict[str, dict[Cell, Entry]]]:
    """`task`'s cells and {method: {cell: Entry}} from the suite's arms and BC alone's files."""
    cells = [Cell(task, c["expert"], c["expert_epsilon"], c["demo_episodes"]) for c in grid_cells(quick)]
    by_config = {_key(a.fields): a for a in arms}
    table: dict[str, dict[Cell, Entry]] = {}
    for a in grid_arms(task, quick):
        found = by_config.get(_key(a.config(0).to_dict()))
        runs = [r for r in found.runs if r.config.seed < a.seeds] if found else []  # the grid's seeds only
        if not runs:
            continue
        entry = Entry(
            np.array([interactions_to_threshold(r) for r in runs], float),
            np.array([r.final.mean_return for r in runs], float),
        )
        targets = cells if a.expert_loss == "none" else [_cell(a)]
        for cell in targets:
            table.setdefault(method_name(a), {})[cell] = entry
    imitation = load_imitation(suite_dir)
    for a in imitation_arms(quick, (task,)):
        if imitation.get(a.name):
            finals = np.array([r["mean_return"] for r in imitation[a.name]], float)
            table.setdefault(BC_ALONE, {})[_cell(a)] = Entry(np.full(finals.size, np.nan), finals)
    return cells, table


def grid_only(config: Config) -> bool:
    """Whether an arm's config (its seed aside) is one only the grid runs: such arms are drawn
    as the grid's heatmaps, not as curves among a setting's variants."""
    return _key(config.to_dict()) in _grid_only_keys()


@functools.cache
def _grid_only_keys() -> frozenset[str]:
    others = {_key(a.config(0).to_dict()) for name, arms in SUITES.items() if name != "demos" for a in arms}
    return frozenset({_key(a.config(0).to_dict()) for a in all_grid_arms()} - others)


def _key(config: dict) -> str:
    return repr(sorted((k, tuple(v) if isinstance(v, list) else v) for k, v in config.items() if k != "seed"))


def effect(entry: Entry, dqn: Entry) -> str:
    """helps | hurts | unclear: the CI of DQN's median interactions ÷ this method's, against 1."""
    _, low, high = ratio_ci(dqn.steps, entry.steps)
    return "helps" if low > 1 else "hurts" if high < 1 else "unclear"


def escapes(entry: Entry, cell: Cell) -> bool:
    return teacher_verdict(entry.final, cell.teacher_return)[3] == "beats its teacher"


def _steps(x: float) -> str:
    return "never" if not np.isfinite(x) else f"{x / 1000:.1f}k" if x >= 1000 else f"{x:.0f}"


def tables(cells: list[Cell], table: dict[str, dict[Cell, Entry]]) -> list[str]:
    """Two markdown tables (rows: methods, columns: cells) and the per-method counts."""
    header = ["| method | " + " | ".join(c.name for c in cells) + " |", "| --- |" + " ---: |" * len(cells)]
    dqn = table.get(DQN, {})
    steps, final = list(header), list(header)
    for method, entries in table.items():
        row_steps, row_final = [], []
        for cell in cells:
            entry = entries.get(cell)
            if entry is None:
                row_steps.append("—")
                row_final.append("—")
                continue
            mark = ""
            if method not in (DQN, BC_ALONE) and cell in dqn:
                mark = {"helps": " ↑", "hurts": " ↓", "unclear": ""}[effect(entry, dqn[cell])]
            reached = int(np.isfinite(entry.steps).sum())
            row_steps.append(
                "—" if method == BC_ALONE else f"{_steps(np.median(entry.steps))}{mark} ({reached}/{entry.steps.size})"
            )
            escape = " ✓" if cell.teacher_return < cell.threshold and escapes(entry, cell) else ""
            row_final.append(f"{np.median(entry.final) - cell.teacher_return:+.0f}{escape}")
        steps.append(f"| {method} | " + " | ".join(row_steps) + " |")
        final.append(f"| {method} | " + " | ".join(row_final) + " |")
    return [
        "Median counted interactions to the threshold (seeds that reached it / seeds); 0: the evaluation "
        "after pre-training, before any interaction, already reached it; ↑ helps, ↓ hurts against plain DQN:",
        "",
        *steps,
        "",
        "Median final return (eval.json, 20 episodes) minus the teacher's 100-episode mean "
        f"({', '.join(f'{c.teacher} {c.teacher_return:g}' for c in _teachers(cells))}); ✓ escapes a teacher "
        "below the threshold:",
        "",
        *final,
    ]


def _teachers(cells: list[Cell]) -> list[Cell]:
    return list({c.teacher: c for c in cells}.values())


def answers(cells: list[Cell], table: dict[str, dict[Cell, Entry]]) -> list[str]:
    """Per method: cells where it helps, hurts, and where it escapes a bad teacher (by §8's rules)."""
    dqn, lines, threshold = table.get(DQN, {}), [], cells[0].threshold
    bad = [c for c in cells if c.teacher_return < threshold]
    for method, entries in table.items():
        if method == DQN:
            continue
        judged = [c for c in cells if c in entries and c in dqn]
        verdicts = {c: effect(entries[c], dqn[c]) for c in judged} if method != BC_ALONE else {}
        helps = [c.name for c in judged if verdicts.get(c) == "helps"]
        hurts = [c.name for c in judged if verdicts.get(c) == "hurts"]
        escaped = [c.name for c in bad if c in entries and escapes(entries[c], c)]
        speed = (
            f"helps in {len(helps)} of {len(judged)} cells{_list(helps)}, hurts in {len(hurts)}{_list(hurts)}; "
            if method != BC_ALONE
            else ""
        )
        lines.append(
            f"- **{method}**: {speed}escapes a teacher below {threshold:g} in "
            f"{len(escaped)} of {sum(c in entries for c in bad)} cells{_list(escaped)}."
        )
    return lines


def _list(names: list[str]) -> str:
    return f" ({', '.join(names)})" if names else ""


def heatmaps(
    cells: list[Cell], table: dict[str, dict[Cell, Entry]], path_steps: Path, path_final: Path, seeds: int
) -> None:
    """The two tables as heatmaps: log10 interactions (blank: never, or BC alone) and final − teacher."""
    methods = list(table)
    steps = np.array(
        [[np.median(table[m][c].steps) if c in table[m] and m != BC_ALONE else np.nan for c in cells] for m in methods]
    )
    final = np.array(
        [[np.median(table[m][c].final) - c.teacher_return if c in table[m] else np.nan for c in cells] for m in methods]
    )
    bound = float(np.nanmax(np.abs(final))) if np.isfinite(final).any() else 1.0
    columns = [c.name.replace(" × ", "\n× ") for c in cells]
    title = f"{cells[0].task}, teacher × demonstrated episodes: "
    log_steps = np.log10(np.maximum(np.where(np.isfinite(steps), steps, np.nan), 1.0))
    heatmap(
        Heatmap(
            methods,
            columns,
            steps,
            log_steps,
            _steps,
            f"{title}median counted interactions to {cells[0].threshold:g} ({seeds} seeds per cell)",
        ),
        dict(cmap="viridis_r"),
        "log10 interactions",
        path_steps,
    )
    heatmap(
        Heatmap(
            methods,
            columns,
            final,
            final,
            lambda v: f"{v:+.0f}",
            f"{title}median final return − the teacher's mean ({seeds} seeds per cell)",
        ),
        dict(cmap="RdBu", vmin=-bound, vmax=bound),
        "return − teacher",
        path_final,
    )


def grid_section(
    arms: list[ArmRuns],
    suite_dir: Path,
    figures_dir: Path,
    markdown_dir: Path,
    quick: bool = False,
    tasks: tuple[str, ...] | None = None,
) -> list[str]:
    """The section of RESULTS.md (and GRID.md): per task (default: every task of the grid), tables,
    heatmaps and the per-method answers."""
    lines = []
    for task in tasks or grid_tasks(quick):
        lines += [f"### {task}", "", *_task_section(arms, suite_dir, task, figures_dir, markdown_dir, quick), ""]
    return lines[:-1]


def _task_section(
    arms: list[ArmRuns], suite_dir: Path, task: str, figures_dir: Path, markdown_dir: Path, quick: bool
) -> list[str]:
    cells, table = collect(arms, suite_dir, task, quick)
    if len(table) < 2:
        return [f"Not run: `python -m dqfd_bc_keras.experiments grid --task {task} --out results` runs it."]
    seeds = max(e.final.size for entries in table.values() for e in entries.values())
    names = (f"grid-{task}-interactions.png", f"grid-{task}-final.png")
    steps_png, final_png = (figures_dir / n for n in names)
    heatmaps(cells, table, steps_png, final_png, seeds)
    links = [f"![{n}]({os.path.relpath(figures_dir / n, markdown_dir)})" for n in names]
    config = grid_arms(task)[0].config(0)
    stop = "early stop" if config.early_stop_window else "no early stop"
    budget = (
        "the QUICK budget (a test, not a result)"
        if quick
        else f"preset defaults ({config.total_steps // 1000}k steps, {stop}, the sample-efficiency protocol)"
    )
    return [
        f"{task}, {budget}; every method with demonstrations "
        f"has up to {seeds} seeds per cell, plain DQN one set for all cells; BC alone is the MLE BC model on the "
        "cell's demonstrations, played greedily without RL (no interaction beyond the demonstrations). "
        "Rules: docs/PREREGISTRATION.md §8 (§12 on MountainCar).",
        "",
        *tables(cells, table),
        "",
        *links,
        "",
        "Per method, by those rules:",
        "",
        *answers(cells, table),
    ]


def run_grid(
    out: str | Path,
    quick: bool = False,
    seeds: int | None = None,
    workers: int = 2,
    progress: Callable[[str], None] = print,
    tasks: tuple[str, ...] | None = None,
) -> Path:
    """Every missing run of the grid on `tasks` (default: all) and of BC alone into `out`, then
    OUT/GRID.md and its heatmaps (every task's, whatever ran)."""
    out = Path(out)
    tasks = tasks or grid_tasks(quick)
    arms = [a for task in tasks for a in grid_arms(task, quick)]
    name = "demos (quick)" if quick else f"demos ({', '.join(tasks)})"
    run_suite(arms, seeds, out, SweepOptions(workers, progress=progress), name=name)
    run_imitation(out, quick, progress, tasks)
    section = grid_section(group_arms(load_runs(out)), out, out / "figures", out, quick, tasks if quick else None)
    write_text(out / GRID_FILE, "\n".join(["# Demonstration quality × quantity", "", *section, ""]))
    progress(f"wrote {out / GRID_FILE}")
    return out / GRID_FILE
