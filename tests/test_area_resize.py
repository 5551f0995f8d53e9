"""The compiled INTER_AREA resize (``envs/area_resize.py``) gives OpenCV's values, bit for bit.

The reference is ``cv2.resize`` itself, followed by the original's conversion
``swapaxes(resized.astype(float32) / 255.0, 0, 2)``; the pixel wrapper must give the same floats on
every frame, through the compiled path where it applies and through OpenCV where it does not.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from envs.area_resize import AreaResize, area_tables, takes_area_path
from envs.car_racing import FastCarRacing
from envs.wrappers import PixelObservation


def original(frame: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """The original's preprocessing: cv2's INTER_AREA to ``size`` (height, width), then / 255, swapaxes."""
    resized = cv2.resize(frame, (size[1], size[0]), interpolation=cv2.INTER_AREA)
    resized = resized if resized.ndim == 3 else resized[:, :, None]  # cv2 drops a single channel's axis
    return np.ascontiguousarray(np.swapaxes(resized.astype(np.float32) / 255.0, 0, 2))


def frames(rng: np.random.Generator, shape: tuple[int, int, int], count: int):
    """Random frames, coarse ones (large uniform runs, as CarRacing's), and the extremes."""
    for case in range(count):
        frame = rng.integers(0, 256, size=shape, dtype=np.uint8)
        if case % 3 == 1:
            frame = (frame // 85 * 85).astype(np.uint8)
        yield frame
    yield np.zeros(shape, dtype=np.uint8)
    yield np.full(shape, 255, dtype=np.uint8)


def same_bits(got: np.ndarray, expected: np.ndarray) -> bool:
    return got.dtype == expected.dtype and got.shape == expected.shape and np.array_equal(
        got.view(np.uint32), expected.view(np.uint32))


SHAPES = [(96, 96, 3), (96, 96, 1), (97, 85, 3), (85, 97, 3), (168, 90, 3), (90, 168, 3), (255, 255, 3),
          (210, 160, 3), (400, 123, 4), (100, 84, 3)]


@pytest.mark.parametrize("shape", SHAPES, ids=lambda shape: "x".join(map(str, shape)))
def test_area_resize_is_opencvs_bit_for_bit(shape):
    """Factors below 2 (two terms a column), above 2 (three or more), one axis unchanged, 1 to 4 channels."""
    size = (84, 84)
    assert takes_area_path(shape[:2], size)
    resize = AreaResize(shape, size)
    rng = np.random.default_rng(sum(shape))
    for frame in frames(rng, shape, 12):
        assert same_bits(resize(frame), original(frame, size))


@pytest.mark.parametrize("size", [(84, 84), (83, 61), (10, 95), (1, 1)])
def test_area_resize_to_other_sizes(size):
    resize = AreaResize((96, 96, 3), size)
    for frame in frames(np.random.default_rng(size[0]), (96, 96, 3), 6):
        assert same_bits(resize(frame), original(frame, size))


def test_car_racings_columns_are_summed_in_stretches_of_seven_pixels():
    """From 96 to 84, every 8 source pixels make 7 outputs, each reading two neighbouring pixels: 12
    stretches of 21 values (7 RGB pixels) whose terms read consecutive source values, which vectorise."""
    columns, _, stretches, *_ = area_tables((96, 96), (84, 84), 3)
    assert stretches.tolist() == [[21 * k, 21] for k in range(12)]
    for first, length in stretches:
        assert (np.diff(columns[:, first:first + length], axis=1) == 1).all()


def test_the_area_path_is_where_opencv_takes_it():
    """Upscales (on either axis) and whole factors on both axes take OpenCV's other paths."""
    assert not takes_area_path((84, 84), (84, 84))
    assert not takes_area_path((168, 252), (84, 84))
    assert not takes_area_path((64, 64), (84, 84))
    assert not takes_area_path((96, 64), (84, 84))
    assert takes_area_path((168, 96), (84, 84))  # whole on one axis only: the tables
    assert not takes_area_path((0, 96), (84, 84))  # an empty frame: OpenCV's own error, as before


@pytest.mark.parametrize("shape", [(96, 96, 3), (84, 84, 3), (168, 168, 3), (64, 64, 3), (96, 64, 3), (210, 160, 3)])
def test_the_pixel_wrapper_gives_the_originals_floats_on_every_path(shape):
    """Through the compiled path or OpenCV, contiguous or not, and a new array at every call."""
    wrapper = PixelObservation(FastCarRacing())
    rng = np.random.default_rng(shape[0])
    for case, frame in enumerate(frames(rng, shape, 6)):
        frame = np.asfortranarray(frame) if case % 2 else frame
        got = wrapper.observation(frame)
        assert got.flags.c_contiguous and same_bits(got, original(frame, (84, 84)))
    assert wrapper.observation(frame) is not wrapper.observation(frame)  # callers may keep one


def test_car_racing_frames_resize_as_opencv_resizes_them():
    """Real observations: the road, grass, the car and the dashboard, uniform runs and their edges."""
    env = FastCarRacing()
    wrapper = PixelObservation(env)
    frame, _ = env.reset(seed=5)
    rng = np.random.default_rng(5)
    for step in range(150):
        action = np.array([np.sin(step / 9.0), 0.6 if step % 40 < 30 else 0.0, 0.0], dtype=np.float32)
        frame = env.step(action + rng.normal(0.0, 0.1, 3).astype(np.float32))[0]
        assert same_bits(wrapper.observation(frame), original(frame, (84, 84))), f"step {step}"
    env.close()
