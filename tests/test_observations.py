"""Observations: the flattening order by hand and against Gymnasium's, batches, dropped parts, images."""

import re
import warnings

import gymnasium as gym
import numpy as np
import pytest

from dqfd_bc_keras.envs.frames import FrameObservation, FrameOptions, as_frames, split_frame_options
from dqfd_bc_keras.envs.observations import (
    MAX_IMAGE_VALUES,
    FlattenObservation,
    Frames,
    describe,
    is_frames,
    is_image,
    observation_layout,
)
from dqfd_bc_keras.errors import ConfigError, DqfdWarning

Box, Discrete, MultiBinary, MultiDiscrete = (
    gym.spaces.Box,
    gym.spaces.Discrete,
    gym.spaces.MultiBinary,
    gym.spaces.MultiDiscrete,
)


def test_a_flat_box_passes_unchanged():
    layout = observation_layout(Box(-1.0, 1.0, (3,), np.float32))
    assert layout.flat and layout.dim == 3 and layout.dropped == ()
    assert layout.to_dict() == {
        "space": "Box(3,) float32",
        "shape": [3],
        "features": 3,
        "flattened": False,
        "dropped": [],
        "frames": None,
    }


def test_the_order_by_hand():
    """Dict keys sorted (Gymnasium sorts a plain dict), Box in C order, Discrete one-hot from its start,
    MultiDiscrete one one-hot per entry, MultiBinary as bits, Tuple by index."""
    space = gym.spaces.Dict(
        {
            "z": Box(0, 9, (2, 2), np.float32),
            "a": Discrete(3, start=1),
            "m": gym.spaces.Tuple((MultiDiscrete([2, 3]), MultiBinary(2))),
        }
    )
    layout = observation_layout(space)
    obs = {"z": np.array([[1, 2], [3, 4]], np.float32), "a": 2, "m": (np.array([1, 0]), np.array([0, 1], np.int8))}
    want = [
        0,
        1,
        0,  # a = 2 with start 1: index 1 of 3
        0,
        1,
        1,
        0,
        0,
        0,
        1,  # m: (1 of 2) (0 of 3), bits 0 1
        1,
        2,
        3,
        4,
    ]  # z row by row
    assert layout.dim == 14
    np.testing.assert_array_equal(layout.flatten(obs), want)
    np.testing.assert_array_equal(layout.flatten(obs), gym.spaces.flatten(space, obs).astype(np.float32))
    assert layout.flatten(obs).dtype == np.float32


@pytest.mark.parametrize("seed", range(5))
def test_batches_flatten_as_single_observations_do(seed):
    space = gym.spaces.Dict({"d": Discrete(4), "b": Box(-1, 1, (3, 2)), "md": MultiDiscrete([[2, 2], [3, 1]])})
    space.seed(seed)
    samples = [space.sample() for _ in range(6)]
    batch = {key: np.stack([s[key] for s in samples]) for key in ("d", "b", "md")}
    layout = observation_layout(space)
    np.testing.assert_array_equal(layout.flatten(batch, batch=6), np.stack([layout.flatten(s) for s in samples]))
    for sample in samples:
        np.testing.assert_allclose(layout.flatten(sample), gym.spaces.flatten(space, sample), rtol=1e-6)


def test_non_numeric_parts_are_dropped_with_one_warning_naming_them():
    space = gym.spaces.Dict(
        {
            "direction": Discrete(4),
            "image": Box(0, 255, (7, 7, 3), np.uint8),
            "mission": gym.spaces.Text(10),
            "extra": gym.spaces.Tuple((Discrete(2), gym.spaces.Text(3))),
        }
    )
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        layout = observation_layout(space, "minigrid-like")
    assert [str(w.message) for w in caught if w.category is DqfdWarning] == [
        "minigrid-like: dropping non-numeric observation part(s) extra.1, mission (of Dict(direction: Discrete(4), "
        "extra: Tuple(Discrete(2), Text), image: Box(7, 7, 3) uint8, mission: Text))"
    ]
    assert layout.dropped == ("extra.1", "mission") and layout.dim == 4 + 2 + 147
    obs = {"direction": 1, "image": np.full((7, 7, 3), 5, np.uint8), "mission": "go", "extra": (1, "abc")}
    flat = layout.flatten(obs)
    np.testing.assert_array_equal(flat[:6], [0, 1, 0, 0, 0, 1])  # direction, then extra's kept Discrete
    assert (flat[6:] == 5).all()


def test_frames_are_kept_in_their_shape_and_images_inside_a_dict_are_refused():
    assert is_frames(Box(0, 255, (84, 84, 4), np.uint8)) and is_frames(Box(0, 255, (210, 160), np.uint8))
    assert is_frames(Box(0, 1, (10, 10, 4), np.bool_))  # MinAtar
    assert not is_frames(Box(0, 255, (MAX_IMAGE_VALUES,), np.uint8))  # Atari RAM is one-dimensional
    assert not is_frames(Box(0.0, 1.0, (5, 5), np.float32))  # highway-env's kinematics table: a vector
    pong = observation_layout(Box(0, 255, (210, 160, 3), np.uint8), "pong")
    assert pong.image and pong.frames == Frames((210, 160, 3), 1 / 255) and pong.dim == 210 * 160 * 3
    assert pong.text() == "Box(210, 160, 3) uint8 as uint8 frames" and pong.to_dict()["frames"] == {
        "shape": [210, 160, 3],
        "scale": 1 / 255,
        "stack": 1,
    }
    minatar = observation_layout(Box(0, 1, (10, 10, 4), np.bool_), stack=1)
    assert minatar.frames.scale == 1.0 and minatar.frames.frame_shape == (10, 10, 4)
    assert observation_layout(Box(0, 255, (84, 84, 4), np.uint8), stack=4).frames.frame_shape == (84, 84)
    with pytest.raises(
        ConfigError,
        match=re.escape("observes images (part pixels): Box(64, 65, 1) uint8 inside a Dict or Tuple is not supported"),
    ):
        observation_layout(gym.spaces.Dict({"pixels": Box(0, 255, (64, 65, 1), np.uint8)}))
    assert not is_image(Box(0, 255, (7, 7, 3), np.uint8))  # a small grid inside a Dict is flattened
    assert observation_layout(gym.spaces.Dict({"board": Box(0, 1, (4, 4, 16), np.uint8)})).dim == 256


def test_frame_observation_casts_bool_frames_to_bytes():
    class Grid(gym.Env):
        observation_space = Box(0, 1, (2, 2, 1), np.bool_)
        action_space = gym.spaces.Discrete(2)

        def reset(self, *, seed=None, options=None):
            return np.array([[[True], [False]], [[False], [True]]]), {}

    env = FrameObservation(Grid())
    obs, _ = env.reset()
    assert env.observation_space == Box(0, 1, (2, 2, 1), np.uint8)
    assert obs.dtype == np.uint8 and obs[:, :, 0].tolist() == [[1, 0], [0, 1]]


def test_nothing_numeric_is_an_error():
    with pytest.raises(ConfigError, match="has no numeric part"):
        observation_layout(gym.spaces.Dict({"mission": gym.spaces.Text(4)}))


def test_the_wrapper_gives_a_float32_box_of_the_layout():
    class Grid(gym.Env):
        observation_space = Box(-2, 2, (2, 3), np.float64)
        action_space = Discrete(2)

        def reset(self, *, seed=None, options=None):
            return np.arange(6.0).reshape(2, 3), {}

        def step(self, action):
            return -np.arange(6.0).reshape(2, 3), 0.0, True, False, {}

    env = FlattenObservation(Grid(), observation_layout(Grid.observation_space))
    assert env.observation_space == Box(-2, 2, (6,), np.float32)
    obs, _ = env.reset()
    assert obs.dtype == np.float32 and obs.tolist() == [0, 1, 2, 3, 4, 5]
    assert env.step(0)[0].tolist() == [0, -1, -2, -3, -4, -5]
    assert describe(Grid.observation_space) == "Box(2, 3) float64"


@pytest.mark.parametrize(
    "shape, read_as, first",
    [
        ((4, 84, 84), (84, 84, 4), True),  # highway-env's GrayscaleObservation stack
        ((1, 36, 48), (36, 48, 1), True),
        ((84, 84, 4), (84, 84, 4), False),  # Atari's, stacked last
        ((7, 7, 3), (7, 7, 3), False),  # MiniGrid's view
        ((4, 4, 16), (4, 4, 16), False),  # a 4×4 board of 16 planes: its first axis is no shorter than a side
        ((10, 10, 4), (10, 10, 4), False),  # MinAtar's
        ((3, 84), (3, 84), False),  # 2-D: no channel axis
    ],
)
def test_frames_are_channels_first_only_when_the_shape_says_so(shape, read_as, first):
    layout = observation_layout(gym.spaces.Box(0, 255, shape, np.uint8))
    assert (layout.frames.shape, layout.frames.channels_first) == (read_as, first)
    obs = np.arange(np.prod(shape), dtype=np.uint8).reshape(shape)
    moved = as_frames(obs, first)
    assert moved.shape == read_as and (not first or moved[1, 2, 0] == obs[0, 1, 2])


def test_frame_options_say_what_the_shape_and_bounds_cannot():
    space = gym.spaces.Box(0, 255, (4, 4, 3), np.uint8)
    assert observation_layout(space).frames.channels_first is False  # (4, 4, 3): read channels-last
    first = observation_layout(space, "e", 1, split_frame_options({"frame_layout": "channels_first"})[0])
    assert first.frames.shape == (4, 3, 4) and first.frames.channels_first
    assert observation_layout(space).frames.scale == 1 / 255
    assert observation_layout(gym.spaces.Box(0, 10, (7, 7, 3), np.uint8)).frames.scale == 1 / 10  # by its bounds
    options, rest = split_frame_options({"frame_scale": "none", "size": 5})
    assert observation_layout(space, "e", 1, options).frames.scale == 1.0 and rest == {"size": 5}
    assert split_frame_options({"frame_scale": 0.1})[0] == FrameOptions("auto", 0.1)
    for kwargs, says in [
        ({"frame_scale": 0}, "frame_scale=0: expected auto (1/the space's high), none (values as they are"),
        ({"frame_scale": "pixels"}, "frame_scale=pixels: expected auto"),
        ({"frame_layout": "chw"}, "frame_layout=chw: expected one of auto, channels_last, channels_first"),
    ]:
        with pytest.raises(ConfigError, match=re.escape(says)):
            split_frame_options(kwargs)
    with pytest.raises(ConfigError, match=r"frame_layout=channels_first: the frames \(4, 84\) have no channel axis"):
        observation_layout(gym.spaces.Box(0, 255, (4, 84), np.uint8), "e", 1, FrameOptions("channels_first"))
    with pytest.raises(ConfigError, match="toy observes Box\\(5,\\) float32, not frames"):
        observation_layout(gym.spaces.Box(0, 1, (5,), np.float32), "toy", 1, FrameOptions(scale=1.0))
