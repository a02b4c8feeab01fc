"""A person's demonstrations, tested as a person makes them: `demos play` in a real window on a
virtual screen (Xvfb) receiving real key presses (xdotool), the file it leaves trained on and
replayed; each preset's key map through posted keyboard events under SDL's headless driver."""

import json
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from helpers import REPO, call
from screen import launch, virtual_screen, xdotool

from dqfd_bc_keras import demos
from dqfd_bc_keras.demos.keys import CONTROLS, env_keys, key_map
from dqfd_bc_keras.envs.make import get_task, make_task
from dqfd_bc_keras.tasks import TASKS

PLAY = [sys.executable, "-m", "dqfd_bc_keras.demos", "play"]


@pytest.fixture(scope="module")
def screen() -> Iterator[dict[str, str]]:
    """A virtual X screen for this module's windows."""
    with virtual_screen() as env:
        yield env


def start(env: dict[str, str], *args: object) -> subprocess.Popen:
    """`demos play ARGS` in a window on the virtual screen, once its window is shown and has the keyboard."""
    return launch(env, "play", *args)[0]


def episodes_in(path: Path, timeout: float = 60.0, at_least: int = 1) -> int:
    """Wait until `path` holds at least `at_least` episodes; returns how many it holds."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if path.exists():
            n = demos.load(path).n_episodes
            if n >= at_least:
                return n
        time.sleep(0.05)
    raise AssertionError(f"{path} did not reach {at_least} episode(s) in {timeout} s")


@pytest.mark.slow
def test_a_person_records_two_cartpole_episodes_that_train_and_evaluate(screen, tmp_path):
    out = tmp_path / "mine.npz"
    process = start(screen, "--task", "cartpole", "--episodes", 2, "--fps", 30, "--out", out)
    xdotool(screen, "keydown", "Right")  # starts episode 1 and pushes right until the pole falls
    episodes_in(out, at_least=1)  # episode 2 waits for a key pressed anew: Right still held is not one
    xdotool(screen, "keyup", "Right")
    xdotool(screen, "keydown", "Left")
    stdout, stderr = process.communicate(timeout=60)
    xdotool(screen, "keyup", "Left")
    assert process.returncode == 0, stderr
    data = demos.load(out, task="cartpole", timeout="bootstrap")
    m = data.meta
    assert (m.expert, m.keys, m.fps, m.max_steps, m.episode_seeds) == (
        "human",
        {"left": 0, "right": 1},
        30,
        500,
        [0, 1],
    )
    first, second = data.episodes()
    assert (first.actions == 1).all()  # Right was held from its first step to its last
    assert (second.actions == 0).all() and first.terminated[-1] and second.terminated[-1]
    assert m.plain_returns == [len(first), len(second)]  # +1 a step, the fall not counted
    assert m.episode_returns == [len(first) - 101, len(second) - 101]  # the fall pays −100 instead of +1
    print(f"recorded returns {m.plain_returns}")
    assert "episode 2 of 2 (seed 1): return" in stdout

    run = call("train.py", "--task", "cartpole", "--demos", out, "--quick", "--quiet", "--out", tmp_path / "run")
    assert run.returncode == 0, run.stderr
    evaluated = call("evaluate.py", tmp_path / "run", "--episodes", 2)
    assert evaluated.returncode == 0, evaluated.stderr
    config = json.loads((tmp_path / "run" / "config.json").read_text())
    assert config["expert"] == f"demonstrations from {out} (human)"

    replayed = subprocess.run(
        [*PLAY[:-1], "show", out, "--fps", "200"], env=screen, cwd=REPO, capture_output=True, text=True, timeout=120
    )
    assert replayed.returncode == 0, replayed.stderr
    assert replayed.stdout.count("replayed exactly") == 2


def test_a_kill_in_the_third_episode_keeps_the_first_two_and_append_goes_on(screen, tmp_path):
    out = tmp_path / "mc.npz"
    common = ["--task", "mountaincar", "--max-steps", 30, "--fps", 30, "--out", out]
    process = start(screen, *common, "--episodes", 5)
    for n in (1, 2):  # each episode starts with a key pressed anew
        xdotool(screen, "keydown", "Right")
        assert episodes_in(out, at_least=n) == n
        xdotool(screen, "keyup", "Right")
    xdotool(screen, "keydown", "Right")
    time.sleep(0.3)  # the third episode is in play: 30 steps last a second
    process.kill()
    process.wait()
    xdotool(screen, "keyup", "Right")
    kept = demos.load(out)
    assert kept.n_episodes == 2 and kept.meta.episode_seeds == [0, 1]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mc.npz"]  # no temporary file left behind
    other_rate = call("dqfd_bc_keras.demos", "play", *common[:4], "--fps", 10, "--out", out, "--append")
    assert other_rate.returncode == 2
    assert "its episodes were played with frame rate 30.0, not 10.0: give --fps 30.0" in other_rate.stderr

    process = start(screen, *common, "--append", "--episodes", 1)
    xdotool(screen, "keydown", "Left")
    process.communicate(timeout=60)
    xdotool(screen, "keyup", "Left")
    assert process.returncode == 0
    more = demos.load(out)
    assert more.meta.episode_seeds == [0, 1, 2] and more.n_episodes == 3
    np.testing.assert_array_equal(more.obs[: len(kept)], kept.obs)
    assert (more.episodes()[2].actions == 0).all()


@pytest.mark.slow
def test_a_person_records_into_a_minari_dataset(screen, tmp_path):
    env = {**screen, "MINARI_DATASETS_PATH": str(tmp_path / "minari")}
    process = start(env, "--env", "CartPole-v1", "--episodes", 1, "--fps", 60, "--out", "minari:cartpole/me-v0")
    xdotool(env, "keydown", "Left")
    _, stderr = process.communicate(timeout=60)
    xdotool(env, "keyup", "Left")
    assert process.returncode == 0, stderr
    again = subprocess.run([*PLAY, "--env", "CartPole-v1", "--out", "minari:cartpole/me-v0"], env=env, cwd=REPO,
                           capture_output=True, text=True, timeout=60)  # fmt: skip
    assert again.returncode == 2 and "a Minari dataset of that id exists; pass --force" in again.stderr
    check = "from dqfd_bc_keras.demos import from_minari; d = from_minari('cartpole/me-v0', 'CartPole-v1'); "
    check += "print(d.n_episodes, d.meta.episode_seeds, set(d.actions.tolist()))"
    read = subprocess.run([sys.executable, "-c", check], env=env, cwd=REPO, capture_output=True, text=True, timeout=60)
    assert read.stdout.split("\n")[0] == "1 [0] {0}", read.stderr  # CartPole's keys: ← is action 0


@pytest.mark.slow
def test_ctrl_c_and_escape_keep_what_finished(screen, tmp_path):
    out = tmp_path / "ac.npz"
    process = start(screen, "--task", "acrobot", "--max-steps", 10, "--fps", 30, "--out", out)
    xdotool(screen, "keydown", "Right")
    episodes_in(out, at_least=1)
    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate(timeout=60)
    xdotool(screen, "keyup", "Right")
    assert process.returncode == 130
    n = demos.load(out).n_episodes
    assert f"holds the {n} finished episode(s)" in stderr

    process = start(screen, "--task", "acrobot", "--max-steps", 10, "--fps", 30, "--out", out, "--append")
    xdotool(screen, "key", "Escape")  # quits before any episode is played
    stdout, _ = process.communicate(timeout=60)
    assert process.returncode == 0 and "nothing written" in stdout
    assert demos.load(out).n_episodes == n


@pytest.mark.parametrize("task", [name for name, spec in TASKS.items() if spec.keys])
def test_each_presets_keys_reach_their_actions_through_posted_events(task, monkeypatch):
    """Every entry of the preset's key map, pressed as a key event, gives its action; released, the
    no-key action (or, without one, the last action)."""
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    monkeypatch.setenv("SDL_AUDIODRIVER", "dummy")
    from dqfd_bc_keras.demos.window import Window

    env = make_task(task, render_mode="rgb_array")
    keys = key_map(get_task(task), env)
    assert keys.keys == dict(get_task(task).keys) and keys.source == f"preset {task}"
    assert not keys.names() & set(CONTROLS)
    window = Window(task)
    pg = window.pg
    try:
        env.reset(seed=0)
        window.draw(env.render(), ["a line"])
        for combo, action in keys.keys.items():
            codes = [pg.key.key_code(name) for name in combo.split("+") if name]
            for code in codes:
                pg.event.post(pg.event.Event(pg.KEYDOWN, key=code, mod=0, unicode="", scancode=0))
            assert keys.action(window.poll().down, last=None) == action, combo
            for code in codes:
                pg.event.post(pg.event.Event(pg.KEYUP, key=code, mod=0, unicode="", scancode=0))
            assert keys.action(window.poll().down, last=action) == keys.keys.get("", action)
        pg.event.post(pg.event.Event(pg.KEYDOWN, key=pg.K_p, mod=0, unicode="p", scancode=0))
        assert window.poll().controls == {"pause"}
    finally:
        window.close()
        env.close()


def _velocity_after(task: str, action: int) -> float:
    """What 10 steps of `action` do to the preset's horizontal velocity (CartPole, MountainCar, LunarLander)."""
    column = {"cartpole": 1, "mountaincar": 1, "lunarlander": 2}[task]
    env = make_task(task)
    env.reset(seed=0)
    for _ in range(10):
        obs, *_ = env.step(action)
    return float(obs[column])


@pytest.mark.parametrize("task", ["cartpole", "mountaincar", "lunarlander"])
def test_left_goes_left_and_right_goes_right(task):
    keys = get_task(task).keys
    assert _velocity_after(task, keys["left"]) < _velocity_after(task, keys.get("", keys["right"]))
    assert _velocity_after(task, keys["right"]) > _velocity_after(task, keys.get("", keys["left"]))


def test_acrobots_keys_are_its_torques():
    torque = make_task("acrobot").unwrapped.AVAIL_TORQUE
    keys = get_task("acrobot").keys
    assert (torque[keys["left"]], torque[keys[""]], torque[keys["right"]]) == (-1.0, 0.0, 1.0)


@pytest.mark.parametrize("task", ["minatar-breakout", "minatar-freeway"])
def test_minatar_presets_keys_are_the_games_own(task):
    env = make_task(task)
    assert env_keys(env)[0] == dict(get_task(task).keys)


def test_envs_without_a_preset_play_with_their_own_keys():
    """The ALE's key map (FIRE on space, NOOP with no key), highway-env's meta-actions, MinAtar's action set
    (Asterix's full set, -v0: its preset plays the minimal one)."""
    atari = key_map(get_task("ale_py:ALE/Breakout-v5"), make_task("ale_py:ALE/Breakout-v5"))
    assert (atari.action({"space"}, None), atari.action(set(), None), atari.action({"a"}, None)) == (1, 0, 3)
    assert atari.meanings == ("NOOP", "FIRE", "RIGHT", "LEFT")
    highway = key_map(get_task("highway_env:highway-v0"), make_task("highway_env:highway-v0", max_steps=40))
    assert highway.keys == {"up": 0, "": 1, "down": 2, "right": 3, "left": 4}
    asterix = key_map(get_task("MinAtar/Asterix-v0"), make_task("MinAtar/Asterix-v0", max_steps=100))  # all 6 actions
    assert asterix.keys == {"": 0, "left": 1, "up": 2, "right": 3, "down": 4, "space": 5}


def test_the_fullest_combination_wins_and_no_key_repeats_the_last_action():
    keys = key_map(get_task("cartpole"), make_task("cartpole"), '{"up": 0, "up+space": 1}')
    assert keys.action({"up", "space"}, None) == 1 and keys.action({"up"}, None) == 0
    assert keys.action(set(), 1) == 1 and keys.action(set(), None) is None
    assert keys.action({"x"}, 0) == 0  # a key of no entry is no key


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--env", "FrozenLake-v1"], "FrozenLake-v1 has no key map for its 4 actions: give one with --keys"),
        (["--task", "cartpole", "--keys", "{left: 0}"], "--keys is not JSON"),
        (["--task", "cartpole", "--keys", '{"lft": 0}'], "'lft' is no key name"),
        (["--task", "cartpole", "--keys", '{"left": 2}'], "an action is an int in [0, 2)"),
        (["--task", "cartpole", "--keys", '{"escape": 0}'], "'escape' is the control key to quit"),
        (["--task", "cartpole", "--out", "x.csv"], "--out must be an .npz file or minari:DATASET_ID"),
    ],
)
def test_what_cannot_be_played_is_one_line_before_any_window(flags, message, tmp_path, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)  # no window could open: the error comes first
    out = [] if "--out" in flags else ["--out", tmp_path / "x.npz"]
    answer = call("dqfd_bc_keras.demos", "play", *flags, *out)
    assert answer.returncode == 2
    assert message in answer.stderr and answer.stderr.count("\n") == 1, answer.stderr
    assert not (tmp_path / "x.npz").exists()


def test_append_to_another_tasks_or_a_programs_file_is_refused(tmp_path):
    scripted = tmp_path / "expert.npz"
    assert call("dqfd_bc_keras.demos", "record", "--task", "mountaincar", "--expert", "imperfect",
                "--episodes", 1, "--out", scripted).returncode == 0  # fmt: skip
    before = scripted.read_bytes()
    other = call("dqfd_bc_keras.demos", "play", "--task", "cartpole", "--append", "--out", scripted)
    assert other.returncode == 2
    assert "was recorded on task 'mountaincar', not on the requested 'cartpole'" in other.stderr
    programs = call("dqfd_bc_keras.demos", "play", "--task", "mountaincar", "--append", "--out", scripted)
    assert programs.returncode == 2 and "not a person's" in programs.stderr
    existing = call("dqfd_bc_keras.demos", "play", "--task", "mountaincar", "--out", scripted)
    assert existing.returncode == 2 and "pass --append to add episodes to it or --force" in existing.stderr
    assert scripted.read_bytes() == before


def test_no_display_is_one_line(tmp_path, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.delenv("SDL_VIDEODRIVER", raising=False)
    answer = call("dqfd_bc_keras.demos", "play", "--task", "cartpole", "--out", tmp_path / "x.npz")
    assert answer.returncode == 2 and "cannot open a window" in answer.stderr and "xvfb-run" in answer.stderr


@pytest.mark.parametrize(
    ("task", "expert"),
    [("cartpole", "imperfect"), ("lunarlander", "imperfect"), ("minatar-breakout", "strong"),
     ("mountaincar-goals", "imperfect")],
)  # fmt: skip
def test_show_replays_any_demonstrators_file_exactly(task, expert, tmp_path):
    path = tmp_path / "d.npz"
    assert call("dqfd_bc_keras.demos", "record", "--task", task, "--expert", expert, "--episodes", 2,
                "--seed", 7, "--max-steps", 120, "--out", path).returncode == 0  # fmt: skip
    answer = call("dqfd_bc_keras.demos", "show", path, "--check")
    assert answer.returncode == 0, answer.stderr
    assert answer.stdout.count("replayed exactly") == 2 and "(seed 8)" in answer.stdout


def test_show_names_the_first_step_the_env_disagrees_with(tmp_path):
    path = tmp_path / "d.npz"
    assert call("dqfd_bc_keras.demos", "record", "--task", "acrobot", "--expert", "imperfect",
                "--episodes", 1, "--max-steps", 50, "--out", path).returncode == 0  # fmt: skip
    data = demos.load(path)
    obs, next_obs = data.obs.copy(), data.next_obs.copy()
    next_obs[16, 0] += 1e-3  # as another version of the physics would give
    obs[17, 0] += 1e-3
    tampered = tmp_path / "tampered.npz"
    demos.save(type(data)(**{**vars(data), "obs": obs, "next_obs": next_obs}), tampered)
    answer = call("dqfd_bc_keras.demos", "show", tampered, "--check")
    assert answer.returncode == 2
    assert "episode 0, step 17: the env gives another observation than the file holds" in answer.stderr
    assert "another version of Acrobot-v1" in answer.stderr


def test_show_writes_one_video_per_episode(tmp_path):
    path = tmp_path / "d.npz"
    assert call("dqfd_bc_keras.demos", "record", "--task", "cartpole", "--expert", "imperfect",
                "--episodes", 2, "--max-steps", 30, "--out", path).returncode == 0  # fmt: skip
    answer = call("dqfd_bc_keras.demos", "show", path, "--video", tmp_path / "videos")
    assert answer.returncode == 0, answer.stderr
    assert len(list((tmp_path / "videos").glob("*.mp4"))) == 2


def test_the_python_api_replays_what_the_cli_recorded(tmp_path):
    path = tmp_path / "d.npz"
    recorded = demos.record("acrobot", "imperfect", episodes=2, seed=3, max_steps=40)
    demos.save(recorded, path)
    shown = demos.show(path, window=False, report=None)
    assert shown.meta.episode_seeds == [3, 4] and shown.meta.max_steps == 40


@pytest.mark.slow
def test_the_screenshot_script_grabs_the_window(tmp_path):
    """docs/play_screenshot.py, as the docs' picture is made: a real window, grabbed from the screen."""
    from PIL import Image

    out = tmp_path / "window.png"
    made = subprocess.run(
        [sys.executable, "docs/play_screenshot.py", "--out", out, "--hold", "0.2"],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=180,
    )
    assert made.returncode == 0, made.stderr
    image = np.asarray(Image.open(out).convert("RGB"))
    assert image.shape[1] == 600 and image.shape[0] > 400  # CartPole's 600x400 frame, the text beneath
    assert (image[-100:] == (24, 24, 28)).all(axis=-1).mean() > 0.5  # the text panel's background
    assert len(np.unique(image.reshape(-1, 3), axis=0)) > 10  # a frame and text, not a blank window


@pytest.mark.slow
def test_closing_the_window_quits_and_keeps_the_finished_episodes(tmp_path, monkeypatch):
    """The window's close button (pygame's QUIT event, posted under SDL's headless driver) ends the
    session as Esc does: the episode in play is dropped, the finished ones stay in the file."""
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    monkeypatch.setenv("SDL_AUDIODRIVER", "dummy")
    from dqfd_bc_keras.demos.window import Window

    out, poll = tmp_path / "mc.npz", Window.poll

    def person(window: Window):
        pg = window.pg
        if not out.exists():  # episode 1: Right pressed on the first frame and held
            if not window.held:
                pg.event.post(pg.event.Event(pg.KEYDOWN, key=pg.K_RIGHT, mod=0, unicode="", scancode=0))
        else:  # episode 2 has begun: the window is closed
            pg.event.post(pg.event.Event(pg.QUIT))
        return poll(window)

    monkeypatch.setattr(Window, "poll", person)
    played = demos.play("mountaincar", out, episodes=3, max_steps=5, fps=1000, report=None)
    assert played.n_episodes == 1 and (played.actions == 2).all()
    assert demos.load(out).meta.episode_seeds == [0]
