"""Middlebury colour coding (``flow_to_color``): the numba pass gives the pixels of the numpy expressions it replaced."""

from __future__ import annotations

import numpy as np
import pytest

from algorithms.flow import _WHEEL, check_flow, color_wheel_image, flow_to_color


def _reference(flow, *, max_magnitude=None, valid=None):
    f = check_flow(flow, allow_nan=True).astype(np.float64)
    u, v = f[..., 0], f[..., 1]
    unknown = ~(np.isfinite(u) & np.isfinite(v))
    if valid is not None:
        unknown |= ~np.asarray(valid, bool)
    u = np.where(unknown, 0.0, u)
    v = np.where(unknown, 0.0, v)
    mag = np.hypot(u, v)
    if max_magnitude is None:
        max_magnitude = float(mag.max()) if mag.size else 0.0
    scale = max(float(max_magnitude), 1e-6)
    r = np.minimum(mag / scale, 1.0)
    ncols = _WHEEL.shape[0]
    angle = np.arctan2(-v, -u) / np.pi
    fk = (angle + 1.0) / 2.0 * (ncols - 1)
    k0 = np.floor(fk).astype(int) % ncols
    k1 = (k0 + 1) % ncols
    frac = (fk - np.floor(fk))[..., None]
    col = ((1 - frac) * _WHEEL[k0] + frac * _WHEEL[k1]) / 255.0
    col = 1.0 - r[..., None] * (1.0 - col)
    rgb = np.round(255.0 * col).astype(np.uint8)
    rgb[unknown] = 0
    return rgb


@pytest.mark.parametrize("scale_px", [0.3, 3.0, 30.0, 300.0])
def test_colours_equal_the_numpy_coding_pixel_for_pixel(scale_px):
    rng = np.random.default_rng(int(scale_px * 10))
    flow = (rng.standard_normal((120, 160, 2)) * scale_px).astype(np.float32)
    flow[rng.random(flow.shape[:2]) < 0.02] = np.nan
    flow[5, :, :] = 0.0  # zero motion: the wheel's start, no saturation
    valid = rng.random(flow.shape[:2]) > 0.1
    for kw in ({}, {"valid": valid}, {"max_magnitude": 2.5}, {"max_magnitude": 2.5, "valid": valid}):
        np.testing.assert_array_equal(flow_to_color(flow, **kw), _reference(flow, **kw))


def test_unknown_pixels_are_black_and_the_wheel_legend_is_unchanged():
    flow = np.full((4, 5, 2), np.nan, np.float32)
    assert not flow_to_color(flow).any()
    c = 50.0
    ys, xs = np.mgrid[0:101, 0:101].astype(np.float32)
    field = np.stack([(xs - c) / c, (ys - c) / c], axis=-1)
    outside = np.hypot(field[..., 0], field[..., 1]) > 1.0
    expected = _reference(field, max_magnitude=1.0)
    expected[outside] = 255
    np.testing.assert_array_equal(color_wheel_image(101), expected)
