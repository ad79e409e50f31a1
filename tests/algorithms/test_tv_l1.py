"""Our TV-L1 (algorithms.tv_l1_flow): the fused kernel against the papers' equations, known motions, bad input."""

from __future__ import annotations


import numpy as np
import pytest
from tests.algorithms.synthetic import translation, wave_texture

import algorithms
from algorithms.registry import get_flow_method
from algorithms.tv_l1_flow import _with_gradient, tv_l1, tv_l1_iterate

M = 12  # border excluded from the error of synthetic pairs, px


def _pair(dx: float, dy: float, shape=(96, 96), seed=0):
    return wave_texture(np.random.default_rng(seed), shape, motion=translation(dx, dy))


def _inner_error(flow: np.ndarray, dx: float, dy: float) -> float:
    inner = flow[M:-M, M:-M]
    return float(np.hypot(inner[..., 0] - dx, inner[..., 1] - dy).mean())


def test_registered_and_exported_under_its_name():
    assert get_flow_method("tv_l1") is tv_l1
    assert algorithms.tv_l1 is tv_l1
    from algorithms.reference import tvl1

    assert get_flow_method("tvl1") is tvl1  # scikit-image's stays the reference


def test_kernel_equals_plain_equations():
    """The fused row pass against the thresholding step and Chambolle's projection written with numpy."""
    rng = np.random.default_rng(5)
    h, w = 7, 9
    a, b, rho0 = (rng.normal(0, 3, (h, w)).astype(np.float32) for _ in range(3))
    inv_g2 = (1.0 / (a * a + b * b)).astype(np.float32)
    u = [rng.normal(0, 0.5, (h, w)).astype(np.float32) for _ in range(2)]
    p = [np.zeros((h, w), np.float32) for _ in range(4)]
    lam, theta, tau, n = 0.4, 0.3, 0.25, 6

    def grad(f):  # forward differences, 0 across the last column / row
        gx, gy = np.zeros_like(f), np.zeros_like(f)
        gx[:, :-1] = f[:, 1:] - f[:, :-1]
        gy[:-1, :] = f[1:, :] - f[:-1, :]
        return gx, gy

    def div(px, py):  # minus the adjoint of grad
        d = px.copy()
        d[:, 1:] -= px[:, :-1]
        d += py
        d[1:, :] -= py[:-1, :]
        return d

    U = [x.astype(np.float64) for x in u]
    P = [np.zeros((h, w)) for _ in range(4)]
    for _ in range(n):
        rho = rho0 + a * U[0] + b * U[1]
        g2 = a * a + b * b
        V = [np.where(rho < -lam * theta * g2, U[0] + lam * theta * a,
                      np.where(rho > lam * theta * g2, U[0] - lam * theta * a, U[0] - rho * a / g2)),
             np.where(rho < -lam * theta * g2, U[1] + lam * theta * b,
                      np.where(rho > lam * theta * g2, U[1] - lam * theta * b, U[1] - rho * b / g2))]
        U = [V[0] + theta * div(P[0], P[1]), V[1] + theta * div(P[2], P[3])]
        for d in range(2):
            gx, gy = grad(U[d])
            den = 1 + tau / theta * np.hypot(gx, gy)
            P[2 * d] = (P[2 * d] + tau / theta * gx) / den
            P[2 * d + 1] = (P[2 * d + 1] + tau / theta * gy) / den
    assert tv_l1_iterate(a, b, rho0, inv_g2, u[0], u[1], *p, lam, theta, tau, n, 0.0) == n
    for ours, plain in zip(u + p, U + P):
        np.testing.assert_allclose(ours, plain, atol=2e-5)
    assert np.abs(P[0]).max() > 0.05  # the duals moved: the comparison is not of zeros


@pytest.mark.parametrize("h, w, n, exact", [(40, 37, 15, True), (5, 40, 15, True), (30, 8, 3, True),
                                             (1, 6, 3, True), (23, 1, 4, True), (16, 12, 15, False)])
def test_wavefront_equals_row_by_row(h, w, n, exact):
    """All iterations in one sweep (epsilon 0) give the same bits as iteration after iteration.

    A stopping rule that never fires (epsilon 1e-30 px) takes the row-by-row loop;
    the cases include fewer rows than iterations and a single row / column. Rows
    of 9 to 16 px: the two compiled loops split vector and scalar code
    differently there, and fastmath's vector reciprocal rounds unlike a division,
    so only close (the pyramid's levels of 640x480 and 160x120 are not that narrow).
    """
    rng = np.random.default_rng(h * w + n)
    a, b, rho0 = (rng.normal(0, 3, (h, w)).astype(np.float32) for _ in range(3))
    inv_g2 = (1.0 / (a * a + b * b)).astype(np.float32)
    u = [rng.normal(0, 0.5, (h, w)).astype(np.float32) for _ in range(2)]
    runs = []
    for eps in (0.0, 1e-30):
        arrays = [x.copy() for x in u] + [np.zeros((h, w), np.float32) for _ in range(4)]
        assert tv_l1_iterate(a, b, rho0, inv_g2, *arrays, 0.15, 0.3, 0.25, n, eps) == n
        runs.append(arrays)
    for sweep, rows in zip(*runs):
        if exact:
            np.testing.assert_array_equal(sweep, rows)
        else:
            np.testing.assert_allclose(sweep, rows, rtol=0, atol=1e-6)
    assert not np.array_equal(runs[0][0], u[0])  # u moved


def test_gradient_stack_is_central_differences_with_replicated_edges():
    img = np.random.default_rng(3).uniform(0, 255, (6, 7)).astype(np.float32)
    out = _with_gradient(img)
    p = np.pad(img, 1, mode="edge")
    assert out.shape == (6, 7, 4) and out.dtype == np.float32
    np.testing.assert_array_equal(out[..., 0], img)
    np.testing.assert_array_equal(out[..., 1], np.float32(0.5) * (p[1:-1, 2:] - p[1:-1, :-2]))
    np.testing.assert_array_equal(out[..., 2], np.float32(0.5) * (p[2:, 1:-1] - p[:-2, 1:-1]))
    np.testing.assert_array_equal(out[..., 3], 0)


def test_epsilon_stops_early():
    f0, f1 = _pair(0.3, 0.2)
    a = np.full(f0.shape, 1.0, np.float32)
    z = [np.zeros(f0.shape, np.float32) for _ in range(7)]
    done = tv_l1_iterate(a, a, z[0], 0.5 * a, *z[1:], 0.15, 0.3, 0.25, 1000, 0.01)
    assert 1 <= done < 1000


@pytest.mark.parametrize("dx, dy", [(0.4, -0.3), (-0.25, 0.6)])
def test_subpixel_translation(dx, dy):
    f0, f1 = _pair(dx, dy)
    flow, valid = tv_l1(f0, f1)
    assert flow.shape == f0.shape + (2,) and flow.dtype == np.float32
    assert _inner_error(flow, dx, dy) < 0.03
    assert valid[M:-M, M:-M].all()


def test_a_few_pixels_needs_the_pyramid():
    dx, dy = 6.4, -4.7
    f0, f1 = _pair(dx, dy, shape=(128, 128), seed=2)
    assert _inner_error(tv_l1(f0, f1)[0], dx, dy) < 0.05
    assert _inner_error(tv_l1(f0, f1, n_scales=1)[0], dx, dy) > 2.0  # one scale, five warps: lost


def test_zero_motion_is_exactly_zero():
    f0, _ = _pair(0.0, 0.0)
    flow, valid = tv_l1(f0, f0.copy())
    assert np.abs(flow).max() < 1e-6
    assert valid.all()


def test_sign_convention_shift_right_gives_positive_u():
    """Frame t+1 is frame t moved 2 px right (+x) and 1 px down (+y): u = +2, v = +1."""
    f0, _ = _pair(0.0, 0.0, shape=(80, 96), seed=3)
    f1 = np.roll(np.roll(f0, 2, axis=1), 1, axis=0)
    flow = tv_l1(f0, f1)[0]
    assert _inner_error(flow, 2.0, 1.0) < 0.05


def test_intensity_scale_and_dtype_do_not_matter():
    """Both frames are mapped onto 0..255 first: an affine change of the intensities changes nothing."""
    f0, f1 = _pair(0.7, 0.2, seed=4)
    flow_a = tv_l1(f0, f1)[0]
    flow_b = tv_l1(f0.astype(np.float64) / 255.0 * 3.0 + 7.0, f1.astype(np.float64) / 255.0 * 3.0 + 7.0)[0]
    np.testing.assert_allclose(flow_a, flow_b, atol=1e-3)
    rgb0 = np.repeat(np.round(f0)[..., None], 3, axis=2).astype(np.uint8)
    rgb1 = np.repeat(np.round(f1)[..., None], 3, axis=2).astype(np.uint8)
    assert _inner_error(tv_l1(rgb0, rgb1)[0], 0.7, 0.2) < 0.05


def test_constant_frames_are_not_valid():
    f = np.full((32, 40), 77, np.uint8)
    flow, valid = tv_l1(f, f)
    assert not valid.any() and np.abs(flow).max() == 0


@pytest.mark.parametrize("kwargs, match", [
    ({"lambda_": 0.0}, r"lambda_: expected a finite value > 0, got 0.0"),
    ({"theta": float("nan")}, r"theta: expected a finite value > 0, got nan"),
    ({"tau": 0.3}, r"tau: expected a time step in \(0, 0.25\], got 0.3"),
    ({"zoom": 1.0}, r"zoom: expected a size ratio in \(0, 1\), got 1.0"),
    ({"n_warps": 0}, r"n_warps: expected an integer >= 1, got 0"),
    ({"n_iter": 2.5}, r"n_iter: expected an integer >= 1, got 2.5"),
    ({"epsilon": -1.0}, r"epsilon: expected a finite value >= 0 \(px\), got -1.0"),
    ({"median_px": 4}, r"median_px: expected 0, 3 or 5 px, got 4"),
    ({"interpolation": "nearest"}, r"interpolation: expected one of \['bicubic', 'bilinear'\], got 'nearest'"),
])
def test_bad_parameters_are_rejected(kwargs, match):
    f0, f1 = _pair(0.1, 0.1, shape=(24, 24))
    with pytest.raises(ValueError, match=match):
        tv_l1(f0, f1, **kwargs)


def test_bad_frames_are_rejected():
    f0, f1 = _pair(0.1, 0.1, shape=(24, 24))
    with pytest.raises(ValueError, match=r"frame0 and frame1 differ in size: \(24, 24\) vs \(24, 23\)"):
        tv_l1(f0, f1[:, :-1])
    with pytest.raises(ValueError, match=r"frame1: expected \(H, W\) gray or \(H, W, 3\) RGB, got \(24, 24, 2\)"):
        tv_l1(f0, np.dstack([f1, f1]))
    with pytest.raises(TypeError, match="frame0: expected an integer or real image"):
        tv_l1(f0 > 100, f1)
