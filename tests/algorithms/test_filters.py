"""Threshold, spatial filter eq. 4.11, temporal filter eq. 4.12."""

import numpy as np
import pytest

from algorithms.filters import spatial_filter, temporal_filter, threshold_flow
from algorithms.registry import get_stage


def _field(u, v):
    return np.stack([np.asarray(u, np.float32), np.asarray(v, np.float32)], axis=-1)


def test_spatial_filter_eq_4_11_by_hand():
    u = np.zeros((5, 5), np.float32)
    u[2, 2] = 16.0
    u[1, 1] = 8.0
    f = spatial_filter(_field(u, -u))
    # centre: 1/2 * 16 + 1/16 * 8 ; neighbour (1, 2): 1/2 * 0 + 1/16 * (16 + 8)
    assert f[2, 2, 0] == pytest.approx(8.5)
    assert f[1, 2, 0] == pytest.approx(1.5)
    assert f[1, 1, 0] == pytest.approx(4.0 + 1.0)
    assert f[3, 3, 0] == pytest.approx(1.0)
    assert f[4, 4, 0] == 0.0
    np.testing.assert_array_equal(f[..., 1], -f[..., 0])


def test_spatial_filter_keeps_constant_field_and_border_modes():
    f = _field(np.full((6, 7), 1.25), np.full((6, 7), -3.0))
    np.testing.assert_allclose(spatial_filter(f), f, atol=1e-6)
    zero = spatial_filter(f, border="zero")
    np.testing.assert_allclose(zero[1:-1, 1:-1], f[1:-1, 1:-1], atol=1e-6)
    # a corner sees 3 of its 8 neighbours inside: 1/2 + 3/16 of the value
    assert zero[0, 0, 0] == pytest.approx(1.25 * (0.5 + 3 / 16))
    with pytest.raises(ValueError, match="border: expected one of"):
        spatial_filter(f, border="wrap")


def test_temporal_filter_eq_4_12_and_ends():
    a, b, c = (_field(np.full((2, 2), x), np.zeros((2, 2))) for x in (4.0, 8.0, 2.0))
    np.testing.assert_allclose(temporal_filter(a, b, c)[..., 0], 0.5 * 8 + 0.25 * (4 + 2))
    np.testing.assert_allclose(temporal_filter(None, b, c)[..., 0], (0.5 * 8 + 0.25 * 2) / 0.75)
    np.testing.assert_allclose(temporal_filter(None, b, None), b)
    with pytest.raises(ValueError, match=r"next: expected size \(2, 2\)"):
        temporal_filter(a, b, _field(np.zeros((3, 3)), np.zeros((3, 3))))
    # a non-finite field is named, the first of cur, prev, next in turn, whichever the other faults
    bad = a.copy()
    bad[1, 0, 1] = np.inf
    nan = a.copy()
    nan[0, 1, 0] = np.nan
    for fields, name in (((a, b, bad), "next"), ((nan, b, bad), "prev"), ((a, nan, None), "cur"),
                         ((None, bad, c), "cur"), ((nan, b, a[:1]), "prev")):
        with pytest.raises(ValueError, match=rf"{name}: 1 value\(s\) are NaN or infinite"):
            temporal_filter(*fields)


def test_threshold_keeps_only_allowed_direction_and_magnitude():
    # up, down, right, up-left (45 deg off up), tiny up, huge up
    u = np.array([[0.0, 0.0, 2.0, -1.0, 0.0, 0.0]])
    v = np.array([[-2.0, 2.0, 0.0, -1.0, -0.1, -50.0]])
    flow, mask = threshold_flow(_field(u, v), direction=-90.0, tolerance_deg=50.0,
                                min_magnitude_px=0.5, max_magnitude_px=10.0)
    np.testing.assert_array_equal(mask, [[True, False, False, True, False, False]])
    np.testing.assert_array_equal(flow[~mask], 0.0)
    np.testing.assert_array_equal(flow[mask], _field(u, v)[mask])
    # a vector direction means the same as its angle; tolerance 90 is the thesis's half-plane
    _, m_vec = threshold_flow(_field(u, v), direction=(0.0, -3.0), tolerance_deg=90.0)
    np.testing.assert_array_equal(m_vec, [[True, False, False, True, True, True]])


def test_threshold_rejects_bad_arguments_and_respects_valid():
    f = _field(np.ones((2, 2)), np.ones((2, 2)))
    _, m = threshold_flow(f, valid=np.array([[True, False], [True, True]]))
    assert m.tolist() == [[True, False], [True, True]]
    with pytest.raises(ValueError, match="direction: expected an angle"):
        threshold_flow(f, direction=(0.0, 0.0))
    with pytest.raises(ValueError, match="tolerance_deg"):
        threshold_flow(f, direction=0.0, tolerance_deg=200)
    with pytest.raises(ValueError, match="channels first"):
        threshold_flow(np.zeros((2, 4, 4), np.float32))


def test_stages_are_registered():
    assert get_stage("threshold", "threshold_flow") is threshold_flow
    assert get_stage("spatial", "spatial_filter") is spatial_filter
    assert get_stage("temporal", "temporal_filter") is temporal_filter


def test_temporal_filter_is_the_float64_formula_bit_for_bit():
    # the fused kernel must round exactly as (1/2 P_t + 1/4 P_t-1 + 1/4 P_t+1) / weight in float64 does
    rng = np.random.default_rng(5)
    a, b, c = (rng.normal(0, 3, (6, 7, 2)).astype(np.float32) for _ in range(3))
    for prev, nxt, weight in [(a, c, 1.0), (None, c, 0.75), (a, None, 0.75), (None, None, 0.5)]:
        total = 0.5 * b.astype(np.float64)
        for nb in (prev, nxt):
            if nb is not None:
                total += 0.25 * nb.astype(np.float64)
        want = (total / weight).astype(np.float32)
        got = temporal_filter(prev, b, nxt)
        assert got.dtype == np.float32 and np.array_equal(got, want)


def test_zero_outside_is_numpy_where_bit_for_bit():
    from algorithms.filters import zero_outside

    rng = np.random.default_rng(6)
    f = rng.normal(0, 3, (5, 8, 2)).astype(np.float32)
    f[0, 0] = (-0.0, np.nan)  # kept as they are where the mask holds
    f[1, 1] = (np.inf, -0.0)
    m = rng.random((5, 8)) > 0.4
    m[0, 0] = m[1, 1] = True
    for flow in (f, f.astype(np.float64), f[:, ::-1]):
        want = np.where(m[..., None], flow, np.float32(0)).astype(np.float32)
        got = zero_outside(flow, m)
        assert got.dtype == np.float32 and np.array_equal(got, want, equal_nan=True)
        assert np.array_equal(np.signbit(got), np.signbit(want))
    with pytest.raises(ValueError, match=r"expected \(H, W, 2\) and \(H, W\) bool"):
        zero_outside(f, m[:, :4])
