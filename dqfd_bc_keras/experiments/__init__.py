"""The lab: suites of runs, the paper's claims and their rules, statistics, figures, the report.

It reads run directories (what `runs.train` writes) and never re-records demonstrations;
nothing in the learning core imports it.

    arm_config.py  an arm: one Config over seeds, named by what it changes from the preset
    suites.py   declared arms × seeds (the grid of demonstration quality × quantity among them)
    jobs.py     a sweep's (arm, seed) jobs and what one run in a worker does
    sweep.py    running the jobs on a local process pool or Ray, the sweep log
    run_files.py   one run directory read into a `FinishedRun`
    data.py     suites read run by run; the compact per-run archive
    metrics.py  per-run metrics (episodes to solve, collapses, interactions to threshold, …)
    arms.py     runs grouped into arms by config; a bayes arm's ce pair
    claims.py   the claims C1–C4 and their verdict rules
    ablations.py   the ablations and the dynamic-demonstration default, judged
    plans.py    seeds per arm of each claim setting, planned by power
    lab_settings.py  what the lab judges each task by (teachers, efficiency goal, ablation metric)
    efficiency.py  sample efficiency against SB3: steps to threshold, ratios
    stats.py    bootstrap CIs, IQM, tests, TOST equivalence
    power.py    power and seeds per arm (normal approximation)
    figures.py  learning curves over seeds, the paper's single runs, heatmaps
    estimators.py  σ² estimators: calibration on four kinds of state, verdicts with each
    grid.py     the quality × quantity grid: help / hurt / escape, heatmaps
    imitation.py   BC alone on each grid cell (no RL)
    sections.py the report's claims, figures, dynamic, ablations, provenance and wall-time sections
    report.py   RESULTS.md from a suite directory or an archive
"""
