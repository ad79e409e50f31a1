"""Jitter removal (thesis 3.2): a known line plus known jitter comes back apart."""

import numpy as np
import pytest

from algorithms.jitter import cumulative_path, fit_flight_path, least_squares_line, remove_jitter


def _line_plus_jitter(rng: np.random.Generator, n=30):
    i = np.arange(n)[:, None]
    line = np.array([0.0, 0.0]) + i * np.array([3.2, -1.1])
    jitter = rng.normal(0, 1.5, size=(n, 2))
    # make the jitter orthogonal to (1, i) per axis, so the least-squares line of
    # line + jitter is exactly the line: what is recovered is exactly the jitter
    A = np.column_stack([np.ones(n), np.arange(n)])
    jitter -= A @ np.linalg.lstsq(A, jitter, rcond=None)[0]
    path = line + jitter
    path -= path[0]  # the cumulative path starts at 0; the line absorbs the offset
    line = line - (line[0] + jitter[0])
    return line, jitter, np.diff(path, axis=0)


def test_line_model_recovers_known_jitter_and_straightens_the_path():
    line, jitter, shifts = _line_plus_jitter(np.random.default_rng(0))
    res = remove_jitter(shifts, model="line")
    np.testing.assert_allclose(res.cumulative_px[0], [0, 0])
    np.testing.assert_allclose(res.flight_line_px, line, atol=1e-9)
    np.testing.assert_allclose(res.jitter_px, jitter, atol=1e-9)
    np.testing.assert_allclose(res.correction_px, -jitter, atol=1e-9)
    corrected = res.cumulative_px + res.correction_px
    # a corrected path is straight: constant steps
    np.testing.assert_allclose(np.diff(corrected, n=2, axis=0), 0, atol=1e-9)


def test_straight_flight_has_zero_jitter_exactly():
    shifts = np.tile([2.0, -0.5], (9, 1))
    res = remove_jitter(shifts)
    np.testing.assert_allclose(res.jitter_px, 0, atol=1e-12)
    np.testing.assert_allclose(res.cumulative_px[-1], [18.0, -4.5])


def test_smooth_model_keeps_a_curved_flight_and_removes_fast_jitter():
    n = 40
    i = np.arange(n, dtype=float)
    curve = np.column_stack([2.0 * i + 0.05 * i**2, -0.03 * i**2])
    np.testing.assert_allclose(fit_flight_path(curve, model="smooth", window_frames=11), curve, atol=1e-9)
    jitter = np.column_stack([np.where(i % 2 == 0, 1.0, -1.0), np.where(i % 4 < 2, 0.5, -0.5)])
    res = remove_jitter(np.diff(curve + jitter, axis=0), model="smooth", window_frames=11)
    # the line model on a curved path leaves the curvature as "jitter"; smooth does not
    line = remove_jitter(np.diff(curve + jitter, axis=0), model="line")
    err_smooth = np.abs(res.flight_line_px - (curve - curve[0] - jitter[0])).max()
    err_line = np.abs(line.flight_line_px - (curve - curve[0] - jitter[0])).max()
    assert err_smooth < 0.6 and err_line > 5 * err_smooth, (err_smooth, err_line)


def test_iterations_reestimate_shrinks_the_residual_of_a_biased_measurement():
    _, _, shifts = _line_plus_jitter(np.random.default_rng(3))
    true_path = cumulative_path(shifts)

    def measure_shrunk(corr):
        # an estimator that sees only 80 % of each displacement (e.g. a smoothed peak)
        return 0.8 * np.diff(true_path + corr, axis=0)

    def residual(r):
        c = true_path + r.correction_px
        return np.abs(c - fit_flight_path(c)).max()

    z = np.zeros_like(true_path)
    r1 = residual(remove_jitter(measure_shrunk(z)))
    r3 = residual(remove_jitter(measure_shrunk(z), iterations=3, reestimate=measure_shrunk))
    # each round leaves 20 % of the previous residual jitter
    np.testing.assert_allclose(r3, 0.04 * r1, rtol=1e-6)


def test_bad_input_rejected():
    with pytest.raises(ValueError, match=r"shifts: expected \(N-1, 2\)"):
        remove_jitter(np.zeros((5, 3)))
    with pytest.raises(ValueError, match="model: expected one of line, smooth"):
        remove_jitter(np.zeros((5, 2)), model="spline")
    with pytest.raises(ValueError, match="iterations > 1 needs reestimate"):
        remove_jitter(np.zeros((5, 2)), iterations=2)
    with pytest.raises(ValueError, match="NaN"):
        remove_jitter(np.array([[0.0, np.nan]]))


def test_least_squares_line_is_exact_on_a_line_skips_nan_and_takes_an_abscissa():
    t = np.array([3.0, 4.0, 6.0, 9.0, 10.0])
    y = np.column_stack([2.0 * t - 1.0, -0.5 * t + 7.0])
    assert np.allclose(least_squares_line(y, t), y, atol=1e-12)
    noisy = y + np.array([[0.3, -0.2], [-0.3, 0.2], [0.0, 0.0], [0.3, -0.2], [-0.3, 0.2]])
    fit = least_squares_line(noisy, t)
    # the residual of a least-squares line is orthogonal to (t, 1)
    r = noisy - fit
    assert np.allclose(r.sum(axis=0), 0.0, atol=1e-12) and np.allclose(t @ r, 0.0, atol=1e-12)
    gap = noisy.copy()
    gap[2, 0] = np.nan                       # left out of the fit, the line is still evaluated there
    g = least_squares_line(gap, t)
    keep = [0, 1, 3, 4]
    assert np.isfinite(g).all() and np.allclose(g[:, 1], fit[:, 1])
    assert np.allclose(g[keep, 0], least_squares_line(noisy[keep, :1], t[keep])[:, 0])
    assert np.isnan(least_squares_line(np.array([1.0, np.nan, np.nan]))).all()
    # over the frame index by default: the thesis's flight line
    assert np.allclose(least_squares_line(np.array([0.0, 1.0, 5.0])), [-0.5, 2.0, 4.5])
    with pytest.raises(ValueError, match=r"t: expected \(5,\) abscissae"):
        least_squares_line(y, t[:3])
