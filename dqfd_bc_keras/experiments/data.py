"""Run directories as the lab reads them: each complete run parsed into a `FinishedRun`."""

from __future__ import annotations

import csv
import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..config import Config
from ..errors import ConfigError


@dataclass
class FinishedRun:
    """One complete run directory, parsed: what every table and figure of the lab reads."""

    path: Path
    config: Config
    metrics: list[dict]
    evals: list[dict]
    final: dict

    def column(self, name: str) -> np.ndarray:
        return np.array([row[name] for row in self.metrics], dtype=float)


def _read_csv(path: Path) -> list[dict]:
    if not path.is_file():
        return []
    with path.open(newline="") as f:
        return [{k: float(v) if v != "" else None for k, v in row.items()} for row in csv.DictReader(f)]


def load_runs(suite_dir: str | os.PathLike) -> list[FinishedRun]:
    """Every complete run (one with eval.json) below `suite_dir`, in path order."""
    runs = []
    for final in sorted(Path(suite_dir).rglob("eval.json")):
        path = final.parent
        if (path / "config.json").is_file() and (path / "metrics.csv").is_file():
            try:
                config = Config.from_dict(json.loads((path / "config.json").read_text()))
            except (ConfigError, json.JSONDecodeError) as error:
                raise ConfigError(f"{path / 'config.json'}: {error}") from None
            runs.append(FinishedRun(path, config, _read_csv(path / "metrics.csv"), _read_csv(path / "evals.csv"),
                                  json.loads(final.read_text())))
    return runs
