"""Horn-Schunck (thesis 2.1.2): the eq. 2.15-2.22 discretisation against an independent oracle, known motions."""

from __future__ import annotations

import numpy as np
import pytest
from tests.algorithms.synthetic import affine_field, rotation_about, translation

from algorithms.horn_schunck_flow import cube_to_pixels, horn_schunck, hs_derivatives, hs_iterate, pixels_to_cube
from algorithms.registry import get_flow_method

M = 16


def test_registered_under_its_name():
    assert get_flow_method("horn_schunck") is horn_schunck


def test_agrees_with_pyoptflow_one_pixel_off(make_pair):
    """pyoptflow (test-only oracle) uses the same cube derivatives, 1/6-1/12 average and
    alpha**2, but its cube spans pixels (i-1..i, j-1..j) where eq. 2.15's spans (i..i+1, j..j+1),
    and it pads the flow with zeros at the border: compare cube grids offset by one, inside."""
    pyoptflow = pytest.importorskip("pyoptflow")
    f0, f1 = make_pair(translation(0.6, -0.3), shape=(80, 80), seed=1)
    U, V = pyoptflow.HornSchunck(f0, f1, alpha=15.0, Niter=60)
    Ex, Ey, Et = hs_derivatives(f0, f1)
    u, v = np.zeros_like(Ex), np.zeros_like(Ex)
    assert hs_iterate(Ex, Ey, Et, u, v, 15.0, 60, 0.0) == 60
    inner = (slice(M, -M), slice(M, -M))
    assert np.abs(u[inner] - U[1:, 1:][inner]).mean() < 1e-3
    assert np.abs(v[inner] - V[1:, 1:][inner]).mean() < 1e-3
    assert np.abs(u[inner]).mean() > 0.3  # the comparison is not of two near-zero fields


def test_kernel_equals_plain_equations():
    """The fused numba sweep against eqs. 2.17, 2.21, 2.22 written with numpy, odd sweep count."""
    rng = np.random.default_rng(3)
    Ex, Ey, Et = (rng.normal(0, 5, (9, 12)).astype(np.float32) for _ in range(3))
    u, v = np.zeros((9, 12), np.float32), np.zeros((9, 12), np.float32)
    un, vn = u.astype(np.float64), v.astype(np.float64)
    alpha = 4.0
    for _ in range(7):
        pu, pv = np.pad(un, 1, mode="edge"), np.pad(vn, 1, mode="edge")

        def bar(p):
            return (p[:-2, 1:-1] + p[2:, 1:-1] + p[1:-1, :-2] + p[1:-1, 2:]) / 6 \
                + (p[:-2, :-2] + p[:-2, 2:] + p[2:, :-2] + p[2:, 2:]) / 12
        u_bar, v_bar = bar(pu), bar(pv)
        r = (Ex * u_bar + Ey * v_bar + Et) / (alpha**2 + Ex**2 + Ey**2)
        un, vn = u_bar - Ex * r, v_bar - Ey * r
    assert hs_iterate(Ex, Ey, Et, u, v, alpha, 7, 0.0) == 7
    np.testing.assert_allclose(u, un, atol=1e-4)
    np.testing.assert_allclose(v, vn, atol=1e-4)


def test_tol_stops_early(make_pair):
    f0, f1 = make_pair(translation(0.2, 0.1))
    Ex, Ey, Et = hs_derivatives(f0, f1)
    u, v = np.zeros_like(Ex), np.zeros_like(Ex)
    done = hs_iterate(Ex, Ey, Et, u, v, 15.0, 5000, 1e-3)
    assert 1 < done < 5000


def test_derivatives_of_a_ramp():
    ys, xs = np.mgrid[0:6, 0:7].astype(np.float32)
    E0 = 2 * xs + 3 * ys
    Ex, Ey, Et = hs_derivatives(E0, E0 + 5)
    np.testing.assert_allclose(Ex, 2)
    np.testing.assert_allclose(Ey, 3)
    np.testing.assert_allclose(Et, 5)


def test_cube_pixel_resampling_keeps_constants_and_ramps():
    c = np.full((5, 6), 0.7, np.float32)
    np.testing.assert_allclose(cube_to_pixels(c), 0.7, rtol=1e-6)
    ys, xs = np.mgrid[0:8, 0:9].astype(np.float64)
    ramp = pixels_to_cube(xs)  # cube centres at x + 1/2
    np.testing.assert_allclose(ramp, xs[:-1, :-1] + 0.5)
    np.testing.assert_allclose(cube_to_pixels(ramp)[1:-1, 1:-1], xs[1:-1, 1:-1])


def test_subpixel_translation_without_half_pixel_bias(make_pair):
    f0, f1 = make_pair(translation(0.3, -0.4))
    flow, valid = horn_schunck(f0, f1, iterations=500)
    inner = flow[M:-M, M:-M]
    assert valid[M:-M, M:-M].all()
    np.testing.assert_allclose(np.median(inner, axis=(0, 1)), [0.3, -0.4], atol=0.01)
    assert np.abs(inner - [0.3, -0.4]).max() < 0.03


def test_large_translation_with_pyramid(make_pair):
    f0, f1 = make_pair(translation(3.0, -2.0))
    flow, _ = horn_schunck(f0, f1, levels=3)
    assert np.abs(flow[M:-M, M:-M] - [3.0, -2.0]).max() < 0.05


def test_small_rotation(make_pair):
    motion = rotation_about(47.5, 47.5, 2.0)
    f0, f1 = make_pair(motion)
    flow, _ = horn_schunck(f0, f1, levels=3)
    err = np.hypot(*(flow - affine_field(motion, flow.shape[:2])).transpose(2, 0, 1))[M:-M, M:-M]
    assert err.mean() < 0.05


def test_zero_motion_is_exactly_zero(make_pair):
    f0, _ = make_pair()
    for kw in ({}, {"levels": 3}):
        flow, valid = horn_schunck(f0, f0.copy(), **kw)
        assert not flow.any()
        assert valid.all()


def test_content_moving_right_gives_positive_u(make_pair):
    f0, f1 = make_pair(translation(0.5, 0.0))
    flow, _ = horn_schunck(np.round(f0).astype(np.uint8), np.round(f1).astype(np.uint8))
    assert np.median(flow[M:-M, M:-M, 0]) > 0.3


def test_constant_frames_are_invalid_not_nan():
    flat = np.full((30, 30), 50, np.uint8)
    flow, valid = horn_schunck(flat, flat)
    assert not valid.any()
    assert np.isfinite(flow).all()


def test_bad_input_rejected():
    f = np.zeros((20, 20), np.float32)
    with pytest.raises(ValueError, match="differ in size"):
        horn_schunck(f, np.zeros((21, 20)))
    with pytest.raises(TypeError, match="complex"):
        horn_schunck(f.astype(complex), f)
    with pytest.raises(ValueError, match="NaN"):
        horn_schunck(np.full((20, 20), np.nan), f)
    with pytest.raises(ValueError, match="alpha"):
        horn_schunck(f, f, alpha=0.0)
