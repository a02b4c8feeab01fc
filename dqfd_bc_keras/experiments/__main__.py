"""The lab's command line: `python -m dqfd_bc_keras.experiments run|report …`."""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path

from ..cli import ArgumentParser, positive_int, run
from ..errors import ConfigError
from .suites import ALL, BACKENDS, SUITES, run_suite


def main(argv: Sequence[str] | None = None) -> int:
    parser = ArgumentParser(prog="python -m dqfd_bc_keras.experiments", description=__doc__)
    commands = parser.add_subparsers(dest="command", required=True)
    go = commands.add_parser("run", help="run a suite's incomplete runs")
    go.add_argument("suite", choices=[*sorted(SUITES), "all"], help=f"a suite, or all: {', '.join(ALL)}")
    go.add_argument("--seeds", type=positive_int, help="seeds 0 … N−1 per arm (default: each arm's planned seeds)")
    go.add_argument("--workers", type=positive_int, default=2, help="runs at once (default 2: one per core)")
    go.add_argument("--out", required=True, help="suite directory")
    go.add_argument("--backend", choices=BACKENDS, default="local")
    go.add_argument("--address", help="Ray cluster to join (ray backend); default: a local Ray instance")
    rep = commands.add_parser("report", help="statistics, figures and a RESULTS-style markdown of a suite dir")
    rep.add_argument("directory")
    rep.add_argument("--results", default="docs/RESULTS.md", help="markdown file to write")
    rep.add_argument("--figures", default="docs/figures", help="directory for the PNG figures")
    args = parser.parse_args(argv)
    if args.command == "run":
        for suite in ALL if args.suite == "all" else (args.suite,):
            run_suite(suite, args.seeds, args.out, args.workers, args.backend, args.address,
                      progress=lambda line: print(line, flush=True))
    else:
        from .report import report

        directory = Path(args.directory)
        if not directory.is_dir():
            raise ConfigError(f"{directory}: no such suite directory")
        report(directory, Path(args.results), Path(args.figures))
        print(f"wrote {args.results} and figures in {args.figures}")
    return 0


if __name__ == "__main__":
    sys.exit(run(main))
