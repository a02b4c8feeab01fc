"""What a run needs of the machine's memory, estimated before TensorFlow allocates it: a run too big
for the machine is refused in one line naming what to lower, not killed halfway."""

from __future__ import annotations

import itertools
import math
import os
from pathlib import Path

from dqfd_bc_keras.core.config import Config
from dqfd_bc_keras.envs.make import TaskSpaces
from dqfd_bc_keras.envs.network_input import CONV_TORSOS, NetworkInput
from dqfd_bc_keras.errors import ConfigError


def check_memory(config: Config, spaces: TaskSpaces) -> None:
    """Raise ConfigError when a run's replay, networks and batch (`memory_needed`) need more
    memory than this machine has, before TensorFlow would die of it halfway.
    Called where a run is about to train, with its env's `envs.checked_spaces` (not by
    `for_task`: the lab reads configs of tasks whose envs it need not make)."""
    parts = memory_needed(config, spaces.network_input(config.torso, config.timeout), spaces.n_actions)
    available = machine_memory()
    if sum(parts.values()) <= available:
        return
    largest = max(parts, key=parts.__getitem__)
    what, lower = {
        "replay": (
            f"the replay (replay_capacity={config.replay_capacity}, demo_capacity={config.demo_capacity}) and networks",
            "replay_capacity (or demo_capacity)",
        ),
        "networks": (
            f"the networks (hidden={_sizes(config.hidden)}, bc_hidden={_sizes(config.bc_hidden)}) and replay",
            "hidden (or bc_hidden)",
        ),
        "activations": (f"the batches (batch_size={config.batch_size}), replay and networks", "batch_size"),
    }[largest]
    raise ConfigError(
        f"{what} need ~{_gib(sum(parts.values()))} GiB, more than the {_gib(available)} GiB "
        f"this machine has; lower {lower}"
    )


def memory_needed(config: Config, net_input: NetworkInput, n_actions: int) -> dict[str, int]:
    """Bytes a run of `config` holds at once, to an order of magnitude, by part:

    replay       per row of D_demo ∪ D_replay (replay.py), float32: the table's [s | s' | a, r,
                 terminated, truncated | π̄_bc (A) | σ²], the n-step view's [R | s_{t+m} | γ^m] and a
                 sum-tree leaf, s being k pool indices for frames, whose pool holds two uint8 slots a row
    networks     float32 parameters (networks.py: torso, dense layers) of the Q-network, its target
                 and θ_prior, its gradient and Adam's two moments; of each BC member, weights, gradient
                 and two moments
    activations  every layer's output for a batch, float32: four Q passes a gradient step (s, s', and
                 s_{t+n} twice), twice for the backward pass; a BC refresh's mc_passes over 8192 states
    """
    rows = config.demo_capacity + config.replay_capacity
    frames = net_input.frames
    columns = net_input.dim if frames is None else frames.stack
    replay = 4 * rows * ((2 * columns + 5 + n_actions) + (columns + 2) + 1)
    if frames is not None:
        replay += 2 * (rows + frames.stack) * math.prod(frames.frame_shape)
    torso_params, torso_outputs, width = 0, math.prod(net_input.shape), math.prod(net_input.shape)
    if frames is not None and net_input.torso in CONV_TORSOS:
        height, across, channels = *frames.shape[:2], (frames.shape[2] if len(frames.shape) == 3 else 1)
        for filters, kernel, stride in CONV_TORSOS[net_input.torso]:
            height, across = (height - kernel) // stride + 1, (across - kernel) // stride + 1
            torso_params += (kernel * kernel * channels + 1) * filters
            channels = filters
            torso_outputs += height * across * filters
        width = height * across * channels
    sizes = {}
    for name, hidden in (("q", config.hidden), ("bc", config.bc_hidden)):
        units = [width, *hidden, n_actions]
        sizes[name] = (
            torso_params + sum((a + 1) * b for a, b in itertools.pairwise(units)),
            torso_outputs + sum(units[1:]),
        )
    members = config.ensemble_members if config.uses_bc and config.uncertainty == "ensemble" else 1
    bc_copies = 4 * members if config.uses_bc else 0
    networks = 4 * (6 * sizes["q"][0] + bc_copies * sizes["bc"][0])
    activations = 4 * (
        8 * config.batch_size * sizes["q"][1]
        + (config.mc_passes * members * 8192 * sizes["bc"][1] if config.uses_bc else 0)
    )
    return {"replay": replay, "networks": networks, "activations": activations}


def _gib(size: int) -> str:
    return f"{size / 2**30:,.0f}" if size >= 10 * 2**30 else f"{size / 2**30:.1f}"


def _sizes(sizes: tuple[int, ...]) -> str:
    """Layer sizes as `--set` takes them."""
    return ",".join(map(str, sizes))


def machine_memory() -> int:
    """Bytes of memory this machine has: its physical memory, or the cgroup's limit if lower."""
    physical = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    for limit in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            return min(physical, int(Path(limit).read_text().strip()))
        except (OSError, ValueError):  # absent, or "max": no limit
            continue
    return physical
