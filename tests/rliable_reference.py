"""Write tests/data/rliable_reference.json: rliable's numbers that tests/test_stats.py holds our
stratified bootstrap and performance profile to. rliable is not a dependency of ours: run this
where `pip install rliable` works (1.2.0 was used, with arch 7.2 and pandas < 2.3)."""

import json
from pathlib import Path

import numpy as np
from rliable import library as rly
from rliable import metrics

if __name__ == "__main__":
    path = Path(__file__).parent / "data" / "rliable_reference.json"
    scores = np.round(np.random.default_rng(7).gamma(2.0, 0.5, size=(6, 5)), 2)  # 6 runs × 5 tasks
    taus = [0.25, 0.5, 1.0, 1.5, 2.0]
    point, interval = rly.get_interval_estimates(
        {"arm": scores},
        lambda x: np.array([metrics.aggregate_iqm(x)]),
        reps=50_000,
        random_state=np.random.RandomState(0),
    )
    profile, bands = rly.create_performance_profile({"arm": scores}, taus, reps=50_000)
    reference = {
        "rliable": "1.2.0",
        "scores": scores.tolist(),
        "taus": taus,
        "iqm": float(point["arm"][0]),
        "iqm_ci": [float(v) for v in interval["arm"].ravel()],
        "profile": profile["arm"].tolist(),
        "profile_bands": bands["arm"].tolist(),
    }
    path.write_text(json.dumps(reference, indent=1) + "\n")
    print(json.dumps(reference))
