"""Sizes that cannot fit in this machine's memory (the replay, the networks or the batches a user's
settings ask for) are refused before TensorFlow loads, in one line saying how much they need, how much
the machine has and what to lower; the presets' defaults need far less than any machine has."""

import re

import pytest
from helpers import assert_without_tensorflow, command, left_in

from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.core.memory import machine_memory, memory_needed
from dqfd_bc_keras.envs.make import checked_spaces

GIB = 2**30


def test_the_default_configs_need_far_less_memory_than_any_machine_has():
    for task in ("cartpole", "mountaincar"):
        config = Config.for_task(task)
        net_input = checked_spaces(config).network_input(config.torso, config.timeout)
        needed = sum(memory_needed(config, net_input, 3).values())
        assert 1 * 2**20 < needed < min(1 * 2**30, machine_memory() / 10)


@pytest.mark.parametrize(
    "setting, subject, lower, at_least",
    [
        # at_least: one part alone, from first principles. The replay's table: rows × (2·4 + 5 + 2) float32;
        (
            "replay_capacity=10000000000",
            r"the replay \(replay_capacity=10000000000, demo_capacity=5000\) and networks",
            r"replay_capacity \(or demo_capacity\)",
            (10**10 + 5000) * 15 * 4,
        ),
        # the Q-network's 10^10 weights, its target's and Adam's two moments;
        (
            "hidden=100000,100000",
            r"the networks \(hidden=100000,100000, bc_hidden=64,64\) and replay",
            r"hidden \(or bc_hidden\)",
            4 * 10**10 * 4,
        ),
        # one forward pass of 10^9 states through 4 + 64 + 64 + 2 units.
        (
            "batch_size=1000000000",
            r"the batches \(batch_size=1000000000\), replay and networks",
            "batch_size",
            10**9 * 134 * 4,
        ),
    ],
)
def test_sizes_that_cannot_fit_are_refused_before_tensorflow_with_what_they_need(
    tmp_path, setting, subject, lower, at_least
):
    done = command("train.py", "--quick", "--set", setting, "--out", tmp_path / "run")
    assert (done.returncode, done.stdout) == (2, ""), done.stderr
    said = re.fullmatch(
        rf"error: {subject} need ~([\d,.]+) GiB, more than the ([\d,.]+) GiB this machine has; "
        rf"lower {lower}\n",
        done.stderr,
    )  # one line
    assert said, done.stderr
    needed, has = (float(n.replace(",", "")) for n in said.groups())
    assert at_least / GIB <= needed <= 10 * at_least / GIB  # an honest order of magnitude
    assert abs(has - machine_memory() / GIB) <= 0.5
    assert_without_tensorflow(done)
    assert left_in(tmp_path) == []
