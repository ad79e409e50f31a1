"""Horn-Schunck (thesis 2.1.2): the eq. 2.15-2.22 discretisation against an independent oracle, known motions."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from algorithms.horn_schunck_flow import (
    _cube_flow_to_pixels,
    _hs_linearise,
    cube_to_pixels,
    horn_schunck,
    hs_derivatives,
    hs_iterate,
    pixels_to_cube,
)
from algorithms.pyramid import target_inside
from algorithms.registry import get_flow_method
from tests.algorithms.synthetic import affine_field, rotation_about, translation

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


def _plain_iteration(Ex, Ey, Et, u, v, alpha, sweeps):
    """Eqs. 2.17, 2.21, 2.22 written with numpy in float64, edges replicated."""
    un, vn = u.astype(np.float64), v.astype(np.float64)
    Ex, Ey, Et = (a.astype(np.float64) for a in (Ex, Ey, Et))

    def bar(p):
        return (p[:-2, 1:-1] + p[2:, 1:-1] + p[1:-1, :-2] + p[1:-1, 2:]) / 6 \
            + (p[:-2, :-2] + p[:-2, 2:] + p[2:, :-2] + p[2:, 2:]) / 12

    for _ in range(sweeps):
        u_bar, v_bar = bar(np.pad(un, 1, mode="edge")), bar(np.pad(vn, 1, mode="edge"))
        r = (Ex * u_bar + Ey * v_bar + Et) / (alpha**2 + Ex**2 + Ey**2)
        un, vn = u_bar - Ex * r, v_bar - Ey * r
    return un, vn


TINY_AND_ODD = [(1, 1), (1, 6), (6, 1), (2, 2), (2, 3), (3, 2), (5, 9), (8, 13), (9, 12)]


def _terms(shape, seed):
    rng = np.random.default_rng(seed)
    Ex, Ey, Et = (rng.normal(0, 5, shape).astype(np.float32) for _ in range(3))
    u, v = (rng.normal(0, 1, shape).astype(np.float32) for _ in range(2))
    return Ex, Ey, Et, u, v


@pytest.mark.parametrize("sweeps", [1, 2, 3, 7])
@pytest.mark.parametrize("shape", TINY_AND_ODD)
def test_kernel_equals_plain_equations(shape, sweeps):
    """The numba iteration against eqs. 2.17, 2.21, 2.22 written with numpy in float64: equal
    within float32 rounding, from a random start, at tiny and odd sizes, even and odd sweep counts."""
    Ex, Ey, Et, u, v = _terms(shape, seed=sweeps)
    un, vn = _plain_iteration(Ex, Ey, Et, u, v, 4.0, sweeps)
    assert hs_iterate(Ex, Ey, Et, u, v, 4.0, sweeps, 0.0) == sweeps
    np.testing.assert_allclose(u, un, rtol=0, atol=2e-6 * sweeps * max(1.0, np.abs(un).max()))
    np.testing.assert_allclose(v, vn, rtol=0, atol=2e-6 * sweeps * max(1.0, np.abs(vn).max()))


def _round32(x: Fraction) -> np.float32:
    """The float32 nearest to the exact ``x`` (ties to even), not through a float64 rounding first."""
    f = np.float32(float(x))
    best = f
    for c in (np.nextafter(f, np.float32(-np.inf)), np.nextafter(f, np.float32(np.inf))):
        d, d_best = abs(Fraction(float(c)) - x), abs(Fraction(float(best)) - x)
        if d < d_best or (d == d_best and int(c.view(np.int32)) % 2 == 0):
            best = c
    return best


def _fma32(a, b, c) -> np.float32:
    return _round32(Fraction(float(a)) * Fraction(float(b)) + Fraction(float(c)))


def _stepwise_sweep(u, v, Ex, Ey, Et, inv_den):
    """One sweep, one float32 rounding per step in the order the kernel documents (exact FMAs)."""
    h, w = u.shape
    c4, c8 = np.float32(1 / 6), np.float32(1 / 12)
    out_u, out_v = np.empty_like(u), np.empty_like(v)
    for i in range(h):
        im, ip = max(i - 1, 0), min(i + 1, h - 1)
        for j in range(w):
            jm, jp = max(j - 1, 0), min(j + 1, w - 1)
            sums = []
            for f in (u, v):
                if 0 < j < w - 1:
                    sums += [((f[i, jp] + f[im, j]) + f[ip, j]) + f[i, jm],
                             ((f[im, jp] + f[im, jm]) + f[ip, jp]) + f[ip, jm]]
                else:  # edge column: f[im, j] + f[ip, j] first, shared by both sums
                    o = jp if j == 0 else jm
                    z = f[ip, j] + f[im, j]
                    sums += [(z + f[i, jp]) + f[i, jm], (z + f[im, o]) + f[ip, o]]
            u_bar = _fma32(sums[1], c8, sums[0] * c4)  # eq. 2.17
            v_bar = _fma32(sums[3], c8, sums[2] * c4)
            rho = _fma32(Ey[i, j], v_bar, _fma32(Ex[i, j], u_bar, Et[i, j])) * inv_den[i, j]
            out_u[i, j] = _fma32(-Ex[i, j], rho, u_bar)  # eq. 2.21
            out_v[i, j] = _fma32(-Ey[i, j], rho, v_bar)  # eq. 2.22
    return out_u, out_v


def _stepwise_iteration(Ex, Ey, Et, u, v, alpha, sweeps, tol):
    a2 = np.float32(alpha * alpha)
    inv_den = np.array([[np.float32(1) / _fma32(ey, ey, _fma32(ex, ex, a2)) for ex, ey in zip(rx, ry)]
                        for rx, ry in zip(Ex, Ey)], dtype=np.float32)
    for done in range(1, sweeps + 1):
        un, vn = _stepwise_sweep(u, v, Ex, Ey, Et, inv_den)
        change = max(np.abs(un - u).max(), np.abs(vn - v).max())
        u, v = un, vn
        if tol > 0 and change < tol:
            break
    return u, v, done


@pytest.mark.parametrize("sweeps", [1, 2, 3])
@pytest.mark.parametrize("shape", [(1, 1), (1, 5), (5, 1), (2, 2), (3, 4), (5, 6)])
def test_kernel_rounds_as_documented(shape, sweeps):
    """Bit for bit the documented float32 steps (sums in order, fused multiply-adds): what the
    kernel's results are pinned to, whatever LLVM does around it (fastmath would reorder them)."""
    Ex, Ey, Et, u, v = _terms(shape, seed=10 + sweeps)
    ur, vr, _ = _stepwise_iteration(Ex, Ey, Et, u, v, 4.0, sweeps, 0.0)
    assert hs_iterate(Ex, Ey, Et, u, v, 4.0, sweeps, 0.0) == sweeps
    assert np.array_equal(u, ur) and np.array_equal(v, vr)


@pytest.mark.parametrize("tol", [1e-2, 1e-3])
def test_tol_stops_after_the_first_small_sweep(tol):
    """tol > 0: the kernel stops after the same sweep as the stepwise reference, with its bits."""
    Ex, Ey, Et, u, v = _terms((4, 5), seed=5)
    ur, vr, done_r = _stepwise_iteration(Ex, Ey, Et, u, v, 8.0, 200, tol)
    assert 1 < done_r < 200
    assert hs_iterate(Ex, Ey, Et, u, v, 8.0, 200, tol) == done_r
    assert np.array_equal(u, ur) and np.array_equal(v, vr)


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


@pytest.mark.parametrize("shape", [(2, 2), (2, 5), (5, 2), (6, 9), (31, 17)])
def test_cube_flow_to_pixels_equals_the_numpy_resampling(shape):
    """The fused numba step (vectorised inner columns, clamped outer ones) against cube_to_pixels and
    target_inside: the same float32 sums in the same order, so the same bits."""
    rng = np.random.default_rng(shape[0] * 100 + shape[1])
    u, v = (rng.normal(0, 3, (shape[0] - 1, shape[1] - 1)).astype(np.float32) for _ in range(2))
    flow = np.empty(shape + (2,), np.float32)
    valid = np.empty(shape, bool)
    _cube_flow_to_pixels(u, v, flow, valid)
    assert np.array_equal(flow[..., 0], cube_to_pixels(u)) and np.array_equal(flow[..., 1], cube_to_pixels(v))
    assert np.array_equal(valid, target_inside(flow))
    if min(shape) > 2:
        assert valid.any() and not valid.all()  # both outcomes of the mask were exercised


@pytest.mark.parametrize("use_inside", [False, True])
@pytest.mark.parametrize("shape", [(2, 2), (2, 5), (5, 2), (6, 9), (31, 17)])
def test_linearise_equals_the_numpy_steps(shape, use_inside):
    """Start and data term of a warp step against pixels_to_cube and Et - Ex u0 - Ey v0 in numpy
    float32 (same order, same bits), the data term dropped where a cube corner was sampled outside."""
    rng = np.random.default_rng(shape[0] * 10 + shape[1])
    flow = rng.normal(0, 2, shape + (2,)).astype(np.float32)
    inside = rng.uniform(0, 1, shape) > 0.2
    Ex, Ey, Et = (rng.normal(0, 5, (shape[0] - 1, shape[1] - 1)).astype(np.float32) for _ in range(3))
    ex, ey, et = Ex.copy(), Ey.copy(), Et.copy()
    u, v = np.empty_like(Ex), np.empty_like(Ex)
    _hs_linearise(ex, ey, et, flow, inside, use_inside, u, v)
    u0, v0 = pixels_to_cube(flow[..., 0]), pixels_to_cube(flow[..., 1])
    assert np.array_equal(u, u0) and np.array_equal(v, v0)
    keep = pixels_to_cube(inside.astype(np.float32)) == 1 if use_inside else np.ones(Ex.shape, bool)
    assert np.array_equal(et, np.where(keep, Et - Ex * u0 - Ey * v0, 0))
    assert np.array_equal(ex, np.where(keep, Ex, 0)) and np.array_equal(ey, np.where(keep, Ey, 0))
    if use_inside and min(shape) > 2:
        assert 0 < keep.sum() < keep.size  # both outcomes exercised
