"""The package as a user installs it: a wheel built from the sources, installed outside the
repository, run from another directory (no checkout on the path)."""

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
from test_cli import Done, assert_answered_without_tensorflow

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[1]
PACKAGE = REPO / "dqfd_bc_keras"


def build_debris() -> set[Path]:
    """What a build writes into a source tree; a checkout installed with `pip install -e .` (the
    README's quick start) already holds an egg-info, so the test compares, not expects none."""
    return {*REPO.glob("build"), *REPO.glob("*.egg-info")}


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """A wheel built offline from a copy of the sources as a checkout holds them (the package, the
    studies, tests, benchmarks, scripts; the build writes nothing into the checkout), installed with
    --target; the environment runs it without the checkout."""
    root = tmp_path_factory.mktemp("package")
    built_before = build_debris()
    source = root / "source"
    for name in ("dqfd_bc_keras", "studies", "tests", "benchmarks"):
        shutil.copytree(REPO / name, source / name, ignore=shutil.ignore_patterns("__pycache__", "results"))
    for path in [*REPO.glob("*.py"), *REPO.glob("docs/*.py"), REPO / "pyproject.toml", REPO / "requirements.txt"]:
        (source / path.relative_to(REPO)).parent.mkdir(exist_ok=True)
        shutil.copy(path, source / path.relative_to(REPO))
    pip = [sys.executable, "-m", "pip", "-q", "--disable-pip-version-check"]
    subprocess.run(
        [*pip, "wheel", "--no-deps", "--no-build-isolation", "-w", root / "dist", source],
        check=True,
        capture_output=True,
        timeout=300,
    )
    [wheel] = (root / "dist").glob("*.whl")
    subprocess.run(
        [*pip, "install", "--no-deps", "--target", root / "site", wheel], check=True, capture_output=True, timeout=300
    )
    assert build_debris() == built_before  # the build wrote nothing into the checkout
    elsewhere = root / "elsewhere"
    elsewhere.mkdir()
    env = {**{k: v for k, v in os.environ.items() if k != "PYTHONPATH"}, "PYTHONPATH": str(root / "site")}
    return wheel, root / "site", elsewhere, env


def test_the_wheel_holds_every_module_of_every_subpackage(installed):
    wheel = installed[0]
    names = set(zipfile.ZipFile(wheel).namelist())
    modules = {p.relative_to(REPO).as_posix() for p in PACKAGE.rglob("*.py") if "__pycache__" not in p.parts}
    assert {"dqfd_bc_keras/experiments/__init__.py", "dqfd_bc_keras/commands/__init__.py"} <= modules
    assert modules <= names, sorted(modules - names)
    entry_points = next(n for n in names if n.endswith("entry_points.txt"))
    scripts = zipfile.ZipFile(wheel).read(entry_points).decode()
    assert "dqfd-train = dqfd_bc_keras.commands.train:cli" in scripts
    assert "dqfd-evaluate = dqfd_bc_keras.commands.evaluate:cli" in scripts


def test_the_wheel_holds_the_library_and_the_labs_engine_only(installed):
    """Built from a tree that also holds studies/, tests/, benchmarks/ and scripts, the wheel holds
    `dqfd_bc_keras/**` and its metadata: no study (docs/EXPERIMENTS.md's studies run from a checkout)."""
    names = zipfile.ZipFile(installed[0]).namelist()
    outside = [n for n in names if n.split("/")[0] != "dqfd_bc_keras" and ".dist-info/" not in n]
    assert outside == []
    assert not [n for n in names if any(s in n for s in ("studies", "minatar_study", "sb3_pixels", "sigma0.py"))]
    assert "dqfd_bc_keras/experiments/sweep.py" in names and "dqfd_bc_keras/experiments/report.py" in names


def test_installed_commands_train_and_evaluate_outside_the_repository(installed):
    _, site, elsewhere, env = installed

    def run(*args):
        return subprocess.run([*map(str, args)], capture_output=True, text=True, cwd=elsewhere, env=env, timeout=600)

    where = run(sys.executable, "-c", "import dqfd_bc_keras; print(dqfd_bc_keras.__file__)")
    assert where.stdout.strip() == str(site / "dqfd_bc_keras" / "__init__.py"), where.stderr
    lab = run(sys.executable, "-m", "dqfd_bc_keras.experiments", "--help")
    assert lab.returncode == 0 and "efficiency" in lab.stdout and "report" in lab.stdout, lab.stderr
    trained = run(site / "bin" / "dqfd-train", "--quick", "--out", elsewhere / "run")
    assert trained.returncode == 0, trained.stderr
    assert "interactions in all" in trained.stdout and (elsewhere / "run" / "q_network.keras").is_file()
    evaluated = run(site / "bin" / "dqfd-evaluate", elsewhere / "run", "--episodes", 2)
    assert evaluated.returncode == 0, evaluated.stderr
    assert "cartpole (CartPole-v1), q policy, 2 greedy episodes" in evaluated.stdout


@pytest.mark.parametrize(
    "script, args, code",
    [
        ("dqfd-evaluate", ["--help"], 0),
        ("dqfd-evaluate", ["run", "--episodes", "0"], 2),
        ("dqfd-train", ["--help"], 0),
        ("dqfd-train", ["--task", "CartPole-v1"], 2),
    ],
)
def test_installed_commands_answer_help_and_errors_before_tensorflow(installed, script, args, code):
    _, site, elsewhere, env = installed
    done = Done(site / "bin" / script, *args, cwd=elsewhere, env=env)
    assert done.code == code and (done.stdout.startswith(f"usage: {script}") or done.stderr[0].startswith(script))
    assert_answered_without_tensorflow(done)
