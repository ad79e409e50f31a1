"""algorithms.pyramid: level sizes, flow rescaling, the target-inside mask, the median, coarse-to-fine driving."""

from __future__ import annotations

import numpy as np
import pytest

from algorithms.pyramid import coarse_to_fine, gaussian_pyramid, median_flow, resize_flow, target_inside


def test_pyramid_halves_until_the_smallest_side_would_drop_below_the_minimum():
    img = np.random.default_rng(0).random((96, 128)).astype(np.float32)
    levels = gaussian_pyramid(img, 6, min_size_px=10)
    assert [lv.shape for lv in levels] == [(96, 128), (48, 64), (24, 32), (12, 16)]  # 6 x 8 is below 10
    assert all(lv.dtype == np.float32 for lv in levels)
    np.testing.assert_array_equal(levels[0], img)


def test_pyramid_keeps_the_mean_of_a_smooth_image():
    ys, xs = np.mgrid[0:64, 0:64].astype(np.float32)
    img = 100 + 20 * np.sin(xs / 9.0) * np.cos(ys / 11.0)
    for lv in gaussian_pyramid(img, 3):
        assert abs(float(lv.mean()) - float(img.mean())) < 1.0


@pytest.mark.parametrize("kw, match", [({"levels": 0}, r"levels: expected at least 1, got 0"),
                                       ({"levels": 2, "scale": 1.0}, r"scale: expected a ratio in \(0, 1\), got 1.0")])
def test_pyramid_refuses_bad_arguments(kw, match):
    with pytest.raises(ValueError, match=match):
        gaussian_pyramid(np.zeros((16, 16), np.float32), **kw)


def test_resize_flow_scales_the_vectors_with_the_pixels():
    flow = np.zeros((10, 20, 2), np.float32)
    flow[..., 0], flow[..., 1] = 1.5, -0.5  # a uniform motion at the coarse level
    fine = resize_flow(flow, (20, 40))
    assert fine.shape == (20, 40, 2) and fine.dtype == np.float32
    np.testing.assert_allclose(fine[..., 0], 3.0, atol=1e-6)
    np.testing.assert_allclose(fine[..., 1], -1.0, atol=1e-6)
    same = resize_flow(flow, (10, 20))
    assert same is not flow and np.array_equal(same, flow)  # a copy, never the caller's array


def test_target_inside_marks_where_x_plus_flow_stays_in_the_frame():
    flow = np.zeros((4, 5, 2), np.float32)
    flow[..., 0] = 1.0  # everything moves one pixel right: the last column leaves the frame
    inside = target_inside(flow)
    assert inside[:, :4].all() and not inside[:, 4].any()


def test_target_inside_and_warp_backward_are_the_float32_sums_and_tests_of_the_numpy_form():
    # the one-pass kernels against the expressions they replace, on points on the frame's edges and NaN
    import cv2

    from algorithms.flow import warp_backward

    rng = np.random.default_rng(2)
    h, w = 31, 47
    flow = rng.uniform(-3, 3, (h, w, 2)).astype(np.float32)
    flow[0, :, 1] = 0.0                       # on the top edge
    flow[:, -1, 0] = 0.0                      # on the right edge
    flow[5, :, 0] = -np.arange(w, dtype=np.float32)  # x + u = 0 exactly
    flow[6, 3] = (np.float32(-3.0000002), 0.0)       # a rounding's width outside
    flow[7, 7] = (np.nan, 0.0)
    xs = np.arange(w, dtype=np.float32)[None, :] + flow[..., 0]
    ys = np.arange(h, dtype=np.float32)[:, None] + flow[..., 1]
    expected = (xs >= 0) & (xs <= w - 1) & (ys >= 0) & (ys <= h - 1)
    assert np.array_equal(target_inside(flow), expected)
    f64 = flow.astype(np.float64)
    assert np.array_equal(target_inside(f64), expected)
    image = rng.uniform(0, 255, (h, w)).astype(np.float32)
    finite = np.nan_to_num(flow)
    xs, ys = np.arange(w, dtype=np.float32)[None, :] + finite[..., 0], np.arange(h, dtype=np.float32)[:, None] + finite[..., 1]
    strided = np.ascontiguousarray(finite.transpose(1, 0, 2)).transpose(1, 0, 2)  # not C-contiguous
    warped, inside = warp_backward(image, strided)
    assert np.array_equal(warped, cv2.remap(image, xs, ys, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE))
    assert np.array_equal(inside, (xs >= 0) & (xs <= w - 1) & (ys >= 0) & (ys <= h - 1))


def test_median_flow_removes_an_isolated_outlier_and_refuses_other_sizes():
    flow = np.ones((9, 9, 2), np.float32)
    flow[4, 4] = (50.0, -50.0)
    np.testing.assert_array_equal(median_flow(flow, 3), np.ones((9, 9, 2), np.float32))
    assert median_flow(flow, 0) is flow
    with pytest.raises(ValueError, match=r"median size: expected 0, 3 or 5 px, got 4"):
        median_flow(flow, 4)


def test_coarse_to_fine_calls_update_coarsest_first_and_rescales_between_levels():
    g = np.zeros((64, 64), np.float32)
    calls = []

    def update(f0, f1w, flow, inside):
        calls.append((f0.shape, float(flow[..., 0].mean())))
        return flow + np.float32(0.5), np.ones(f0.shape, bool)  # adds half a pixel at every level

    flow, valid = coarse_to_fine(g, g, update, levels=3, warps=1)
    assert [c[0] for c in calls] == [(16, 16), (32, 32), (64, 64)]
    # 0.5 at 16 px -> 1.0 at 32 px, + 0.5 -> 3.0 at 64 px, + 0.5
    np.testing.assert_allclose([c[1] for c in calls], [0.0, 1.0, 3.0], atol=1e-6)
    np.testing.assert_allclose(flow, 3.5, atol=1e-5)
    # both components are 3.5 px: the point lands outside frame t+1 in the last 4 columns and rows
    ys, xs = np.mgrid[0:64, 0:64]
    np.testing.assert_array_equal(valid, (xs + 3.5 <= 63) & (ys + 3.5 <= 63))
    with pytest.raises(ValueError, match=r"warps per level\): expected at least 1, got 0"):
        coarse_to_fine(g, g, update, levels=1, warps=0)
