"""The SB3 baseline on MinAtar: Stable-Baselines3's DQN with MinAtar's own network and rl-zoo3's
tuned Atari schedule, through one `learn()` per seed, evaluated greedily on a fixed grid.

It is the pixels counterpart of the lab's CartPole baseline (`dqfd_bc_keras/experiments/baselines.py`)
and is run the same way: one `learn()` of the whole budget per seed (so ε decays over the schedule it
was tuned with), a callback that plays `eval_episodes` greedy episodes at step 0 and at every
multiple of `every` env steps of SB3's own counter, on a separate env whose episode i resets with
seed `eval_seed(seed) + i`, one json per seed. The network is Young & Tian's (2019) MinAtar DQN
network (`MinAtarCNN` + a linear head); the hyperparameters are rl-zoo3's `atari:` entry with the
changes MinAtar's setup forces (`CHANGES`). MinAtar's own DQN settings (`MINATAR_DQN`) and its
published DQN curves (`MINATAR_DQN_RETURNS`) are the second anchor: they are not what this
baseline runs, but where its returns should land.

    python -m studies.sb3_pixels --env MinAtar/Breakout-v1 --seeds 3 --budget 500000 --out results
    python -m studies.sb3_pixels --env MinAtar/Breakout-v1 --out /tmp/x --quick   # seconds

Writes DIR/<env, '/' as '-'>/seed<k>.json (seed<k>-quick.json with --quick); a file that records
the same settings is kept, not rerun. SB3 is optional: pip install -r benchmarks/requirements.txt.
"""

from __future__ import annotations

import sys

if __name__ == "__main__":
    # SB3's logger imports tensorboard, which imports TensorFlow when it is installed (seconds,
    # and a second framework's threads): keep it out of this process, as benchmarks/interleave.py
    # does. Only here: a process that imports this module may well want TensorFlow.
    sys.modules.setdefault("tensorflow", None)  # type: ignore[arg-type]  # a None entry blocks the import

import json
import time
from collections.abc import Sequence
from importlib.metadata import version
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3 import DQN
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.preprocessing import is_image_space
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn
from torch.nn import functional as F

from dqfd_bc_keras.commands.cli import ArgumentParser, positive_int, run
from dqfd_bc_keras.envs.episodes import play
from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.files import write_text
from dqfd_bc_keras.seeds import eval_seed

CONV_CHANNELS, HIDDEN_UNITS = 16, 128
"""MinAtar's network (Young & Tian 2019, examples/dqn.py): one 3×3 stride-1 convolution of 16
filters, one dense layer of 128 units, both ReLU (a quarter of Mnih et al.'s 64 and 512)."""


class MinAtarCNN(BaseFeaturesExtractor):
    """MinAtar's DQN torso as SB3 features: Conv2d(C, 16, 3, stride 1) + ReLU, flatten, Linear(·, 128)
    + ReLU. SB3's Q head (`net_arch=[]`) adds MinAtar's final linear layer on these 128 features.

    Takes MinAtar's frames as the env gives them, (B, H, W, C) channel-last 0/1 (bool, or uint8
    0/1), and permutes them to channel-first floats itself: such a space is not an SB3 image
    space (uint8 in [0, 255]), so SB3 neither transposes nor divides it by 255."""

    def __init__(self, observation_space: spaces.Box, features_dim: int = HIDDEN_UNITS) -> None:
        if not isinstance(observation_space, spaces.Box) or len(observation_space.shape) != 3:
            raise ConfigError(f"MinAtarCNN takes (H, W, C) frames, got the observation space {observation_space}")
        if is_image_space(observation_space):
            raise ConfigError(
                f"MinAtarCNN takes MinAtar's 0/1 frames, got the 8-bit image space {observation_space}, "
                "which SB3 would transpose to channel-first and divide by 255"
            )
        super().__init__(observation_space, features_dim)
        height, width, channels = observation_space.shape
        self.conv = nn.Conv2d(channels, CONV_CHANNELS, kernel_size=3, stride=1)
        self.hidden = nn.Linear(CONV_CHANNELS * (height - 2) * (width - 2), features_dim)

    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        x = observations.permute(0, 3, 1, 2).float()
        return F.relu(self.hidden(F.relu(self.conv(x)).flatten(start_dim=1)))


# rl-baselines3-zoo's tuned DQN entry for Atari, verbatim: hyperparams/dqn.yml of DLR-RM/rl-baselines3-zoo
# at 22e3ff24 (2026-04-23; the entry unchanged since f1064a7, 2022-07-15):
#   atari:
#     env_wrapper:
#       - stable_baselines3.common.atari_wrappers.AtariWrapper
#     frame_stack: 4
#     policy: 'CnnPolicy'
#     n_timesteps: !!float 1e7
#     buffer_size: 100000
#     learning_rate: !!float 1e-4
#     batch_size: 32
#     learning_starts: 100000
#     target_update_interval: 1000
#     train_freq: 4
#     gradient_steps: 1
#     exploration_fraction: 0.1
#     exploration_final_eps: 0.01
#     # If True, you need to deactivate handle_timeout_termination
#     # in the replay_buffer_kwargs
#     optimize_memory_usage: False
ZOO_ATARI: dict[str, Any] = {
    "policy": "CnnPolicy",
    "n_timesteps": 10_000_000,
    "kwargs": dict(
        buffer_size=100_000,
        learning_rate=1e-4,
        batch_size=32,
        learning_starts=100_000,
        target_update_interval=1000,
        train_freq=4,
        gradient_steps=1,
        exploration_fraction=0.1,
        exploration_final_eps=0.01,
        optimize_memory_usage=False,
    ),
}

CHANGES = {
    "env_wrapper": "dropped: AtariWrapper's no-op starts, frame skip 4, 84×84 grey frames, life loss and reward "
    "clipping belong to the ALE; a MinAtar step is one frame of a 10×10 object grid, its env has its "
    "own sticky actions (p = 0.1), and MinAtar's DQN learns from its raw rewards",
    "frame_stack": "dropped (1): MinAtar's trail channels carry the motion, and Young & Tian stack no frames",
    "policy_kwargs": "NatureCNN (for 84×84×4) → MinAtarCNN with net_arch=[] (MinAtar's conv 16 + dense 128 + "
    "linear head) and normalize_images=False (its frames are 0/1)",
    "n_timesteps": "1e7 → the budget: one learn() per seed, so the ε schedule (exploration_fraction × budget) "
    "follows it as in rl-zoo3",
    "learning_starts": "100,000 of 1e7 (1%) → 1% of the budget: the tuned schedule's shape at a shorter budget "
    "(100,000 would be most or all of it; MinAtar's own is 5,000 of 5e6)",
}
"""What MinAtar's setup changes in the zoo's entry, and why. Kept as tuned: the replay (100,000,
MinAtar's size too), Adam at 1e-4, batch 32, target every 1,000 steps, one update every 4 steps,
ε 1 → 0.01 over the first 10%; SB3's defaults γ = 0.99 and the Huber loss (MinAtar's too)."""

MINATAR_DQN = {
    "source": "kenjyoung/MinAtar examples/dqn.py at 4241f246 (2024-12-19)",
    "batch_size": 32,
    "replay_buffer_size": 100_000,
    "target_network_update_freq": 1000,
    "training_freq": 1,
    "num_frames": 5_000_000,
    "replay_start_size": 5000,
    "epsilon": "1.0 → 0.1 linearly over the 100,000 frames after the replay start, then 0.1",
    "optimizer": "centered RMSprop, lr 0.00025, α (squared-gradient momentum) 0.95, eps 0.01",
    "gamma": 0.99,
    "loss": "smooth L1 (Huber)",
    "network": "Conv2d(C, 16, 3, stride 1) + ReLU → Linear(1024, 128) + ReLU → Linear(128, A)",
    "actions": "the full set of 6 (MinAtar/<Game>-v0)",
}
"""MinAtar's published DQN settings (Young & Tian 2019), the second anchor's; not this baseline's
schedule (it runs the zoo's, as the comparison asks)."""

MINATAR_DQN_RETURNS: dict[str, dict[int, float]] = {
    "MinAtar/Breakout": {100_000: 5, 500_000: 8.5, 1_000_000: 9.5, 5_000_000: 10},
    "MinAtar/Seaquest": {1_000_000: 1, 5_000_000: 20},
    "MinAtar/Asterix": {1_000_000: 9, 5_000_000: 17},
    "MinAtar/Freeway": {1_000_000: 48, 5_000_000: 50},
    "MinAtar/SpaceInvaders": {1_000_000: 35, 5_000_000: 43},
}
"""Young & Tian's DQN (with replay) by frames, read off the learning curves of the MinAtar README
(img/learning_curves.gif at 4241f246, the paper's figure; no table of numbers is published): the
moving average of the last 100 training returns (ε-greedy at 0.1, not greedy), mean of 30 seeds,
6 actions, MinAtar's schedule above. Readings to ±0.5 (Freeway, Space Invaders ±1); Seaquest's
curve predates MinAtar 1.0.11's oxygen fix."""

SB3_VERSIONS = ("stable-baselines3", "torch", "gymnasium", "minatar")
QUICK = {"budget": 1000, "every": 250, "eval_episodes": 2, "max_steps": 200}
"""--quick: seconds, one seed (checks the command runs; the numbers mean nothing)."""
DEFAULTS = {"every": 10_000, "eval_episodes": 10, "max_steps": 10_000}
"""The CLI's evaluation defaults: 10 greedy episodes every 10,000 steps, each cut at 10,000 steps
(a greedy Breakout policy can keep the ball in play forever); use our runs' step limit."""


def minatar_env_id(env_id: str) -> str:
    """`env_id` if it names a registered MinAtar env (registering MinAtar's ids first)."""
    import minatar.gym

    if not any(name.startswith("MinAtar/") for name in gym.registry):
        minatar.gym.register_envs()
    known = sorted(name for name in gym.registry if name.startswith("MinAtar/"))
    if env_id not in known:
        raise ConfigError(f"unknown MinAtar env id {env_id!r}; expected one of {', '.join(known)}")
    return env_id


def policy_kwargs() -> dict:
    """MinAtar's network in SB3: `MinAtarCNN` features, a linear head, no /255 (the frames are 0/1;
    SB3 divides only image spaces, which MinAtar's are not, so this is belt and braces)."""
    return {"features_extractor_class": MinAtarCNN, "net_arch": [], "normalize_images": False}


def hyperparameters(budget: int) -> dict:
    """DQN's keyword arguments (but `policy_kwargs`) for one `learn()` of `budget` steps: the zoo's
    Atari entry with `CHANGES` (learning_starts 1% of the budget, as 1e5 is of 1e7)."""
    ratio = ZOO_ATARI["kwargs"]["learning_starts"] / ZOO_ATARI["n_timesteps"]
    return {**ZOO_ATARI["kwargs"], "learning_starts": int(ratio * budget)}


def sb3_model(env_id: str, seed: int, budget: int, max_steps: int) -> DQN:
    """SB3's DQN for one `learn()` of `budget` steps on `env_id` cut at `max_steps`, as rl-zoo3
    builds it (a DummyVecEnv of a Monitor), on one torch thread."""
    torch.set_num_threads(1)
    env = make_vec_env(minatar_env_id(env_id), n_envs=1, seed=seed, env_kwargs={"max_episode_steps": max_steps})
    return DQN(ZOO_ATARI["policy"], env, seed=seed, verbose=0, policy_kwargs=policy_kwargs(), **hyperparameters(budget))


def settings(env_id: str, seed: int, budget: int, every: int, eval_episodes: int, max_steps: int) -> dict:
    """What a run's file records of how it was run, and must match for it to be kept."""
    return {
        "env": env_id,
        "seed": seed,
        "budget": budget,
        "eval_every": every,
        "eval_episodes": eval_episodes,
        "max_steps": max_steps,
        "eval_seed": eval_seed(seed),
        "hyperparameters": {
            "policy": ZOO_ATARI["policy"],
            **hyperparameters(budget),
            "policy_kwargs": {
                "features_extractor_class": MinAtarCNN.__name__,
                "net_arch": [],
                "normalize_images": False,
            },
        },
    }


class Grid(BaseCallback):
    """`episodes` greedy episodes at step 0 and at every multiple of `every` up to `budget` (a
    rollout of `train_freq` steps may run past the budget), on `env`, episode i from seed + i."""

    def __init__(self, env: gym.Env, every: int, budget: int, episodes: int, seed: int) -> None:
        super().__init__()
        self.env, self.every, self.budget, self.episodes, self.seed = env, every, budget, episodes, seed
        self.evaluations: list[dict] = []

    def _evaluate(self) -> None:
        def greedy(obs: np.ndarray) -> int:
            return int(self.model.predict(obs, deterministic=True)[0])

        returns = play(self.env, greedy, range(self.seed, self.seed + self.episodes)).returns
        self.evaluations.append(
            {"interactions": self.num_timesteps, "mean_return": float(np.mean(returns)), "returns": returns}
        )

    def _on_training_start(self) -> None:
        self._evaluate()

    def _on_step(self) -> bool:
        if self.num_timesteps % self.every == 0 and self.num_timesteps <= self.budget:
            self._evaluate()
        return True


def sb3_minatar_run(
    env_id: str, seed: int, budget: int, every: int, eval_episodes: int, max_steps: int, path: Path
) -> dict:
    """One seed: one `learn()` of `budget` steps, the greedy policy evaluated at 0, every, 2·every, …
    ≤ budget; writes `path` (atomically) and returns what it holds."""
    started = time.perf_counter()
    model = sb3_model(env_id, seed, budget, max_steps)
    eval_env = gym.make(env_id, max_episode_steps=max_steps)  # gym.make + TimeLimit(max_steps)
    grid = Grid(eval_env, every, budget, eval_episodes, eval_seed(seed))
    model.learn(total_timesteps=budget, callback=grid)
    eval_env.close()
    record = {
        **settings(env_id, seed, budget, every, eval_episodes, max_steps),
        "sb3_defaults": {
            "gamma": model.gamma,
            "tau": model.tau,
            "max_grad_norm": model.max_grad_norm,
            "optimizer": type(model.policy.optimizer).__name__,
            "loss": "smooth_l1 (Huber)",
        },
        "changes_from_zoo": CHANGES,
        "evaluations": grid.evaluations,
        "seconds": round(time.perf_counter() - started, 1),
        "versions": {name: version(name) for name in SB3_VERSIONS},
    }
    write_text(path, json.dumps(record, indent=1))
    return record


def current(path: Path, wanted: dict) -> bool:
    """`path` exists and records the settings asked for (a changed setting reruns it)."""
    return path.is_file() and wanted.items() <= json.loads(path.read_text()).items()


def main(argv: Sequence[str] | None = None) -> int:
    parser = ArgumentParser(prog="python -m studies.sb3_pixels", description=__doc__.split("\n\n")[0])
    parser.add_argument("--env", required=True, help="a MinAtar env id, e.g. MinAtar/Breakout-v1")
    parser.add_argument("--seeds", type=positive_int, default=1, help="seeds 0 … N-1 (default %(default)s)")
    parser.add_argument("--budget", type=positive_int, help=f"env steps of each learn() (--quick: {QUICK['budget']})")
    parser.add_argument(
        "--every", type=positive_int, help=f"env steps between evaluations (default {DEFAULTS['every']})"
    )
    parser.add_argument(
        "--eval-episodes",
        type=positive_int,
        help=f"greedy episodes per evaluation (default {DEFAULTS['eval_episodes']})",
    )
    parser.add_argument(
        "--max-steps",
        type=positive_int,
        help=f"step limit of every episode, training and evaluation (default {DEFAULTS['max_steps']})",
    )
    parser.add_argument("--out", type=Path, required=True, help="directory of the per-seed json files")
    parser.add_argument(
        "--quick",
        action="store_true",
        help="one seed, tiny budget and evaluations (given options still win): checks the command runs",
    )
    args = parser.parse_args(argv)
    fallback = QUICK if args.quick else DEFAULTS
    budget = args.budget if args.budget is not None else fallback.get("budget")
    every, eval_episodes, max_steps = (
        getattr(args, name) if getattr(args, name) is not None else fallback[name]
        for name in ("every", "eval_episodes", "max_steps")
    )
    if budget is None:
        raise ConfigError("--budget is required (env steps of each learn()), unless --quick")
    env_id = minatar_env_id(args.env)
    for seed in range(1 if args.quick else args.seeds):
        path = args.out / env_id.replace("/", "-") / f"seed{seed}{'-quick' if args.quick else ''}.json"
        if current(path, settings(env_id, seed, budget, every, eval_episodes, max_steps)):
            print(f"{env_id} seed {seed}: {path} is current, kept")
            continue
        record = sb3_minatar_run(env_id, seed, budget, every, eval_episodes, max_steps, path)
        last = record["evaluations"][-1]
        print(
            f"{env_id} seed {seed}: mean return {last['mean_return']:.2f} at {last['interactions']:,} steps "
            f"({record['seconds']:.0f} s) -> {path}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(run(main))
