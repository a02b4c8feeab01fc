"""One-off studies: each runs the lab (`dqfd_bc_keras.experiments`) as a library, has its own
pre-registered rules (docs/PREREGISTRATION.md), its own archive of per-run data in docs/data/ and
its own generated report in docs/. They are not part of the installed package (the wheel holds
`dqfd_bc_keras` only): run them from the repository's root, where `studies` is importable.

    pixels.py         MinAtar Breakout: DQfD on frames against SB3's DQN (docs/PIXELS.md)
    sb3_pixels.py     SB3's DQN with MinAtar's network and rl-zoo3's Atari schedule: the MinAtar baseline
    minatar_study.py  the five MinAtar games: normalised scores, IQM, profiles (docs/MINATAR.md)
    sigma0.py         the Bayesian loss with σ0² below the variance cap, against ce (docs/SIGMA0.md)
    tuned.py          a tuning study's params against the preset's defaults on fresh seeds (docs/TUNING.md)
    past_teacher.py   issue W on the five MinAtar games: the pilot's new arm beside §13's (docs/PAST_TEACHER.md)
    past_teacher_vector.py  issue W on Acrobot, LunarLander and MiniGrid, and the 10× question (§15)
    tuned_presets.py  issue W's tuning of the presets: studies, the defaults on their seeds, fresh-seed checks (§16)

    python -m studies.pixels --out docs/data/pixels.tar.xz --no-run --report docs/PIXELS.md
    python -m studies.minatar_study --out docs/data/minatar.tar.xz --no-run \
        --report docs/MINATAR.md --figures docs/figures
    python -m studies.sigma0 docs/data/sigma0.tar.xz --report docs/SIGMA0.md

A study's workers (the lab's local pool, SB3's process pool) are spawned with the parent's
`sys.path`, so they import `studies` as the command did; the lab's Ray backend puts the
repository's root on its workers' PYTHONPATH.
"""
