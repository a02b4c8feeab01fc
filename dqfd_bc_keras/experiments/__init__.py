"""The lab: suites of runs, the paper's claims and their rules, statistics, figures, the report.

It reads run directories (what `runs.train` writes) and never re-records demonstrations;
nothing in the learning core imports it.

    suites.py   declared arms × seeds, run on a local process pool or Ray
    data.py     run directories read into `FinishedRun`s; the compact per-run archive
    claims.py   per-run metrics, the claims C1–C4 and their verdict rules
    plans.py    seeds per arm of each claim setting, planned by power
    efficiency.py  sample efficiency against SB3: steps to threshold, ratios
    stats.py    bootstrap CIs, IQM, tests, TOST equivalence, power
    figures.py  learning curves over seeds, the paper's single runs
    report.py   RESULTS.md from a suite directory or an archive
"""
