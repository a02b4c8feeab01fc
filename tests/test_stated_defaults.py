"""Every default a help text or a task table states is the presets' own: `train.py --help`'s
defaults are read back per preset, and the README's and docs/TASKS.md's task tables' step limits,
demonstrated episodes, budgets and early stops are compared with each preset's spec and Config."""

import re
from pathlib import Path

import pytest
from helpers import call

from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.tasks import TASKS

REPO = Path(__file__).resolve().parents[1]
HELP_DEFAULTS = {
    "--expert-loss": "expert_loss",
    "--target": "target",
    "--timeout": "timeout",
    "--expert": "expert",
    "--demo-episodes": "demo_episodes",
    "--steps": "total_steps",
    "--seed": "seed",
}
"""train.py's flags that state a preset default, and the Config field each sets."""


def stated_per_preset(default: str) -> dict[str, str]:
    """`10; 5 on cartpole, cartpole-200; …` → {every preset: "10", but cartpole and cartpole-200: "5"}
    (parts after the exceptions, such as `none = plain DQN`, are the help's own words)."""
    common, *parts = default.split("; ")
    said = dict.fromkeys(TASKS, common.replace(",", ""))
    for part in parts:
        if not (other := re.fullmatch(r"(\S+) on ([\w-]+(?:, [\w-]+)*)", part)):
            break
        said.update(dict.fromkeys(other[2].split(", "), other[1].replace(",", "")))
    return said


def test_stated_per_preset_reads_a_default_and_its_exceptions():
    said = stated_per_preset("100,000; 50,000 on cartpole, cartpole-200")
    assert said["cartpole"] == said["cartpole-200"] == "50000" and said["acrobot"] == "100000"
    assert set(stated_per_preset("bayes; none = plain DQN").values()) == {"bayes"}


@pytest.fixture(scope="module")
def train_options() -> str:
    """`train.py --help`'s options, as one line."""
    answer = call("train.py", "--help")
    assert answer.returncode == 0
    return " ".join(answer.stdout.split("options:", 1)[1].split())


@pytest.mark.parametrize("flag, field", HELP_DEFAULTS.items())
def test_train_help_states_each_presets_default(train_options, flag, field):
    described = train_options[train_options.index(f" {flag} ") :]
    assert "(default: " in described, f"{flag}: no default stated"
    stated = stated_per_preset(described.split("(default: ", 1)[1].split(")", 1)[0])
    assert stated == {name: str(getattr(Config.for_task(name), field)) for name in TASKS}


def limit_of(name: str) -> int:
    return TASKS[name].max_steps


def check_row(presets: list[str], setting: str, earlier: dict[str, str]) -> None:
    """One table row's stated figures against each of its presets (`as `acrobot``: that row's too)."""
    if as_row := re.search(r"as `([\w-]+)`", setting):
        setting += " " + earlier[as_row[1]]
    for name in presets:
        config = Config.for_task(name)
        if limits := re.search(r"(\d+)-step limits? \((\w+) (\d+)\)", setting):  # "1000-step limits (Freeway 2500)"
            expected = int(limits[3]) if limits[2].lower() in name else int(limits[1])
            assert limit_of(name) == expected, (name, setting)
        elif limit := re.search(r"(\d+)-step limit|runs to (\d+) steps", setting):
            assert limit_of(name) == int(limit[1] or limit[2]), (name, setting)
        if episodes := re.search(r"(\d+) demo(?:nstrated)? episodes", setting):
            assert config.demo_episodes == int(episodes[1]), (name, setting)
        if budget := re.search(r"(\d+)k steps", setting):
            assert config.total_steps == int(budget[1]) * 1000, (name, setting)
        if "no early stop" in setting:
            assert config.early_stop_window == 0, (name, setting)
        if stop := re.search(r"stops once (\d+) episodes in a row return ≥ (\d+)", setting):
            assert config.early_stop_window == int(stop[1]), (name, setting)
            assert config.early_stop_fraction * limit_of(name) == pytest.approx(int(stop[2])), (name, setting)
        if solved := re.search(r"solved at (−?\d+)", setting):
            assert TASKS[name].solved_return == float(solved[1].replace("−", "-")), (name, setting)


def task_rows(text: str) -> list[tuple[list[str], str]]:
    """The rows of every table whose first column names presets: (presets, the row's last cell)."""
    rows = []
    for line in text.splitlines():
        cells = [cell.strip() for cell in line.strip().strip("|").split("|")] if line.startswith("| `") else []
        presets = re.findall(r"`([\w-]+)`", cells[0]) if cells else []
        if presets and all(name in TASKS for name in presets):
            rows.append((presets, cells[-1]))
    return rows


@pytest.mark.parametrize("page", ["README.md", "docs/TASKS.md"])
def test_the_task_tables_state_the_presets_limits_budgets_and_stops(page):
    rows = task_rows((REPO / page).read_text())
    assert {name for presets, _ in rows for name in presets} >= {"cartpole", "mountaincar", "acrobot", "lunarlander"}
    earlier: dict[str, str] = {}
    checked = 0
    for presets, setting in rows:
        check_row(presets, setting, earlier)
        earlier.update(dict.fromkeys(presets, setting))
        checked += bool(re.search(r"step limit|demo(?:nstrated)? episodes|k steps|runs to", setting))
    assert checked >= 5
