"""The lab's names and defaults its command line offers, in a module that imports nothing: `--help`
and a wrong name answer before TensorFlow loads, and sweep.py runs by the same values."""

from __future__ import annotations

BACKENDS = ("local", "ray")
"""Where a sweep's runs execute (`run --backend`): a local process pool, or Ray."""
RUNS_PER_WORKER = 25
"""Runs a worker process takes in turn before it retires and a fresh one takes its place (as
`multiprocessing.Pool(maxtasksperchild=…)`): TensorFlow's import is paid once per worker,
not once per run, and whatever a run leaves behind in the process is bounded."""
