"""Atari: the standard DQN preprocessing of an `ALE/<Game>-v5` env (`--env ale_py:ALE/Breakout-v5`).

The learner's env (`learning=True`) is, from the emulator out (the wrappers are in atari_wrappers.py):

    AtariFrames    no-op starts (1..noop_max frames of NOOP, drawn from the env's np_random),
                   each action repeated frame_skip frames with the rewards summed, the last two
                   frames max-pooled, the grey screen area-averaged to screen_size x screen_size
    EpisodicLife   losing a life ends the episode (terminated=True); the reset after it goes on
                   with the same game, a real reset happens only once the game is over
    ClipReward     the reward becomes sign(r); info["plain_reward"] keeps the raw game reward
    StackFrames    the last frame_stack frames, uint8 (84, 84, 4), newest last

and the plain env (`learning=False`, what evaluation scores) is AtariFrames and StackFrames
only: the same observations, the raw game reward, one episode per game. Our `TimeLimitMode`
goes outside either (`envs/make.py`).

This is CleanRL's `dqn_atari.py` and SB3's `AtariWrapper` (NoopResetEnv(30), MaxAndSkipEnv(4),
EpisodicLifeEnv, ClipRewardEnv, an 84x84 grey frame, 4 frames stacked) with these differences:

* ALE v5. CleanRL and SB3 use `<Game>NoFrameskip-v4`: no frame skip, no sticky actions. v5 skips
  4 frames itself (no max-pooling) and repeats the previous action with probability 0.25
  (Machado et al. 2018). We make the v5 env with `frameskip=1`, so that skipping and pooling
  happen here once, and keep its sticky actions (0.25) unless the env kwargs say otherwise
  (`{"repeat_action_probability": 0.0}` is v4's setting). The `max_num_frames_per_episode`
  of 108 000 frames (27 000 steps) stays: the ALE truncates a game there.
* No FireResetEnv (pressing FIRE at reset, which CleanRL and SB3 add for Breakout and the like):
  the agent has to learn to press FIRE, as in gymnasium's `AtariPreprocessing`.
* The grey frame is the ALE's own (`obs_type="grayscale"`, as `AtariPreprocessing` reads it),
  not cv2's RGB-to-grey conversion, and the area average is ours (`area_weights`, cv2's
  INTER_AREA as two matrix products, within one grey level of cv2's rounding) so opencv is
  not needed.
* After a lost life SB3's EpisodicLifeEnv takes one NOOP step that nobody sees and starts the
  next episode from its frame; we start it from the frame the life was lost on, so no step's
  reward goes missing: over the episodes of one game the plain rewards add up to its score.
  A seed passed to that reset is ignored (the seed of the reset that started the game fixed
  its course); the stack restarts with copies of that frame, as at any reset.
* Frames are stacked on the last axis, (84, 84, 4), the layout the networks take.

The frame stack keeps two invariants the replay relies on to store each frame once: within an
episode next_obs[..., :-1] == obs[..., 1:], and every reset's stack is frame_stack copies of
the reset frame (also after a lost life).

The options (`AtariOptions`) come from the run's env kwargs: `split_kwargs` takes the keys
`noop_max`, `frame_skip`, `screen_size`, `frame_stack`, `clip_rewards`,
`terminal_on_life_loss` and `obs_type` out; the rest go to `gym.make` (`repeat_action_probability`,
`full_action_space`, `mode`, `difficulty`, `max_num_frames_per_episode`, ...). With
`obs_type="ram"` the agent observes the console's 128 bytes of RAM, a vector: no-op starts and
frame skip (the last frame's RAM, no pooling), lives and clipping as above, no screen or stack.

>>> env = make_atari("ale_py:ALE/Breakout-v5", {"frame_stack": 2})
>>> obs, info = env.reset(seed=0)
>>> obs.shape, obs.dtype.name
((84, 84, 2), 'uint8')
"""

from __future__ import annotations

import dataclasses
import difflib
import importlib
import inspect
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import gymnasium as gym

from dqfd_bc_keras.envs.atari_wrappers import AtariFrames, ClipReward, EpisodicLife, StackFrames
from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.plugins import bare_id

RESERVED_ALE_KWARGS = {
    "frameskip": "the preprocessing skips frames: use frame_skip",
    "sound_obs": "the observation is the screen or the RAM only",
}

OBS_TYPES = ("grayscale", "ram")
"""What an Atari agent can observe: the grey screen as frames, or the console's 128 bytes of RAM."""
FRAME_OPTIONS = ("screen_size", "frame_stack")
"""The options that shape frames, which a RAM observation does not have."""


def is_atari(env_id: str) -> bool:
    """Whether `env_id` (with or without a `module:` prefix) is in the ALE/ namespace."""
    return bare_id(env_id).startswith("ALE/")


@dataclass(frozen=True)
class AtariOptions:
    """The preprocessing of an Atari env; each field can be set by an env kwarg of that name."""

    noop_max: int = 30
    """At most this many NOOP frames after a real reset (at least one); 0: none."""
    frame_skip: int = 4
    """Each action is repeated this many frames; the last two are max-pooled."""
    screen_size: int = 84
    """The grey frame is area-averaged to screen_size x screen_size."""
    frame_stack: int = 4
    """The observation is the last frame_stack frames, newest last."""
    clip_rewards: bool = True
    """Learning: the reward is sign(r) (info["plain_reward"] keeps r)."""
    terminal_on_life_loss: bool = True
    """Learning: a lost life ends the episode, and the next reset continues the game."""
    obs_type: str = "grayscale"
    """"grayscale": the screen, shrunk and stacked as above; "ram": the console's 128 bytes as one
    vector, with no-op starts and frame skip (the last step's RAM: pooling is for flickering
    sprites) and neither screen_size nor frame_stack."""


ATARI_OPTIONS = AtariOptions()
"""The defaults: CleanRL's and SB3's."""

ATARI_STEP_LIMIT = 27_000
"""An Atari task's step limit: the ALE's 108,000 frames at 4 frames a step."""
ATARI_QUICK: Mapping[str, object] = {"max_steps": 200}
"""`--quick`'s step limit: a greedy agent that never presses FIRE plays every step of each evaluation's."""
ATARI_DEFAULTS: Mapping[str, object] = {
    "hidden": (512,),
    "bc_hidden": (512,),
    "learning_rate": 1e-4,
    "batch_size": 32,
    "target_update_period": 1000,
    "train_freq": 4,
    "replay_capacity": 100_000,
    "demo_capacity": 50_000,
    "total_steps": 1_000_000,
    "eval_every": 50_000,
    "eval_episodes": 5,
    "final_eval_episodes": 10,
    "demo_episodes": 5,
    "early_stop_window": 0,
    "checkpoint_every": 100_000,
}
"""The Config defaults of an Atari env: the Nature network's 512 dense units, CleanRL dqn_atari.py's
learning rate, batch, target period and training frequency; D_replay 100k (not 1M: a frame
costs two pool slots, 1.4 GB per 100k transitions here) and a 1M-step budget, ours."""

_MINIMUM = {"noop_max": 0, "frame_skip": 1, "screen_size": 1, "frame_stack": 1}


def split_kwargs(env_kwargs: Mapping[str, Any] | None) -> tuple[AtariOptions, dict[str, Any]]:
    """The preprocessing options in `env_kwargs` and the kwargs for `gym.make` (the rest, with
    the ALE's own frame skip off and the observation `obs_type`). A one-line `ConfigError` for a bad
    option value, for an ALE kwarg the preprocessing sets, for a frame option with the RAM, and
    for a key that is neither."""
    fields = {field.name: field for field in dataclasses.fields(AtariOptions)}
    ale_keywords = [
        name
        for name in inspect.signature(_ale_env().__init__).parameters
        if name not in ("self", *RESERVED_ALE_KWARGS, *fields)
    ]
    options: dict[str, Any] = {}
    make_kwargs: dict[str, Any] = {}
    for key, value in (env_kwargs or {}).items():
        if key in fields:
            options[key] = _checked(key, value, str(fields[key].type))
        elif key in RESERVED_ALE_KWARGS:
            raise ConfigError(f"--env-kwargs {key}: not for an Atari env here; {RESERVED_ALE_KWARGS[key]}")
        elif key in ale_keywords:
            make_kwargs[key] = value
        else:
            near = difflib.get_close_matches(key, [*fields, *ale_keywords], n=1)
            hint = f"did you mean {near[0]!r}? " if near else ""
            raise ConfigError(
                f"--env-kwargs {key}: neither an Atari option nor an ALE keyword ({hint}options: "
                f"{', '.join(fields)}; ALE: {', '.join(ale_keywords)})"
            )
    atari = AtariOptions(**options)
    if atari.obs_type == "ram":
        for key in FRAME_OPTIONS:
            if key in options:
                raise ConfigError(
                    f"--env-kwargs {key}: not with obs_type='ram', which observes the console's 128 bytes, not frames"
                )
    return atari, {**make_kwargs, "frameskip": 1, "obs_type": atari.obs_type}


def _checked(key: str, value: Any, kind: str) -> int | bool | str:
    """`value` of option `key` if it has the option's type (`kind`, the annotation) and range."""
    if kind == "str":
        if value not in OBS_TYPES:
            raise ConfigError(
                f"--env-kwargs {key}: expected 'grayscale' (the screen as frames) or 'ram' (the "
                f"console's 128 bytes), got {value!r}"
            )
        return value
    if kind == "bool":
        if not isinstance(value, bool):
            raise ConfigError(f"--env-kwargs {key}: expected true or false, got {value!r}")
        return value
    if isinstance(value, bool) or not isinstance(value, int) or value < _MINIMUM[key]:
        raise ConfigError(f"--env-kwargs {key}: expected an integer >= {_MINIMUM[key]}, got {value!r}")
    return value


def _ale_env() -> Any:
    """The ALE's Gymnasium env class (importing ale_py registers the ALE/ ids)."""
    return importlib.import_module("ale_py.env").AtariEnv


def wrap_atari(env: gym.Env, options: AtariOptions = ATARI_OPTIONS, learning: bool = True) -> gym.Env:
    """`env` (an ALE env made with `split_kwargs`'s kwargs) preprocessed: the learner's env when
    `learning`, else the plain env (raw rewards, one episode per game); RAM is not stacked."""
    env = AtariFrames(env, options.noop_max, options.frame_skip, options.screen_size)
    if learning and options.terminal_on_life_loss:
        env = EpisodicLife(env)
    if learning and options.clip_rewards:
        env = ClipReward(env)
    return env if options.obs_type == "ram" else StackFrames(env, options.frame_stack)


def make_atari(
    env_id: str,
    env_kwargs: Mapping[str, Any] | None = None,
    learning: bool = True,
    render_mode: str | None = None,
    **make_options: Any,
) -> gym.Env:
    """`gym.make` of ALE env `env_id` (`ale_py:ALE/<Game>-v5`) with the ALE kwargs of `env_kwargs`,
    then `wrap_atari` with its options; `make_options` (e.g. `max_episode_steps`) go to `gym.make`."""
    module, _, bare = env_id.rpartition(":")
    importlib.import_module(module or "ale_py")
    options, make_kwargs = split_kwargs(env_kwargs)
    rendering: dict[str, Any] = {} if render_mode is None else {"render_mode": render_mode}
    return wrap_atari(gym.make(bare, **make_options, **make_kwargs, **rendering), options, learning)
