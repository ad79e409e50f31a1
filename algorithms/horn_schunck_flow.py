"""Horn-Schunck optical flow (thesis 2.1.2, eqs. 2.15-2.22), single scale or coarse-to-fine.

Where the estimate sits
-----------------------
Eq. 2.15 estimates Ex, Ey, Et at the centre of the 2x2x2 cube of pixels
``(i..i+1, j..j+1, t..t+1)``, i.e. at ``(x, y) = (j + 1/2, i + 1/2)``, half a pixel
off our pixel centres. The iteration (eqs. 2.17, 2.21, 2.22) therefore runs on
the ``(H-1, W-1)`` grid of cube centres, exactly as the thesis writes it; the
result is then brought to our pixel centres by bilinear interpolation (the
mean of the up to four cube centres around each pixel). A constant
translation is unchanged by that step, so it is recovered without a
half-pixel bias, and the field is located where our convention says.
At the borders of the cube grid the neighbour average of eq. 2.17 replicates
the edge values (a zero-flux boundary), rather than padding with zero flow.
"""

from __future__ import annotations

import numba
import numpy as np
from llvmlite import ir as llvmir
from numba.extending import intrinsic

from algorithms.flow import FLOW_DTYPE, check_frame_pair
from algorithms.pyramid import coarse_to_fine
from algorithms.registry import register_flow

__all__ = ["horn_schunck", "hs_derivatives", "hs_iterate", "cube_to_pixels", "pixels_to_cube"]


@numba.njit(cache=True)
def hs_derivatives(E0: np.ndarray, E1: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ex, Ey, Et of eq. 2.15 at the cube centres: each ``(H-1, W-1)`` float32.

    Each is the average of the four first differences along the cube's edges
    in its direction; row index i is y, column index j is x, k is time.
    """
    h, w = E0.shape
    Ex = np.empty((h - 1, w - 1), dtype=np.float32)
    Ey = np.empty((h - 1, w - 1), dtype=np.float32)
    Et = np.empty((h - 1, w - 1), dtype=np.float32)
    for i in range(h - 1):
        for j in range(w - 1):
            a0 = E0[i, j]
            b0 = E0[i, j + 1]
            c0 = E0[i + 1, j]
            d0 = E0[i + 1, j + 1]
            a1 = E1[i, j]
            b1 = E1[i, j + 1]
            c1 = E1[i + 1, j]
            d1 = E1[i + 1, j + 1]
            Ex[i, j] = 0.25 * ((b0 - a0) + (d0 - c0) + (b1 - a1) + (d1 - c1))
            Ey[i, j] = 0.25 * ((c0 - a0) + (d0 - b0) + (c1 - a1) + (d1 - b1))
            Et[i, j] = 0.25 * ((a1 - a0) + (b1 - b0) + (c1 - c0) + (d1 - d0))
    return Ex, Ey, Et


# The iteration below is compiled without fastmath and spells out every rounding (the order of
# the sums, the fused multiply-adds), so its results do not depend on how LLVM happens to compile
# and inline it. They are the results of the earlier fastmath kernel as it ran inside hs_iterate
# (its edge columns differed in the last bit when it ran on its own): benchmarks/hs_speed.py
# checks them against that kernel, tests/algorithms/test_horn_schunck.py against a plain
# per-sweep reference of the same steps.


@intrinsic
def _fma(typingctx, a, b, c):
    """``a * b + c`` rounded once (float32 fused multiply-add, ``llvm.fma``)."""
    sig = numba.float32(numba.float32, numba.float32, numba.float32)

    def codegen(context, builder, signature, args):
        f32 = llvmir.FloatType()
        fn = builder.module.declare_intrinsic("llvm.fma", [f32], llvmir.FunctionType(f32, [f32, f32, f32]))
        return builder.call(fn, args)

    return sig, codegen


_C4 = np.float32(1.0 / 6.0)  # eq. 2.17: weight of each 4-neighbour
_C8 = np.float32(1.0 / 12.0)  # and of each diagonal neighbour


# fastmath=False is explicit on every kernel here: numba passes a caller's fastmath on to
# callees that do not set it.
@numba.njit(cache=True, fastmath=False)
def _hs_update(s4u, s8u, s4v, s8v, ex, ey, et, inv_den):
    """New ``(u, v)`` at one point from its neighbour sums (float32 scalars), eqs. 2.17, 2.21, 2.22.

    ``s4u`` is the sum of the 4-neighbours of u, ``s8u`` of the diagonal ones
    (likewise v); ``inv_den = 1 / (alpha^2 + Ex^2 + Ey^2)``.
    """
    u_bar = _fma(s8u, _C8, s4u * _C4)  # eq. 2.17
    v_bar = _fma(s8v, _C8, s4v * _C4)
    rho = _fma(ey, v_bar, _fma(ex, u_bar, et)) * inv_den  # (Ex u_bar + Ey v_bar + Et) / (alpha^2 + Ex^2 + Ey^2)
    return _fma(-ex, rho, u_bar), _fma(-ey, rho, v_bar)  # eqs. 2.21, 2.22


@numba.njit(cache=True, fastmath=False)
def _hs_interior(un, uc, us, vn, vc, vs, Ex, Ey, Et, inv_den, out_u, out_v) -> None:
    """Eqs. 2.17, 2.21, 2.22 along a run of points, from flat ``(n + 2,)`` views of u and v that
    start one point before it in the row above (``un``), its own row (``uc``) and the row below (``us``).

    Point t has its neighbours at ``[t]``, ``[t + 1]``, ``[t + 2]`` of those
    views (left, centre, right), so every index is t plus a constant: no
    negative-index handling, and the loop vectorises.
    """
    for t in range(Ex.shape[0]):
        out_u[t], out_v[t] = _hs_update(
            ((uc[t + 2] + un[t + 1]) + us[t + 1]) + uc[t],
            ((un[t + 2] + un[t]) + us[t + 2]) + us[t],
            ((vc[t + 2] + vn[t + 1]) + vs[t + 1]) + vc[t],
            ((vn[t + 2] + vn[t]) + vs[t + 2]) + vs[t],
            Ex[t], Ey[t], Et[t], inv_den[t])


@numba.njit(cache=True, fastmath=False)
def _hs_sweep(u, v, Ex, Ey, Et, inv_den, out_u, out_v) -> None:
    """One Jacobi sweep of eqs. 2.17, 2.21, 2.22 from ``u, v`` into ``out_u, out_v`` (C-contiguous).

    The interior rows run as one flat loop (:func:`_hs_interior`), which also
    writes the first and last column with wrapped neighbours; the first and
    last row, and then the first and last column of every row, follow with the
    edge replicated.
    """
    h, w = u.shape
    if h > 2 and w > 2:
        # the points k = w + 1 .. (h - 1) w - 2 of the flat arrays: rows 1 .. h - 2 (and columns
        # w - 1 and 0 between them, overwritten below)
        n = h * w
        k0, k1 = w + 1, (h - 1) * w - 1
        uf, vf = u.reshape(n), v.reshape(n)
        _hs_interior(uf[k0 - w - 1:k1 - w + 1], uf[k0 - 1:k1 + 1], uf[k0 + w - 1:k1 + w + 1],
                     vf[k0 - w - 1:k1 - w + 1], vf[k0 - 1:k1 + 1], vf[k0 + w - 1:k1 + w + 1],
                     Ex.reshape(n)[k0:k1], Ey.reshape(n)[k0:k1], Et.reshape(n)[k0:k1], inv_den.reshape(n)[k0:k1],
                     out_u.reshape(n)[k0:k1], out_v.reshape(n)[k0:k1])
    for i in range(h):
        im = max(i - 1, 0)  # the missing neighbour row replicates the edge
        ip = min(i + 1, h - 1)
        if i == 0 or i == h - 1 or w <= 2:
            for j in range(1, w - 1):
                out_u[i, j], out_v[i, j] = _hs_update(
                    ((u[i, j + 1] + u[im, j]) + u[ip, j]) + u[i, j - 1],
                    ((u[im, j + 1] + u[im, j - 1]) + u[ip, j + 1]) + u[ip, j - 1],
                    ((v[i, j + 1] + v[im, j]) + v[ip, j]) + v[i, j - 1],
                    ((v[im, j + 1] + v[im, j - 1]) + v[ip, j + 1]) + v[ip, j - 1],
                    Ex[i, j], Ey[i, j], Et[i, j], inv_den[i, j])
        # first and last column: the missing neighbour replicates the edge, so u[im, j] + u[ip, j]
        # is in both sums (the earlier kernel added it first, once)
        for j in (0, w - 1):  # (at w = 1 both are column 0, with the same result)
            jm = max(j - 1, 0)
            jp = min(j + 1, w - 1)
            o = jp if j == 0 else jm  # the neighbour column that is not j itself
            zu = u[ip, j] + u[im, j]
            zv = v[ip, j] + v[im, j]
            out_u[i, j], out_v[i, j] = _hs_update(
                (zu + u[i, jp]) + u[i, jm], (zu + u[im, o]) + u[ip, o],
                (zv + v[i, jp]) + v[i, jm], (zv + v[im, o]) + v[ip, o],
                Ex[i, j], Ey[i, j], Et[i, j], inv_den[i, j])


@numba.njit(cache=True, fastmath=False, error_model="numpy")
def _hs_inv_den(Ex, Ey, alpha2) -> np.ndarray:
    """``1 / (alpha^2 + Ex^2 + Ey^2)``, the denominator of eqs. 2.21-2.22, ``(h, w)`` float32.

    ``error_model="numpy"``: no zero-division check (``alpha2 > 0``), so the loop vectorises.
    """
    h, w = Ex.shape
    inv_den = np.empty((h, w), dtype=np.float32)
    one = np.float32(1.0)
    for i in range(h):
        for j in range(w):
            inv_den[i, j] = one / _fma(Ey[i, j], Ey[i, j], _fma(Ex[i, j], Ex[i, j], alpha2))
    return inv_den


@numba.njit(cache=True, fastmath=False)
def hs_iterate(Ex: np.ndarray, Ey: np.ndarray, Et: np.ndarray, u: np.ndarray, v: np.ndarray,
               alpha: float, iterations: int, tol: float) -> int:
    """Run the Horn-Schunck iteration in place on ``u``, ``v`` (all ``(h, w)`` float32).

    eq. 2.17  u_bar = 1/6 (4-neighbours) + 1/12 (diagonal neighbours), edges replicated
    eq. 2.21  u <- u_bar - Ex (Ex u_bar + Ey v_bar + Et) / (alpha^2 + Ex^2 + Ey^2)
    eq. 2.22  v <- v_bar - Ey (Ex u_bar + Ey v_bar + Et) / (alpha^2 + Ex^2 + Ey^2)

    Jacobi sweeps (every update uses the previous sweep's field). Stops after
    ``iterations`` sweeps, or earlier once the largest change of a sweep is
    below ``tol`` px (``tol <= 0``: never). Returns the sweeps done.
    """
    h, w = Ex.shape
    inv_den = _hs_inv_den(Ex, Ey, np.float32(alpha * alpha))
    src_u, src_v = u, v
    dst_u = np.empty_like(u)
    dst_v = np.empty_like(v)
    done = 0
    for _ in range(iterations):
        _hs_sweep(src_u, src_v, Ex, Ey, Et, inv_den, dst_u, dst_v)
        done += 1
        change = np.float32(0.0)
        if tol > 0:
            for i in range(h):
                for j in range(w):
                    change = max(change, abs(dst_u[i, j] - src_u[i, j]), abs(dst_v[i, j] - src_v[i, j]))
        src_u, dst_u = dst_u, src_u
        src_v, dst_v = dst_v, src_v
        if tol > 0 and change < tol:
            break
    if done % 2 == 1:  # the latest sweep sits in the scratch buffers
        # element by element: ``u[:, :] = src_u``'s shape check compiles numba's string code (~1.5 s cold)
        for i in range(h):
            for j in range(w):
                u[i, j] = src_u[i, j]
                v[i, j] = src_v[i, j]
    return done


def cube_to_pixels(a: np.ndarray) -> np.ndarray:
    """``(h, w)`` values at cube centres ``(i + 1/2, j + 1/2)`` -> ``(h + 1, w + 1)`` at pixel centres.

    Bilinear: each pixel takes the mean of the cube centres around it (two at an
    edge, one at a corner).
    """
    p = np.pad(a, 1, mode="edge")
    return 0.25 * (p[:-1, :-1] + p[:-1, 1:] + p[1:, :-1] + p[1:, 1:])


def pixels_to_cube(a: np.ndarray) -> np.ndarray:
    """``(H, W)`` values at pixel centres -> ``(H - 1, W - 1)`` at the cube centres between them."""
    return 0.25 * (a[:-1, :-1] + a[:-1, 1:] + a[1:, :-1] + a[1:, 1:])


@numba.njit(cache=True)
def _hs_linearise(Ex, Ey, Et, flow, inside, use_inside, u, v) -> None:
    """Start (u, v) on the cube grid from the pixel-centred ``flow`` and linearise Et about it, in place.

    ``u, v = pixels_to_cube(flow)``; ``Et <- Et - Ex u - Ey v``; where a cube
    corner lies outside frame t+1 (``use_inside`` and ``inside`` False) the
    data term is dropped: Ex = Ey = Et = 0. Without branches on the values
    (a select, and ``&`` of the four corners), so that the loop vectorises.
    """
    h, w = Ex.shape
    zero = np.float32(0.0)
    q = np.float32(0.25)
    f = flow.reshape(h + 1, 2 * (w + 1))  # (u, v) of pixel j at 2 j, 2 j + 1: a constant stride
    for i in range(h):
        for j in range(w):
            u0 = q * (f[i, 2 * j] + f[i, 2 * j + 2] + f[i + 1, 2 * j] + f[i + 1, 2 * j + 2])
            v0 = q * (f[i, 2 * j + 1] + f[i, 2 * j + 3] + f[i + 1, 2 * j + 1] + f[i + 1, 2 * j + 3])
            u[i, j] = u0
            v[i, j] = v0
            et = Et[i, j] - Ex[i, j] * u0 - Ey[i, j] * v0
            if use_inside:  # (loop-invariant: the inner loop is compiled once for each case)
                keep = inside[i, j] & inside[i, j + 1] & inside[i + 1, j] & inside[i + 1, j + 1]
                Ex[i, j] = Ex[i, j] if keep else zero
                Ey[i, j] = Ey[i, j] if keep else zero
                Et[i, j] = et if keep else zero
            else:
                Et[i, j] = et


@numba.njit(cache=True)
def _cube_flow_to_pixels(u, v, flow, valid) -> None:
    """:func:`cube_to_pixels` of ``u`` and ``v`` into ``flow`` ``(h + 1, w + 1, 2)``, and ``valid``:
    where ``x + flow`` lies inside the frame (:func:`algorithms.pyramid.target_inside`).

    The inner columns (both neighbours present) run without clamping or
    branches, so that the loop vectorises; the first and last column follow.
    """
    h, w = u.shape
    H, W = h + 1, w + 1
    q = np.float32(0.25)
    zero = np.float32(0.0)
    x_max = np.float32(W - 1)
    y_max = np.float32(H - 1)
    f = flow.reshape(H, 2 * W)  # (u, v) of pixel j at 2 j, 2 j + 1: a constant stride
    for i in range(H):
        i0 = max(i - 1, 0)
        i1 = min(i, h - 1)
        y_i = np.float32(i)
        for j in range(1, W - 1):
            a = q * (u[i0, j - 1] + u[i0, j] + u[i1, j - 1] + u[i1, j])
            b = q * (v[i0, j - 1] + v[i0, j] + v[i1, j - 1] + v[i1, j])
            f[i, 2 * j] = a
            f[i, 2 * j + 1] = b
            x = np.float32(j) + a
            y = y_i + b
            valid[i, j] = (x >= zero) & (x <= x_max) & (y >= zero) & (y <= y_max)
        for j in (0, W - 1):
            j0 = max(j - 1, 0)
            j1 = min(j, w - 1)
            a = q * (u[i0, j0] + u[i0, j1] + u[i1, j0] + u[i1, j1])
            b = q * (v[i0, j0] + v[i0, j1] + v[i1, j0] + v[i1, j1])
            flow[i, j, 0] = a
            flow[i, j, 1] = b
            x = np.float32(j) + a
            y = y_i + b
            valid[i, j] = x >= zero and x <= x_max and y >= zero and y <= y_max


def _hs_on_cube(f0: np.ndarray, f1: np.ndarray, flow: np.ndarray | None, *, alpha: float, iterations: int,
                tol: float | None, inside: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """HS from the initial pixel-centred ``flow`` (None: zero): frame t+1 is already warped back by it.

    The constraint is linearised about ``flow`` (u0, v0) and the smoothness acts
    on the total flow: with Et' = Et - Ex u0 - Ey v0, eqs. 2.21-2.22 iterate the
    total (u, v) unchanged. Cubes with a corner that the warp sampled outside
    frame t+1 (``inside`` False) carry no data term: smoothness fills them in.
    Returns the pixel-centred flow and where ``x + flow`` lies inside the frame.
    """
    Ex, Ey, Et = hs_derivatives(np.ascontiguousarray(f0, np.float32), np.ascontiguousarray(f1, np.float32))
    u = np.zeros(Ex.shape, dtype=np.float32)
    v = np.zeros(Ex.shape, dtype=np.float32)
    if flow is not None:
        use_inside = inside is not None and not inside.all()
        mask = inside if use_inside else np.ones((1, 1), dtype=np.bool_)
        _hs_linearise(Ex, Ey, Et, np.ascontiguousarray(flow, dtype=np.float32), mask, use_inside, u, v)
    hs_iterate(Ex, Ey, Et, u, v, float(alpha), int(iterations), float(tol or 0.0))
    out = np.empty(f0.shape + (2,), dtype=FLOW_DTYPE)
    valid = np.empty(f0.shape, dtype=np.bool_)
    _cube_flow_to_pixels(u, v, out, valid)
    return out, valid


@register_flow(cost=4.0)
def horn_schunck(frame0: np.ndarray, frame1: np.ndarray, *, alpha: float = 15.0, iterations: int = 100,
                 tol: float | None = None, levels: int = 1, warps: int | None = None,
                 median_px: int | None = None, scale: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """Horn-Schunck flow: brightness constancy plus a smoothness term (eqs. 2.13-2.22).

    The defaults are the thesis's discretisation at one scale: derivatives over
    the 2x2x2 cube (eq. 2.15), the 1/6-1/12 neighbour average (eq. 2.17), and
    ``iterations`` Jacobi sweeps of eqs. 2.21-2.22 with ``u_bar`` in the numerator
    (Horn & Schunck 1981) and ``alpha**2`` in the denominator, from zero flow.
    ``levels > 1`` gives the coarse-to-fine form (thesis 6.1): per level,
    ``warps`` times, frame t+1 is warped back by the current flow and the
    iteration restarts from it, linearised about it (see the module notes for
    where the estimate sits). Tuned on Middlebury RubberWhale and Yosemite
    (``test_external.py``): ``levels=4`` with the other defaults.

    Parameters
    ----------
    frame0, frame1 : ndarray, (H, W) or (H, W, 3)
        Frames t and t+1, uint8 or float; ``alpha`` is in their intensity units.
    alpha : float
        The weight ``a`` of eq. 2.18 (smoothness), in intensity units per px;
        enters squared. 15 suits 0..255 images.
    iterations : int
        Sweeps of eqs. 2.21-2.22 (per warp in the coarse-to-fine form).
    tol : float, optional
        Stop a run of sweeps once no value changes by more than ``tol`` px.
    levels : int
        Pyramid levels (1 = single scale, the thesis).
    warps : int, optional
        Warps per level; default 1 at one level, 2 otherwise.
    median_px : int, optional
        Median filter of the flow after every warp, 0, 3 or 5 px; default 0 at
        one level (thesis), 5 otherwise.
    scale : float
        Size ratio between pyramid levels.

    Returns
    -------
    flow : ndarray, (H, W, 2) float32
        (u, v) in px, forward t -> t+1, at the pixel centres of frame t.
    valid : ndarray, (H, W) bool
        ``x + flow`` inside frame t+1; all False if either frame is constant
        (no brightness gradient anywhere: the flow, 0, is undetermined).
    """
    g0, g1 = check_frame_pair(frame0, frame1)
    if not alpha > 0:
        raise ValueError(f"alpha: expected > 0 (intensity units per px), got {alpha}")
    if iterations < 1 or levels < 1:
        raise ValueError(f"iterations and levels: expected at least 1, got {iterations} and {levels}")
    if warps is None:
        warps = 1 if levels == 1 else 2
    if median_px is None:
        median_px = 0 if levels == 1 and warps == 1 else 5

    def update(f0: np.ndarray, f1w: np.ndarray, flow: np.ndarray,
               inside: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return _hs_on_cube(f0, f1w, flow, alpha=alpha, iterations=iterations, tol=tol, inside=inside)[0], inside

    if levels == 1 and warps == 1:
        flow, valid = _hs_on_cube(g0, g1, None, alpha=alpha, iterations=iterations, tol=tol)
    else:
        flow, valid = coarse_to_fine(g0, g1, update, levels=levels, warps=warps, scale=scale,
                                     median_px=median_px)
    if np.ptp(g0) == 0 or np.ptp(g1) == 0:
        valid[:] = False
    return flow, valid
