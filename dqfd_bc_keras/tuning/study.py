"""`tune`: an Optuna study of one method on one task, in a storage many processes can share.

A study is named and stored (`storage`: a SQLite file under `out` by default; any URL Optuna
takes, so a PostgreSQL or MySQL server shares it across machines; a `.log` path, a journal file,
where SQLite's locking is not enough). It records what it tunes (the task, its env settings, the
demonstrations, the method, the metric, the budget, the seeds, the fixed fields): the same command
run again continues it, and a command that would tune something else with it is refused. Each
worker (a process here, or a Ray task) takes trials until the study holds `trials` of them
complete, pruned or under way; a trial stopped by Ctrl-C or SIGTERM is marked failed, never left
running, and its run directories keep their last checkpoints.
"""

from __future__ import annotations

import json
import time
import uuid
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from dqfd_bc_keras.core.config import QUICK, Config
from dqfd_bc_keras.envs.make import get_task, task_slug
from dqfd_bc_keras.errors import ConfigError, one_line
from dqfd_bc_keras.experiments.names import BACKENDS
from dqfd_bc_keras.files import read_json, write_text
from dqfd_bc_keras.seeds import TUNE_SEED
from dqfd_bc_keras.tuning.objective import METRICS
from dqfd_bc_keras.tuning.space import as_json, check_space, study_space

if TYPE_CHECKING:
    import optuna

SAMPLERS = ("tpe", "random", "cmaes")
PRUNERS = ("median", "hyperband", "none")
FAILURES_IN_A_ROW = 3
"""Trials failed one after the other before a worker gives up: a failure that is not the params'
(a missing file, a broken env) fails every trial alike."""


@dataclass(frozen=True)
class TuneSettings:
    """One study: what it tunes, how it searches, where it keeps what it finds."""

    out: Path
    task: str = "cartpole"
    """A preset, or any Gymnasium env id (with `env_kwargs` and `max_steps` as train.py takes them)."""
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    max_steps: int | None = None
    demos: str | None = None
    """A .npz file or minari:ID, or who demonstrates (train.py's --demos or --expert)."""
    expert_loss: str = "bayes"
    trials: int = 20
    """Trials the study holds when done (complete, pruned or under way): run again with more for more."""
    study_name: str | None = None
    """Default: TASK-METHOD-METRIC."""
    storage: str | None = None
    """Default: sqlite:///OUT/study.db."""
    seeds: int = 1
    """K: each trial's value is the mean over seeds TUNE_SEED … TUNE_SEED + K − 1."""
    steps: int | None = None
    """Each run's budget of env steps (default: the task's total_steps)."""
    metric: str = "auc"
    threshold: float | None = None
    """The `threshold` metric's return (default: the task's solved return)."""
    sampler: str = "tpe"
    pruner: str = "median"
    workers: int = 2
    backend: str = "local"
    address: str | None = None
    space_file: str | None = None
    fixed: dict[str, Any] = field(default_factory=dict)
    """Config fields every trial keeps (`--set`), out of the search."""
    quick: bool = False
    """The quick budget (train.py --quick), for tests."""

    def __post_init__(self) -> None:
        for name, value, allowed in (
            ("metric", self.metric, tuple(METRICS)),
            ("sampler", self.sampler, SAMPLERS),
            ("pruner", self.pruner, PRUNERS),
            ("backend", self.backend, BACKENDS),
        ):
            if value not in allowed:
                raise ConfigError(f"{name}={value!r} is not one of {allowed}")
        for name in ("trials", "seeds", "workers"):
            if not isinstance(getattr(self, name), int) or getattr(self, name) < 1:
                raise ConfigError(f"{name} must be a positive integer, got {getattr(self, name)!r}")
        object.__setattr__(self, "out", Path(self.out))
        if self.metric == "threshold" and self.threshold is None:
            solved = get_task(self.task).solved_return
            if solved is None:
                raise ConfigError(f"{self.task} sets no solved return: --metric threshold needs --threshold R")
            object.__setattr__(self, "threshold", float(solved))

    @property
    def name(self) -> str:
        return self.study_name or f"{task_slug(self.task)}-{self.expert_loss}-{self.metric}"

    @property
    def storage_url(self) -> str:
        return self.storage or f"sqlite:///{(self.out / 'study.db').resolve()}"

    @property
    def seed_list(self) -> list[int]:
        return [TUNE_SEED + k for k in range(self.seeds)]

    @property
    def trials_dir(self) -> Path:
        return self.out / "trials"

    def run_fields(self) -> dict[str, Any]:
        """The Config fields every trial's runs share (the budget, the env settings, `fixed`)."""
        quick = {**QUICK, **get_task(self.task).quick} if self.quick else {}
        env = {"env_kwargs": self.env_kwargs} if self.env_kwargs else {}
        limit = {"max_steps": self.max_steps} if self.max_steps is not None else {}
        steps = {"total_steps": self.steps} if self.steps is not None else {}
        return {**quick, **env, **limit, **steps, **self.fixed}

    def identity(self, fixed: dict[str, Any]) -> dict[str, Any]:
        """What the study tunes: a command asking any of it otherwise is refused on this study."""
        return {
            "task": self.task,
            "demos": self.demos,
            "expert_loss": self.expert_loss,
            "metric": self.metric,
            "threshold": self.threshold,
            "seeds": self.seed_list,
            "fixed": fixed,
        }


def open_storage(url: str) -> optuna.storages.BaseStorage:
    """The storage `url` names: a `.log` path is a journal file, anything else a database URL
    (SQLite waits up to a minute for another process's write). A URL that cannot be opened is a ConfigError."""
    import optuna

    if "://" not in url and not url.endswith(".log"):
        raise ConfigError(
            f"--storage {url}: expected a database URL (sqlite:///study.db, postgresql://…) or a journal "
            "file's path ending in .log"
        )
    if "://" not in url:
        from optuna.storages.journal import JournalFileBackend

        Path(url).parent.mkdir(parents=True, exist_ok=True)
        return optuna.storages.JournalStorage(JournalFileBackend(url))
    if url.startswith("sqlite:///"):
        Path(url.removeprefix("sqlite:///")).parent.mkdir(parents=True, exist_ok=True)
    engine = {"connect_args": {"timeout": 60}} if url.startswith("sqlite") else {}
    attempt = 1
    while True:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter(
                    "ignore", optuna.exceptions.ExperimentalWarning
                )  # the heartbeat, since Optuna 2.9
                return optuna.storages.RDBStorage(url, engine_kwargs=engine, heartbeat_interval=30, grace_period=120)
        except Exception as error:  # sqlalchemy's and the drivers' errors have no common base a user would know
            if isinstance(error, ImportError):  # the URL's driver, which no requirement installs
                raise ConfigError(f"--storage {url}: {one_line(error)} ({DRIVERS})") from None
            if not lost_the_race(error) or attempt == CREATE_ATTEMPTS:
                raise ConfigError(f"--storage {url}: {one_line(error)}") from None
        time.sleep(0.5 * attempt)  # another process made the tables first: they are there now
        attempt += 1


DRIVERS = (
    "a server's URL needs its driver: pip install 'psycopg[binary]' for postgresql://, psycopg2-binary for "
    "postgresql+psycopg2://, PyMySQL for mysql+pymysql://"
)
CREATE_ATTEMPTS = 5
"""Processes that open a new database at once race to create Optuna's tables; the losers open it
again once the winner has."""


def lost_the_race(error: Exception) -> bool:
    """Whether opening a new database failed because another process was creating its tables:
    SQLAlchemy's create_all checks, then creates, so a loser sees an IntegrityError (the version row)
    or an OperationalError "table ... already exists"."""
    kind = type(error).__name__
    return kind == "IntegrityError" or (kind == "OperationalError" and "already exists" in str(error))


def sampler(name: str) -> optuna.samplers.BaseSampler:
    import optuna

    if name == "random":
        return optuna.samplers.RandomSampler()
    if name == "cmaes":
        return optuna.samplers.CmaEsSampler(warn_independent_sampling=False)
    return optuna.samplers.TPESampler()


def pruner(name: str, steps: int) -> optuna.pruners.BasePruner:
    """`steps`: the intermediate values one trial reports (its seeds × its evaluations)."""
    import optuna

    if name == "median":
        return optuna.pruners.MedianPruner(n_startup_trials=5, n_warmup_steps=1)
    if name == "hyperband":
        return optuna.pruners.HyperbandPruner(min_resource=1, max_resource=steps, reduction_factor=3)
    return optuna.pruners.NopPruner()


@dataclass(frozen=True)
class Prepared:
    """A study checked and created or found: what each worker needs to take its trials."""

    settings: TuneSettings
    space: dict
    fixed: dict[str, Any]
    runner: str

    def study(self) -> optuna.Study:
        import optuna

        s = self.settings
        config = Config.for_task(s.task, **self.fixed)
        steps = s.seeds * (config.total_steps // config.eval_every + 1)
        return optuna.load_study(
            study_name=s.name,
            storage=open_storage(s.storage_url),
            sampler=sampler(s.sampler),
            pruner=pruner(s.pruner, steps),
        )


def prepare(settings: TuneSettings) -> Prepared:
    """Check everything a trial needs, then create the study, or find it and check that it tunes
    what `settings` asks (else a ConfigError naming what differs)."""
    import optuna

    fixed = settings.run_fields()
    space, fixed = study_space(settings.expert_loss, fixed, settings.space_file)
    check_space(settings.task, space, {**fixed, "expert_loss": settings.expert_loss, **_demonstrator(settings.demos)})
    if not space:
        raise ConfigError("the search space is empty: every field is fixed")
    _check_runs(settings, fixed)
    claimed = _check_out(settings)
    optuna.logging.set_verbosity(optuna.logging.ERROR)  # a line of ours per trial says what Optuna would
    storage = open_storage(settings.storage_url)
    identity = settings.identity(fixed)
    direction = METRICS[settings.metric].direction
    study = optuna.create_study(study_name=settings.name, storage=storage, direction=direction, load_if_exists=True)
    recorded = study.user_attrs.get("tunes")
    if recorded is None:
        study.set_user_attr("tunes", identity)
    elif recorded != _as_stored(identity):
        differ = _differences(recorded, _as_stored(identity))
        raise ConfigError(
            f"study {settings.name!r} in {settings.storage_url} tunes something else ({'; '.join(differ)}): "
            "choose another --study-name, or ask what it tunes"
        )
    if not claimed:  # once the study is there: a refused command leaves --out as it was
        settings.out.mkdir(parents=True, exist_ok=True)
        write_text(settings.out / STUDY_FILE, json.dumps(_out_record(settings)) + "\n")
    if study.user_attrs.get("space") != _as_stored(as_json(space)):  # a study read again is left as it was
        study.set_user_attr("space", as_json(space))
    return Prepared(settings, space, fixed, uuid.uuid4().hex[:12])


STUDY_FILE = "study.json"
"""In `--out`: the study whose trials the directory holds (its name, and its storage as given)."""


def _check_out(settings: TuneSettings) -> bool:
    """`--out` holds one study's trials (their directories are named by trial number): a command
    for another study there is refused. True if `--out` holds this study's already."""
    marker = settings.out / STUDY_FILE
    if not marker.is_file():
        return False
    try:
        theirs = read_json(marker, "study file")
    except ConfigError as error:
        raise ConfigError(f"{error}; is {settings.out} a study's?") from None
    if theirs != _out_record(settings):
        raise ConfigError(
            f"{settings.out} holds the trials of study {theirs.get('study')!r} (storage "
            f"{theirs.get('storage') or 'its study.db'}); give this study its own --out"
        )
    return True


def _out_record(settings: TuneSettings) -> dict[str, Any]:
    """What --out/study.json says: the study's name and its storage as given (None: --out's study.db)."""
    return {"study": settings.name, "storage": settings.storage}


def _check_runs(settings: TuneSettings, fixed: dict[str, Any]) -> None:
    """What every trial makes, made once and dropped before any trial: a `DQfD` of the study's fixed
    settings (its env, its demonstrator answering, its demonstrations read). A study whose every
    trial would fail the same way is refused here, in one line."""
    import keras

    from dqfd_bc_keras.model import DQfD

    DQfD(settings.task, settings.demos, expert_loss=settings.expert_loss, seed=TUNE_SEED, **fixed)
    keras.backend.clear_session()


def _demonstrator(demos: str | None) -> dict[str, str]:
    """The `expert` field a run of `demos` gets: who demonstrates, or where given demonstrations came from."""
    from dqfd_bc_keras.arguments import is_demo_source
    from dqfd_bc_keras.demos import GIVEN

    if demos is None:
        return {}
    return {"expert": f"{GIVEN}{demos}" if is_demo_source(demos) else demos}


def _differences(theirs: dict[str, Any], ours: dict[str, Any], prefix: str = "") -> list[str]:
    """What a study tunes against what a command asks, key by key (into the fixed fields)."""
    said = []
    for key in sorted(set(theirs) | set(ours)):
        a, b = theirs.get(key), ours.get(key)
        if isinstance(a, dict) and isinstance(b, dict):
            said += _differences(a, b, f"{prefix}{key} ")
        elif a != b:
            said.append(f"{prefix}{key}: the study's {a!r}, asked {b!r}")
    return said


def _as_stored(value: Any) -> Any:
    """`value` as the storage gives it back (JSON: tuples as lists)."""
    return json.loads(json.dumps(value))
