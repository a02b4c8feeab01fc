"""Key maps: which keys a person presses for which action (`demos play`).

A key map is a dict {keys: action}. Keys are pygame's key names ("left", "a", "space"), several
held together joined by "+" ("up+space"), and "" is no key pressed. At each step the action is
that of the entry with the most keys that are all down (held, or pressed since the last step, so
a tap between two frames counts); with no entry down it is the "" entry's, and a map without one
(CartPole has no action for "no push") repeats the last action.

Where a map comes from, first found: `--keys`, the preset's (`TaskSpec.keys`), the env's own (the
ALE's `get_keys_to_action`, highway-env's meta-actions, MinAtar's action set). An env with none is
refused in one line saying how to give one. The control keys (`CONTROLS`) are never actions.
"""

from __future__ import annotations

import json
import os
import warnings
from collections.abc import Mapping, Set
from dataclasses import dataclass

import gymnasium as gym

from dqfd_bc_keras.envs.make import actions_of
from dqfd_bc_keras.errors import ConfigError
from dqfd_bc_keras.tasks import TASKS, TaskSpec

CONTROLS = {"return": "start", "p": "pause", "backspace": "discard", "escape": "quit"}
"""Keys that steer the recording (pygame names → what they do), never an action."""

MINATAR_KEYS = {"NOOP": "", "LEFT": "left", "UP": "up", "RIGHT": "right", "DOWN": "down", "FIRE": "space"}
"""MinAtar's actions in the order of its full set (`minatar.Environment.action_map`'s letters n l u r d f,
named as the ALE names them) → keys."""
ARROWS = {"left": "Left arrow", "right": "Right arrow", "up": "Up arrow", "down": "Down arrow"}
"""pygame's names of the arrow keys → what the window calls them (pygame's own font has no arrow glyphs)."""
HIGHWAY_KEYS = {"LANE_LEFT": "up", "IDLE": "", "LANE_RIGHT": "down", "FASTER": "right", "SLOWER": "left"}
"""highway-env's meta-actions → keys, as its own manual control (`EventHandler`) has them."""
EXAMPLE = '--keys \'{"left": 0, "right": 1, "": 2}\''


def pygame():
    """pygame, imported quietly; a one-line `ConfigError` if it is not installed."""
    os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
    try:
        import pygame
    except ImportError:
        raise ConfigError("playing and showing demonstrations needs pygame: pip install pygame") from None
    return pygame


@dataclass(frozen=True)
class KeyMap:
    """Keys → actions, checked; `action` resolves what is down."""

    keys: dict[str, int]
    """The map as given (what a recording's meta keeps)."""
    source: str
    """Where it came from, for the window and errors."""
    meanings: tuple[str, ...] = ()
    """The env's names of its actions, where it has them."""

    def action(self, down: Set[str], last: int | None) -> int | None:
        """The action for the keys `down`: the fullest entry all down, else "" 's, else `last`."""
        best = max(
            (combo for combo in self.keys if combo and set(combo.split("+")) <= down),
            key=lambda combo: combo.count("+"),
            default=None,
        )
        if best is not None:
            return self.keys[best]
        return self.keys.get("", last)

    def names(self) -> set[str]:
        """Every key an entry uses."""
        return {name for combo in self.keys if combo for name in combo.split("+")}

    def legend(self) -> list[str]:
        """One short text per entry, the keys as a keyboard names them and the action by its name
        where the env names it: "Left arrow = LEFT", "Space = FIRE", "no key = NOOP", "A = action 3"."""
        return [
            f"{key_label(combo)} = " + (self.meanings[action] if action < len(self.meanings) else f"action {action}")
            for combo, action in self.keys.items()
        ] + ([] if "" in self.keys else ["no key = the last action"])


def key_label(combo: str) -> str:
    """A key map entry's keys as a keyboard names them: "Left arrow", "Space", "A", "Up arrow + Space";
    "" is "no key"."""
    if not combo:
        return "no key"
    return " + ".join(ARROWS.get(name, name.upper() if len(name) == 1 else name.title()) for name in combo.split("+"))


def check_keys(keys: Mapping[str, int], n_actions: int, source: str) -> dict[str, int]:
    """`keys` as a checked map: pygame key names, no control key, int actions in [0, n_actions)."""
    if not isinstance(keys, Mapping) or not keys:
        raise ConfigError(f"{source}: a key map is a non-empty JSON object of keys → actions, e.g. {EXAMPLE}")
    checked = {}
    for combo, action in keys.items():
        if isinstance(action, bool) or not isinstance(action, int) or not 0 <= action < n_actions:
            raise ConfigError(f"{source}: {combo!r} → {action!r}; an action is an int in [0, {n_actions})")
        names = combo.lower().split("+") if combo else []
        for name in names:
            try:
                with warnings.catch_warnings():  # "pygame.init() has not been called": names need no display
                    warnings.simplefilter("ignore")
                    pygame().key.key_code(name)
            except ValueError:
                raise ConfigError(
                    f"{source}: {name!r} is no key name (pygame's names: left, right, up, down, space, a, …)"
                ) from None
            if name in CONTROLS:
                raise ConfigError(f"{source}: {name!r} is the control key to {CONTROLS[name]}, not an action key")
        checked["+".join(names)] = action
    return checked


def parse_keys(text: str, n_actions: int) -> dict[str, int]:
    """A `--keys` JSON object, checked."""
    try:
        keys = json.loads(text)
    except json.JSONDecodeError as error:
        raise ConfigError(f"--keys is not JSON ({error}); e.g. {EXAMPLE}") from None
    return check_keys(keys, n_actions, "--keys")


def env_keys(env: gym.Env) -> tuple[dict[str, int], str, tuple[str, ...]] | None:
    """The env's own key map (the ALE's, highway-env's, MinAtar's), where and its action names; None if it has none."""
    base, n = env.unwrapped, actions_of(env)
    if hasattr(base, "get_keys_to_action"):
        meanings = tuple(base.get_action_meanings()) if hasattr(base, "get_action_meanings") else ()
        keys = {
            "+".join("space" if char == " " else chr(char) if isinstance(char, int) else char for char in combo): action
            for combo, action in base.get_keys_to_action().items()
        }
        if "NOOP" in meanings:
            keys[""] = meanings.index("NOOP")
        return keys, "the env's get_keys_to_action", meanings
    action_type = getattr(base, "action_type", None)
    indexes = getattr(action_type, "actions_indexes", None)
    if isinstance(indexes, Mapping) and set(indexes) <= set(HIGHWAY_KEYS):
        names = tuple(sorted(indexes, key=indexes.__getitem__))
        return {HIGHWAY_KEYS[name]: indexes[name] for name in names}, "highway-env's meta-actions", names
    action_set = getattr(base, "action_set", None)
    if type(base).__module__.startswith("minatar") and action_set is not None and len(action_set) == n:
        names = tuple(list(MINATAR_KEYS)[int(a)] for a in action_set)
        return {MINATAR_KEYS[name]: i for i, name in enumerate(names)}, "MinAtar's action set", names
    return None


def played_like(task: TaskSpec) -> TaskSpec | None:
    """The preset whose keys and rate `task` plays with: itself if it has keys, else a preset of
    the same plain env (`--env CartPole-v1` plays as `cartpole`), else None."""
    if task.keys:
        return task
    return next((spec for spec in TASKS.values() if spec.env_id == task.env_id and spec.keys), None)


def key_map(task: TaskSpec, env: gym.Env, given: Mapping[str, int] | str | None = None) -> KeyMap:
    """The key map to play `task` on `env` with: `given` (a dict, or `--keys`'s JSON), the preset's
    (`played_like`), the env's own."""
    n = actions_of(env)
    own = env_keys(env)
    meanings = own[2] if own else ()
    if given is not None:
        keys = parse_keys(given, n) if isinstance(given, str) else check_keys(given, n, "keys")
        return KeyMap(keys, "--keys", meanings)
    preset = played_like(task)
    if preset is not None:
        return KeyMap(check_keys(preset.keys, n, f"preset {preset.name}'s keys"), f"preset {preset.name}", meanings)
    if own is not None:
        return KeyMap(check_keys(own[0], n, own[1]), own[1], meanings)
    named = f" ({', '.join(f'{i} {m}' for i, m in enumerate(meanings))})" if meanings else ""
    raise ConfigError(
        f"{task.name} has no key map for its {n} actions{named}: give one with {EXAMPLE} "
        '(pygame key names, "+" for keys held together, "" for no key pressed)'
    )
