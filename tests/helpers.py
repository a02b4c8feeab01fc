"""The package's commands called in the test's own process, as their console scripts call them
(`cli.run`: one-line errors and exit codes). A test that needs a command's answer, or a finished
run, pays no new Python process and no second TensorFlow import; a subprocess stays where the
process itself is what a test is about (a kill, a lock between processes, imports, a fresh registry):
`command` runs one as a user types it. And what a refused command must leave: one line on stderr,
and the user's directory as it was (`one_line`, `assert_refused`, `tree`, `left_in`)."""

import contextlib
import io
import json
import os
import signal
import subprocess
import sys
import warnings
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import gymnasium as gym
import pytest

from dqfd_bc_keras.commands import cli
from dqfd_bc_keras.commands.demos import main as demos_main
from dqfd_bc_keras.commands.evaluate import main as evaluate_main
from dqfd_bc_keras.commands.train import main as train_main
from dqfd_bc_keras.core.methods import METHODS
from dqfd_bc_keras.envs import make
from dqfd_bc_keras.experiments.__main__ import main as lab_main
from dqfd_bc_keras.experiments.lab_settings import LAB_SETTINGS
from dqfd_bc_keras.experiments.suites import SUITES
from dqfd_bc_keras.tasks import TASKS
from studies.minatar_study import main as minatar_study_main
from studies.past_teacher import main as past_teacher_main
from studies.past_teacher_vector import main as past_teacher_vector_main
from studies.pixels import main as pixels_main
from studies.tuned import main as tuned_main
from studies.tuned_presets import main as tuned_presets_main

REPO = Path(__file__).resolve().parents[1]
PROGRAMS: dict[str, Callable[[Sequence[str] | None], int]] = {
    "train.py": train_main,
    "dqfd-train": train_main,
    "evaluate.py": evaluate_main,
    "dqfd-evaluate": evaluate_main,
    "dqfd_bc_keras.demos": demos_main,
    "dqfd_bc_keras.experiments": lab_main,
    "studies.pixels": pixels_main,
    "studies.minatar_study": minatar_study_main,
    "studies.past_teacher": past_teacher_main,
    "studies.past_teacher_vector": past_teacher_vector_main,
    "studies.tuned": tuned_main,
    "studies.tuned_presets": tuned_presets_main,
}
"""Each command by the names a user types it (a script, a console script, a `python -m` module)."""
PROCESS_CACHES = (make.env_task, make._task_spaces, make._own_limit)
"""What the package remembers for the rest of its process: each env's task and spaces, and with them
the warnings said once while working them out. A command answered by `call` starts without them, as
it would in a process of its own."""


@dataclass
class Answer:
    """What a command answered: its exit code, stdout and stderr (and, run with `-X importtime`, the
    modules it imported)."""

    returncode: int
    stdout: str
    stderr: str
    imports: list[str] = field(default_factory=list)


def call(program: str, *args: object, cwd: Path = REPO, path: Sequence[Path] = ()) -> Answer:
    """`program ARGS` (a name of `PROGRAMS`) answered in this process as its own process would answer
    it, typed in `cwd` (the repository, as `python train.py` is) with `path` first on PYTHONPATH: what
    `cli.run` returns (or the code an argparse error exits with) and what it printed. It sees its own
    argv and shows each warning once, as in a new process; what it imported from `path` or registered
    is forgotten when it ends."""
    argv = [str(arg) for arg in args]
    out, err = io.StringIO(), io.StringIO()
    for cache in PROCESS_CACHES:
        cache.cache_clear()
    with pytest.MonkeyPatch.context() as process, forgetting(*path), warnings.catch_warnings():
        process.setattr(sys, "argv", [program, *argv])
        process.chdir(cwd)
        for directory in reversed(path):
            process.syspath_prepend(str(directory))
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = cli.run(PROGRAMS[program], argv)
            except SystemExit as exit:
                code = exit.code
    return Answer(code, out.getvalue(), err.getvalue())


def python(*args: object, cwd: Path = REPO, path: Sequence[Path] = ()) -> Answer:
    """What `python ARGS` answers, typed as a user types it (`train.py …`, `-m dqfd_bc_keras.demos …`),
    answered in this process by `call`."""
    first, *rest = map(str, args)
    program, *rest = rest if first == "-m" else [first, *rest]
    return call(program, *rest, cwd=cwd, path=path)


REGISTRIES = (METHODS, TASKS, SUITES, LAB_SETTINGS)
"""What a user's module (or a test) adds to by registering a method, preset, suite or lab setting."""


def entry_module(spec: gym.envs.registration.EnvSpec) -> str:
    """The module that defines a Gymnasium id's env."""
    entry = spec.entry_point
    return entry.partition(":")[0] if isinstance(entry, str) else getattr(entry, "__module__", "")


@contextlib.contextmanager
def forgetting(*directories: Path) -> Iterator[None]:
    """After the block, the registries and the SIGTERM handler (`cli.run` installs its own) as they
    were before it, and the modules it imported from `directories` forgotten with the Gymnasium ids they
    registered: what a process that ran the block would take with it when it ends. (Ids a package
    registers on its first import stay, with the package.)"""
    registered = [dict(registry) for registry in REGISTRIES]
    modules, env_ids = set(sys.modules), set(gym.registry)
    on_sigterm = signal.getsignal(signal.SIGTERM)
    try:
        yield
    finally:
        for registry, before in zip(REGISTRIES, registered, strict=True):
            registry.clear()
            registry.update(before)
        users = {
            name
            for name in set(sys.modules) - modules
            if (getattr(sys.modules[name], "__file__", None) or "").startswith(tuple(map(str, directories)))
        }
        for name in users:
            del sys.modules[name]
        for env_id in set(gym.registry) - env_ids:
            if entry_module(gym.registry[env_id]) in users:
                del gym.registry[env_id]
        signal.signal(signal.SIGTERM, on_sigterm)


TINY_SWEEP = [
    arg
    for setting in (
        "total_steps=100",
        "pretrain_steps=10",
        "eval_every=50",
        "checkpoint_every=50",
        "demo_episodes=1",
        "eval_episodes=1",
        "final_eval_episodes=1",
        "bc_epochs=1",
    )
    for arg in ("--set", setting)
]
"""`--set` flags that make each run of a sweep a few seconds: 100 interactions, one episode of everything."""


# --- a command in a process of its own, and what a refusal leaves ---

ENV = {**os.environ, "PYTHONPATH": str(REPO)}
"""The environment of a command run as its own process: the repository importable, as if installed."""


NO_TENSORFLOW = 'raise ImportError("tensorflow is blocked by the test")\n'
"""A `tensorflow` package first on the path: a command that imports TensorFlow fails with this."""


def command(*args: object, cwd: Path = REPO, path: Sequence[str | Path] = (), block_tensorflow: bool = False) -> Answer:
    """`python -X importtime ARGS` run in `cwd` as a user types it: a first argument `NAME.py` is the
    repository's script; `path`, then the repository, on PYTHONPATH; with `block_tensorflow`, a
    `tensorflow` first on the path that cannot be imported (written to `cwd`/no_tensorflow)."""
    if block_tensorflow:
        blocker = cwd / "no_tensorflow"
        (blocker / "tensorflow").mkdir(parents=True, exist_ok=True)
        (blocker / "tensorflow" / "__init__.py").write_text(NO_TENSORFLOW)
        path = [blocker, *path]
    first, *rest = map(str, args)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(map(str, [*path, REPO]))}
    done = subprocess.run(
        [sys.executable, "-X", "importtime", str(REPO / first) if first.endswith(".py") else first, *rest],
        capture_output=True,
        text=True,
        cwd=cwd,
        env=env,
        timeout=600,
    )
    lines = done.stderr.splitlines(keepends=True)
    timed = [line.split("|")[-1].rstrip("\n") for line in lines if line.startswith("import time:")]
    own = [
        line for line in lines if not line.startswith("import time:") and "A.L.E" not in line and "Stella" not in line
    ]
    return Answer(done.returncode, done.stdout, "".join(own), timed[1:])  # timed[0] is importtime's header


def importers(timings: list[str], module: str) -> list[str]:
    """The modules that imported `module`, innermost first: importtime prints a module when its
    import ends, indented by depth, so its importers are the next lines of smaller depth."""
    names = [(len(t) - len(t.lstrip()), t.strip()) for t in timings]
    first = next((i for i, (_, name) in enumerate(names) if name == module), None)
    if first is None:
        return []
    chain, depth = [], names[first][0]
    for indent, name in names[first + 1 :]:
        if indent < depth:
            chain.append(name)
            depth = indent
    return chain


def assert_refused(done: Answer, message: str) -> None:
    """Exit code 2, nothing on stdout, and `message` as the one line on stderr."""
    assert (done.returncode, done.stdout, done.stderr) == (2, "", message + "\n"), done.stderr


def assert_without_tensorflow(done: Answer) -> None:
    """The command answered before TensorFlow: importtime timed its imports, and none was TensorFlow."""
    assert done.imports, "importtime timed no import"
    assert "tensorflow" not in [name.strip() for name in done.imports], (
        f"TensorFlow imported by {importers(done.imports, 'tensorflow')}"
    )


def left_in(directory: Path) -> list[str]:
    """What `directory` holds, by name, besides the test's TensorFlow blocker and Python's bytecode cache."""
    return sorted({p.name for p in directory.iterdir()} - {"no_tensorflow", "__pycache__"})


def one_line(capsys, code, message, expected_code=2):
    """What `capsys` caught on stderr, checked to be one line holding `message`, after the exit `code`."""
    err = capsys.readouterr().err
    assert code == expected_code, err
    assert message in err, err
    assert len(err.strip().splitlines()) == 1, err
    return err


def tree(path: Path) -> dict:
    """Every file under `path` and its bytes: to show that a failure damaged nothing."""
    return {str(p.relative_to(path)): p.read_bytes() for p in sorted(path.rglob("*")) if p.is_file()}


def latest_checkpoint(run: Path) -> Path:
    """The directory of the run's current checkpoint, as checkpoints/latest.json names it."""
    return run / "checkpoints" / json.loads((run / "checkpoints" / "latest.json").read_text())["dir"]


TINY_RUN = ["--quick", "--quiet", "--set", "total_steps=300", "--set", "pretrain_steps=10"]
"""A run of a few seconds: one checkpoint after ckpt-0, one evaluation."""
LAB = ("-m", "dqfd_bc_keras.experiments")
DEMOS = ("-m", "dqfd_bc_keras.demos")
"""The lab's and the demonstrations' commands, as `python -m` runs them."""
