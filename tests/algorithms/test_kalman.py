"""Kalman filters: the thesis's Table 4.1, filterpy as an oracle, class == function."""

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter

from algorithms.kalman import THESIS_KALMAN, ConstantVelocityKalman, kalman_cv_filter, scalar_kalman

# Thesis Table 4.1: vertical motion of the tracked pixel, px/frame.
TABLE_4_1_OPTICAL_FLOW = [-0.50642, -0.49838, -0.55926, -0.5661, -0.66467,
                          -0.70376, -0.43438, -0.51412, -0.46289, -0.65887]
TABLE_4_1_KALMAN = [-1, -0.51061, -0.55705, -0.56569, -0.66016,
                    -0.70177, -0.44656, -0.51104, -0.46508, -0.65004]


def test_scalar_kalman_reproduces_thesis_table_4_1():
    x = scalar_kalman(TABLE_4_1_OPTICAL_FLOW, **THESIS_KALMAN)
    # printed to 5 decimals: half a unit of the last digit
    np.testing.assert_allclose(x, TABLE_4_1_KALMAN, rtol=0, atol=5e-6)


def test_scalar_kalman_ignores_first_measurement_as_appendix_b_does():
    z = np.array(TABLE_4_1_OPTICAL_FLOW)
    z2 = z.copy()
    z2[0] = 123.0
    np.testing.assert_array_equal(scalar_kalman(z, **THESIS_KALMAN), scalar_kalman(z2, **THESIS_KALMAN))


def test_scalar_kalman_nan_only_predicts_and_constant_series_is_a_fixed_point():
    x = scalar_kalman([0.3, 0.3, np.nan, 0.3], x0=None, p0=1, q=1, r=0.05)
    np.testing.assert_allclose(x, 0.3, atol=1e-12)


def test_scalar_kalman_rejects_bad_noise():
    with pytest.raises(ValueError, match="r: expected a finite number > 0"):
        scalar_kalman([1.0, 2.0], x0=0, p0=1, q=1, r=0)
    with pytest.raises(ValueError, match="measurements: expected a 1-D series"):
        scalar_kalman(np.zeros((3, 2)), **THESIS_KALMAN)


def _measurements(rng: np.random.Generator, n=40):
    t = np.arange(n)
    truth = np.column_stack([10 + 1.5 * t + 0.02 * t**2, 50 - 0.7 * t])
    z = truth + rng.normal(0, 1.0, size=truth.shape)
    z[[5, 6, 17]] = np.nan
    return truth, z


def test_cv_kalman_matches_filterpy():
    _, z = _measurements(np.random.default_rng(1))
    kw = dict(dt=1.0, sigma_accel_px=0.3, sigma_meas_px=1.2, sigma_pos0_px=2.0, sigma_vel0_px=5.0)
    x0 = np.array([9.0, 49.0, 1.0, -0.5])
    ours = kalman_cv_filter(z, x0=x0, **kw)
    ref = ConstantVelocityKalman(x0, **kw)
    kf = KalmanFilter(dim_x=4, dim_z=2)
    kf.x, kf.P, kf.F, kf.H, kf.Q, kf.R = x0.copy(), ref.P.copy(), ref.F, ref.H, ref.Q, ref.R
    for k, zk in enumerate(z):
        if k > 0:
            kf.predict()
        kf.update(None if np.isnan(zk).any() else zk)
        np.testing.assert_allclose(ours.states[k], kf.x, rtol=0, atol=1e-9)
        np.testing.assert_allclose(ours.covariances[k], kf.P, rtol=0, atol=1e-9)


def test_cv_kalman_q_is_white_acceleration_model():
    kf = ConstantVelocityKalman([0, 0], dt=2.0, sigma_accel_px=0.5)
    per_axis = 0.25 * np.array([[2.0**4 / 4, 2.0**3 / 2], [2.0**3 / 2, 2.0**2]])
    np.testing.assert_allclose(kf.Q[np.ix_([0, 2], [0, 2])], per_axis)
    np.testing.assert_allclose(kf.Q[np.ix_([1, 3], [1, 3])], per_axis)
    assert kf.Q[0, 1] == 0 and kf.Q[0, 3] == 0


def test_cv_kalman_class_equals_function_and_tracks_the_truth():
    truth, z = _measurements(np.random.default_rng(2))
    res = kalman_cv_filter(z, sigma_accel_px=0.2, sigma_meas_px=1.0)
    kf = ConstantVelocityKalman(z[0], sigma_accel_px=0.2, sigma_meas_px=1.0, sigma_pos0_px=1.0)
    for k in range(1, len(z)):
        np.testing.assert_array_equal(kf.predict(), res.predicted_px[k])
        np.testing.assert_array_equal(kf.update(z[k]), res.filtered_px[k])
    # after convergence the filter beats the raw 1 px measurement noise
    err_f = np.hypot(*(res.filtered_px[10:] - truth[10:]).T)
    err_z = np.hypot(*(z[10:] - truth[10:]).T)
    assert np.nanmean(err_f) < 0.8 * np.nanmean(err_z)


def test_cv_kalman_leading_nans_and_bad_input():
    z = np.array([[np.nan, np.nan], [1.0, 2.0], [2.0, 3.0]])
    res = kalman_cv_filter(z)
    assert np.isnan(res.filtered_px[0]).all()
    np.testing.assert_array_equal(res.filtered_px[1], [1.0, 2.0])
    with pytest.raises(ValueError, match=r"measurements: expected \(N, 2\)"):
        kalman_cv_filter(np.zeros(5))
    with pytest.raises(ValueError, match="sigma_meas_px"):
        ConstantVelocityKalman([0, 0], sigma_meas_px=-1)
