"""The flow convention: input checks, warping direction, colour coding."""

from __future__ import annotations

import numpy as np
import pytest

from algorithms.flow import as_gray, check_flow, check_frame_pair, color_wheel_image, flow_to_color, warp_backward


def _texture(rng: np.random.Generator, h: int = 48, w: int = 64) -> np.ndarray:
    import cv2

    noise = rng.random((h, w)).astype(np.float32)
    return cv2.GaussianBlur(noise, (0, 0), 1.5) * 255.0


def test_uint8_rgb_becomes_float32_gray_in_the_same_units():
    rgb = np.zeros((4, 5, 3), np.uint8)
    rgb[..., 0] = 100  # red only
    g = as_gray(rgb)
    assert g.dtype == np.float32 and g.shape == (4, 5)
    np.testing.assert_allclose(g, 0.299 * 100, rtol=1e-6)
    np.testing.assert_array_equal(as_gray(np.full((3, 3), 7, np.uint8)), np.full((3, 3), 7.0, np.float32))


@pytest.mark.parametrize(
    "bad, exc, match",
    [
        (np.zeros((4, 4), bool), TypeError, "dtype bool"),
        (np.zeros((4, 4), complex), TypeError, "dtype complex"),
        (np.zeros((4, 4), object), TypeError, "dtype object"),
        (np.zeros((0, 4), np.uint8), ValueError, "at least 2x2"),
        (np.zeros((4, 4, 4, 1), np.uint8), ValueError, r"expected \(H, W\) gray or \(H, W, 3\) RGB"),
        (np.full((4, 4), np.nan, np.float32), ValueError, "16 pixel"),
    ],
)
def test_bad_frames_are_rejected_with_a_message(bad, exc, match):
    with pytest.raises(exc, match=match):
        as_gray(bad)


def test_frames_of_different_size_are_rejected():
    with pytest.raises(ValueError, match=r"differ in size: \(4, 4\) vs \(4, 5\)"):
        check_frame_pair(np.zeros((4, 4)), np.zeros((4, 5)))


def test_channels_first_flow_gets_a_hint():
    with pytest.raises(ValueError, match=r"expected \(H, W, 2\) float32, got \(2, 5, 6\) float64 \(channels first"):
        check_flow(np.zeros((2, 5, 6)))
    with pytest.raises(TypeError, match="got \\(5, 6, 2\\) int64"):
        check_flow(np.zeros((5, 6, 2), np.int64))


def test_warping_frame1_by_the_true_flow_gives_frame0():
    rng = np.random.default_rng(3)
    big = _texture(rng, 60, 80)
    frame0 = big[5:53, 5:69]
    frame1 = big[5 - 2 : 53 - 2, 5 - 3 : 69 - 3]  # content moved +3 px in x, +2 px in y
    flow = np.zeros(frame0.shape + (2,), np.float32)
    flow[..., 0], flow[..., 1] = 3.0, 2.0
    warped, inside = warp_backward(frame1, flow)
    np.testing.assert_allclose(warped[inside], frame0[inside], atol=1e-3)
    assert not inside[:, -3:].any() and inside[:-2, :-3].all()


def test_colour_coding_follows_the_middlebury_wheel():
    flow = np.zeros((1, 4, 2), np.float32)
    flow[0, 0] = (1, 0)   # right: red
    flow[0, 1] = (-1, 0)  # left: cyan-blue
    flow[0, 2] = (0, -1)  # up: blue-violet
    flow[0, 3] = (0, 0)   # no motion: white
    rgb = flow_to_color(flow, max_magnitude=1.0).astype(int)
    assert rgb[0, 0, 0] == 255 and rgb[0, 0, 1] < 30 and rgb[0, 0, 2] < 30
    assert rgb[0, 1, 0] < 30 and rgb[0, 1, 1] > 150 and rgb[0, 1, 2] == 255
    assert rgb[0, 2, 2] == 255 and rgb[0, 2, 0] < 120 and rgb[0, 2, 1] < 30
    assert (rgb[0, 3] == 255).all()


def test_unknown_flow_is_drawn_black_and_the_legend_is_a_disc():
    flow = np.full((2, 2, 2), np.nan, np.float32)
    assert (flow_to_color(flow) == 0).all()
    wheel = color_wheel_image(21)
    assert wheel.shape == (21, 21, 3) and (wheel[0, 0] == 255).all() and (wheel[10, 10] == 255).all()
    with pytest.raises(ValueError, match="at least 3"):
        color_wheel_image(2)
