"""The pace a person plays each MinAtar preset at (`demos play`'s default steps per second), as
benchmarks/play_pace.py measures it: a player who reacts in τ = 0.25 s acts at f steps/s on a frame
⌈τ·f⌉ − 1 steps old, with the strong expert's intent; a preset plays at the fastest pace at which
such a player keeps 80% of the expert's return (benchmarks/results/play-pace.json)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
from helpers import REPO, call

from dqfd_bc_keras.envs.episodes import play
from dqfd_bc_keras.envs.make import make_task
from dqfd_bc_keras.tasks import TASKS

sys.path.insert(0, str(REPO / "benchmarks"))
import play_pace  # benchmarks/ is no package: on the path above

pytest.importorskip("minatar")
MEASURED = json.loads((REPO / "benchmarks" / "results" / "play-pace.json").read_text())


def test_a_frame_is_as_old_as_the_frames_a_reaction_spans():
    """At f steps/s frame k is on screen from (k − 1)/f to k/f; the keys read at k/f came from what
    was seen at k/f − 0.25 s: at 4 steps/s the frame then on screen is frame k itself."""
    assert [play_pace.delay_at(f, 0.25) for f in (1, 2, 4, 4.5, 8, 9, 10, 12, 13)] == [0, 0, 0, 1, 1, 2, 2, 2, 3]
    assert [play_pace.fastest_pace(d, 0.25) for d in (0, 1, 2)] == [4, 8, 12]
    assert [play_pace.delay_at(play_pace.fastest_pace(d, 0.3), 0.3) for d in (0, 1, 2)] == [0, 1, 2]


def test_the_pace_is_the_fastest_whose_delay_and_every_smaller_one_keep_the_share():
    assert play_pace.chosen_pace({0: [10, 10], 1: [9, 8], 2: [8, 8], 3: [1, 1]}, 0.25, 0.8) == (12, 2)
    assert play_pace.chosen_pace({0: [10], 1: [7], 2: [9]}, 0.25, 0.8) == (4, 0)  # 1 step behind already loses
    assert play_pace.chosen_pace({0: [10], 1: [7]}, 0.2, 0.7) == (10, 1)


def test_no_delay_is_the_expert_itself():
    env = make_task("minatar-breakout", max_steps=80)
    expert = TASKS["minatar-breakout"].experts["strong"]
    delayed = play_pace.Delayed(expert, 0)
    assert play(env, delayed, range(3), watcher=delayed) == play(env, expert, range(3))
    late = play_pace.Delayed(expert, 1)
    assert play(env, late, range(3), watcher=late).returns != play(env, expert, range(3)).returns
    env.close()


@pytest.mark.slow
def test_the_quick_measurement_covers_every_minatar_preset():
    done = subprocess.run(
        [sys.executable, "benchmarks/play_pace.py", "--quick", "--json"],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout)
    assert set(report["presets"]) == {name for name, spec in TASKS.items() if spec.env_id.startswith("MinAtar/")}
    for row in report["presets"].values():
        delays = row["delays"]
        assert list(delays) == ["0", "1", "2", "3", "4"] and delays["0"]["share"] in (1.0, None)
        assert row["pace"] == play_pace.fastest_pace(row["delay"], 0.25)


@pytest.mark.parametrize("task", sorted(MEASURED["presets"]))
def test_each_minatar_preset_plays_at_its_measured_pace(task):
    """The preset's pace is what the full measurement chose (20 episodes a delay), and `play` plays at it."""
    assert (MEASURED["episodes"], MEASURED["reaction_s"], MEASURED["keep"]) == (20, 0.25, 0.8)
    measured = MEASURED["presets"][task]
    assert TASKS[task].fps == measured["pace"]
    assert measured["delays"][str(measured["delay"])]["share"] >= 0.8
    assert measured["delays"][str(measured["delay"] + 1)]["share"] < 0.8
    answer = call("dqfd_bc_keras.demos", "play", "--task", task, "--list-keys")
    assert answer.returncode == 0 and f"pace: {measured['pace']:g} steps/s" in answer.stdout


def test_a_minatar_env_given_by_id_plays_and_records_at_its_games_pace():
    """`--env MinAtar/Asterix-v0` (all six actions: no preset plays that env) takes Asterix's pace, which
    is also its videos' frame rate."""
    answer = call("dqfd_bc_keras.demos", "play", "--env", "MinAtar/Asterix-v0", "--max-steps", 100, "--list-keys")
    assert answer.returncode == 0, answer.stderr
    assert f"pace: {TASKS['minatar-asterix'].fps:g} steps/s" in answer.stdout
    env = make_task("MinAtar/Asterix-v0", max_steps=100, render_mode="rgb_array")
    assert env.metadata["render_fps"] == TASKS["minatar-asterix"].fps
    env.close()
