"""docs/EXTENDING.md's three recipes, performed as the doc writes them: a user's own method, task preset
and suite, each in a module of their own outside the package. The modules are the doc's python blocks
and the commands its bash blocks, read from the doc when the tests run, so the tests follow the doc
when it changes. Each recipe runs in tmp_path (the user's directory, where the modules are written)
with the repository on PYTHONPATH, standing in for the installed package; the doc's own `PYTHONPATH=.`
adds tmp_path. Each command runs in a process of its own, as the user types it: `dqfd-train` and
`dqfd-evaluate` as the repository's train.py and evaluate.py (the same programs as the entry points).

Budgets: the method's commands are the doc's as written (`--quick`, and evaluate's 100 episodes of a
quick run); the preset's training gets `--quick` (the doc's preset trains 20,000 steps); the suite's
run gets `--seeds 1` and a run of seconds (the doc's suite is 3 arms × 5 seeds of full runs).

The doc also shows the plug-in contract's Protocols, as excerpts of the package (`# from PATH`): each
is checked against the module it quotes."""

import csv
import json
import os
import re
import runpy
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import tensorflow as tf
from helpers import TINY_SWEEP

from dqfd_bc_keras.core import expert_terms, reference
from dqfd_bc_keras.core.agent import make_agent
from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.core.methods import TermAgent, TermBatch

REPO = Path(__file__).resolve().parents[1]
DOC = REPO / "docs" / "EXTENDING.md"
PROGRAMS = {
    "dqfd-train": [sys.executable, str(REPO / "train.py")],
    "dqfd-evaluate": [sys.executable, str(REPO / "evaluate.py")],
    "python": [sys.executable],
}
"""The doc's programs as this checkout runs them (the console scripts are train.py and evaluate.py)."""
"""A run of seconds: what the suite recipe needs is its runs, not learning."""


def blocks(text: str) -> list[tuple[str, str]]:
    """(language, code) of each fenced python or bash block of `text`."""
    return re.findall(r"^```(python|bash)\n(.*?)^```", text, re.DOTALL | re.MULTILINE)


def recipe(heading: str) -> tuple[dict[str, str], list[str]]:
    """The `## heading` section of the doc: its python blocks by the file each names on its first line
    (`# my_methods.py`; an excerpt of the package, `# from PATH`, is none), and the lines of its bash blocks."""
    section = re.search(rf"^## {re.escape(heading)}\n(.*?)(?=^## |\Z)", DOC.read_text(), re.DOTALL | re.MULTILINE)[1]
    named = [(kind, re.match(r"# (\w+\.py)\n", code), code) for kind, code in blocks(section)]
    modules = {name[1]: code for kind, name, code in named if kind == "python" and name}
    commands = [line for kind, _, code in named if kind == "bash" for line in code.splitlines() if line.strip()]
    assert modules and commands, f"no module or no command in the doc's section {heading!r}"
    return modules, commands


def run(line: str, *extra: str, cwd: Path) -> subprocess.CompletedProcess:
    """One of the doc's command lines, typed in `cwd` in a process of its own as a user types it,
    with `extra` arguments appended; its leading `NAME=VALUE` words set the environment
    (`PYTHONPATH=.`: `cwd`, then the repository, standing in for the installed package)."""
    words = shlex.split(line)
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    while "=" in words[0]:
        name, _, value = words.pop(0).partition("=")
        env[name] = os.pathsep.join([str(cwd / value), str(REPO)]) if name == "PYTHONPATH" else value
    return subprocess.run(
        [*PROGRAMS[words[0]], *words[1:], *extra], cwd=cwd, env=env, capture_output=True, text=True, timeout=900
    )


def write(modules: dict[str, str], where: Path) -> None:
    for name, code in modules.items():
        (where / name).write_text(code)


@pytest.mark.slow
def test_the_method_recipe_trains_and_evaluates_with_the_users_method(tmp_path):
    modules, (train, evaluate) = recipe("A method (an expert loss)")
    write(modules, tmp_path)
    done = run(train, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    out = tmp_path / re.search(r"--out (\S+)", train)[1]
    config = json.loads((out / "config.json").read_text())
    assert config["expert_loss"] == re.search(r"--expert-loss (\S+)", train)[1]  # my_methods:HALF_CE, for --resume
    assert (out / "bc_model.keras").is_file()  # bc_fit="mle": a BC model is fitted, saved and used
    evaluated = run(evaluate, cwd=tmp_path)
    assert evaluated.returncode == 0, evaluated.stderr
    assert "100 greedy episodes" in evaluated.stdout


@pytest.fixture
def users_method(tmp_path, monkeypatch):
    """The doc's method module, importable in this process (conftest forgets it after the test)."""
    modules, _ = recipe("A method (an expert loss)")
    write(modules, tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))


def test_the_recipes_method_is_the_agents_j_e_and_agrees_with_its_reference(users_method, demos, bc_models):
    """The agent's J_E on a batch is the user's term, half of ce's, not a built-in one; the
    recipe's reference formula, as reference.py gives it, computes the same."""
    agent = make_agent(Config.for_task("cartpole", expert_loss="my_methods:HALF_CE"), demos, bc_models["ce"])
    b = agent.replay.sample(8, agent.beta())
    q = tf.constant(agent.q_network(b.obs))
    expected = 0.5 * float(expert_terms.ce(agent, q, b))
    np.testing.assert_allclose(float(reference.expert_reference(agent.config.method)(agent, q, b)), expected, rtol=1e-5)
    agent.reset_metrics()
    agent.train_step(b)
    np.testing.assert_allclose(float(agent.losses_so_far()["expert"]), expected, rtol=1e-5)
    assert expected > 0.0


def test_the_doc_quotes_the_plug_in_protocols_as_the_package_declares_them():
    """Each `# from PATH` excerpt is in PATH line for line, and the doc names every member of the
    agent and of the batch that a term may read."""
    excerpts = [code for _, code in blocks(DOC.read_text()) if code.startswith("# from ")]
    assert len(excerpts) == 2  # the Term, the Rule
    for code in excerpts:
        path, *lines = code.splitlines()
        source = (REPO / path.removeprefix("# from ")).read_text().splitlines()
        assert all(line in source for line in lines), code
    for prefix, protocol in (("agent", TermAgent), ("batch", TermBatch)):
        members = [name for name, value in vars(protocol).items() if isinstance(value, property)]
        assert members and all(f"`{prefix}.{name}`" in DOC.read_text() for name in members), members


@pytest.mark.slow
def test_the_preset_recipe_trains_on_the_users_preset_with_its_only_expert(tmp_path):
    """`--quick` added to the doc's command; evaluating the run, as the doc's introduction says,
    needs the preset's module and plays the plain env."""
    modules, (train,) = recipe("A task preset, or a task family")
    write(modules, tmp_path)
    done = run(train, "--quick", cwd=tmp_path)
    assert (done.returncode, done.stderr) == (0, "")
    (out,) = [path.parent for path in (tmp_path / "runs").glob("*/config.json")]
    config = json.loads((out / "config.json").read_text())
    assert (config["task"], config["expert"]) == (re.search(r"--task (\S+)", train)[1], "lean")
    assert json.loads((out / "demonstrations.json").read_text())["expert"] == "lean"
    with open(out / "metrics.csv") as rows:
        lengths = [int(row["length"]) for row in csv.DictReader(rows)]
    assert lengths and max(lengths) <= 60  # the preset's own step limit, max_steps=60
    evaluated = run(f"PYTHONPATH=. dqfd-evaluate {out}", "--episodes", "2", "--json", cwd=tmp_path)
    assert evaluated.returncode == 0, evaluated.stderr
    assert max(json.loads(evaluated.stdout)["lengths"]) <= 500  # scored on the plain CartPole-v1


@pytest.mark.slow
def test_the_suite_recipe_runs_its_arms_and_reports_them(tmp_path):
    """`--seeds 1` and a run of seconds added to the doc's `run`; its `report` as written. What each
    arm should be is read from the doc's module (the SIGMAS arms)."""
    modules, (sweep, report) = recipe("A suite of runs")
    write(modules, tmp_path)
    module, _, name = re.search(r" run (\S+)", sweep)[1].partition(":")
    arms = runpy.run_path(str(tmp_path / f"{module}.py"))[name]
    done = run(sweep, "--seeds", "1", *TINY_SWEEP, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines()[0] == (
        f"{module}:{name}: {len(arms)} runs, 0 already complete, {len(arms)} to run on 2 local worker(s)"
    )
    results = tmp_path / re.search(r"--out (\S+)", sweep)[1]
    configs = [json.loads(p.read_text()) for p in results.glob("*/seed0/config.json")]
    assert arms and len(configs) == len(list(results.glob("*/seed0/complete.json"))) == len(arms)
    varied = {k for arm in arms for k, _ in arm.overrides}  # sigma0_sq (an arm at the default sets none)
    wanted = [{k: getattr(arm.config(0), k) for k in ("task", "timeout", "expert_loss", *varied)} for arm in arms]
    for arm in wanted:  # one finished run per arm, with the arm's task, loss and fields
        assert [all(c[k] == v for k, v in arm.items()) for c in configs].count(True) == 1, arm
    reported = run(report, cwd=tmp_path)
    assert reported.returncode == 0, reported.stderr
    with open(results / "per_seed.csv") as rows:
        named = [row["arm"] for row in csv.DictReader(rows)]
    for arm in wanted:  # one row per arm, named by the fields the arms differ in (e.g. bayes sigma0_sq=0.1)
        assert [all(f"{k}={arm[k]}" in n for k in varied) for n in named].count(True) == 1, arm
    assert len(named) == len(arms)
    assert all(f"| {n} |" in (results / "RESULTS.md").read_text() for n in named)
