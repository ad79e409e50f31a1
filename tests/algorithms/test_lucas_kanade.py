"""Dense Lucas-Kanade (thesis 2.1.1): known motions, zero motion, degenerate and bad input."""

from __future__ import annotations

import numpy as np
import pytest
from tests.algorithms.synthetic import affine_field, rotation_about, translation

from algorithms.lucas_kanade_flow import lucas_kanade
from algorithms.registry import get_flow_method

M = 16  # px left out at each border: the window and the warp see past the edge there


def test_registered_under_its_name():
    assert get_flow_method("lucas_kanade") is lucas_kanade


def test_subpixel_translation_thesis_form(make_pair):
    f0, f1 = make_pair(translation(0.3, -0.4))
    flow, valid = lucas_kanade(f0, f1)
    inner = flow[M:-M, M:-M][valid[M:-M, M:-M]]
    assert valid[M:-M, M:-M].mean() > 0.95
    # one linearisation of a 0.5 px motion: within 0.05 px everywhere inside
    np.testing.assert_allclose(inner, np.broadcast_to([0.3, -0.4], inner.shape), atol=0.05)


def test_large_translation_needs_and_gets_the_pyramid(make_pair):
    f0, f1 = make_pair(translation(3.0, -2.0))
    flow, valid = lucas_kanade(f0, f1, levels=3, iterations=3)
    inner = flow[M:-M, M:-M]
    np.testing.assert_allclose(np.median(inner, axis=(0, 1)), [3.0, -2.0], atol=0.02)
    assert np.abs(inner - [3.0, -2.0]).max() < 0.1
    single, _ = lucas_kanade(f0, f1)
    assert np.abs(np.median(single[M:-M, M:-M], axis=(0, 1)) - [3.0, -2.0]).max() > 0.3


def test_warps_converge_on_a_translation_with_the_box_window(make_pair):
    """Each warp adds its solve to the window mean of the current flow: the error settles
    instead of growing in the modes where the box window's response is negative (an increment
    added pixel by pixel grew from 0.03 px after 3 warps to 0.07 px after 20)."""
    f0, f1 = make_pair(translation(0.7, -0.4))

    def mean_error(warps: int) -> float:
        flow, _ = lucas_kanade(f0, f1, iterations=warps, median_px=0)
        return float(np.hypot(*(flow - [0.7, -0.4])[M:-M, M:-M].transpose(2, 0, 1)).mean())

    few, many = mean_error(3), mean_error(20)
    assert many < 0.02
    assert many <= few + 1e-3


def test_small_rotation(make_pair):
    motion = rotation_about(47.5, 47.5, 2.0)  # up to 1.7 px at the corners
    f0, f1 = make_pair(motion)
    flow, _ = lucas_kanade(f0, f1, levels=3, iterations=3)
    err = np.hypot(*(flow - affine_field(motion, flow.shape[:2])).transpose(2, 0, 1))[M:-M, M:-M]
    assert err.mean() < 0.06


def test_zero_motion_is_exactly_zero(make_pair):
    f0, _ = make_pair()
    for kw in ({}, {"levels": 3, "iterations": 2}):
        flow, valid = lucas_kanade(f0, f0.copy(), **kw)
        assert not flow.any()
        assert valid.mean() > 0.95


def test_content_moving_right_and_down_gives_positive_u_v(make_pair):
    f0, f1 = make_pair(translation(0.5, 0.5))
    flow, _ = lucas_kanade(np.round(f0).astype(np.uint8), np.round(f1).astype(np.uint8))
    assert (np.median(flow[M:-M, M:-M], axis=(0, 1)) > 0.3).all()


def test_rgb_equals_gray_of_same_luma(make_pair):
    f0, f1 = make_pair(translation(0.3, 0.2))
    rgb0, rgb1 = np.repeat(f0[..., None], 3, axis=2), np.repeat(f1[..., None], 3, axis=2)
    np.testing.assert_allclose(lucas_kanade(rgb0, rgb1)[0], lucas_kanade(f0, f1)[0], atol=1e-4)


def test_flat_image_is_invalid_not_nan():
    flat = np.full((40, 40), 7.0, np.float32)
    flow, valid = lucas_kanade(flat, flat)
    assert not valid.any()
    assert np.isfinite(flow).all() and not flow.any()


def test_flat_patch_in_texture_is_invalid(make_pair):
    f0, f1 = make_pair(translation(0.2, 0.0))
    f0[30:70, 30:70] = 100.0
    f1[30:70, 30:70] = 100.0
    flow, valid = lucas_kanade(f0, f1)
    assert not valid[45:55, 45:55].any()
    assert np.isfinite(flow).all()


@pytest.mark.parametrize("a, b, exc, match", [
    (np.zeros((20, 20)), np.zeros((20, 21)), ValueError, "differ in size"),
    (np.full((20, 20), np.nan), np.zeros((20, 20)), ValueError, "NaN"),
    (np.zeros((20, 20), complex), np.zeros((20, 20)), TypeError, "complex"),
    (np.zeros((20, 20), bool), np.zeros((20, 20), bool), TypeError, "bool"),
    (np.zeros((20, 20), object), np.zeros((20, 20)), TypeError, "object"),
    (np.zeros((0, 0)), np.zeros((0, 0)), ValueError, "at least 2x2"),
])
def test_bad_frames_rejected(a, b, exc, match):
    with pytest.raises(exc, match=match):
        lucas_kanade(a, b)


def test_bad_parameters_rejected():
    f = np.zeros((20, 20), np.float32)
    with pytest.raises(ValueError, match="window: expected an odd"):
        lucas_kanade(f, f, window=4)
    with pytest.raises(ValueError, match="levels and iterations"):
        lucas_kanade(f, f, levels=0)
    with pytest.raises(ValueError, match="min_eigenvalue"):
        lucas_kanade(f, f, min_eigenvalue=0.0)
