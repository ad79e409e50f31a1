"""TV-L1 (algorithms.tvl1_flow): scikit-image's solver in numba gives scikit-image's flow, and recovers motion.

scikit-image's ``optical_flow_tvl1`` is the oracle: the port must return its field to
float rounding (on this machine bit for bit) on a real pair (Yosemite), on a pair
with large motion (the coarse levels and the stopping rule), and on a pair whose
warp leaves the frame (edge replication).
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import translation
from skimage.registration import optical_flow_tvl1
from test_external import _load, _mean_epe

from algorithms.reference import tvl1
from algorithms.tvl1_flow import tvl1_level, tvl1_vu

# float rounding only: a different libm sqrt or division would show as an ulp or two, a
# different step as far more
ATOL_PX = 1e-4


def _unit(*frames):
    lo = min(float(f.min()) for f in frames)
    span = max(float(f.max()) for f in frames) - lo
    return [((f - lo) / span).astype(np.float32) for f in frames]


def test_same_flow_as_scikit_image_on_yosemite():
    g0, g1, gt, known = _load("Yosemite")
    n0, n1 = _unit(g0.astype(np.float32), g1.astype(np.float32))
    ours = tvl1_vu(n0, n1)
    ref = optical_flow_tvl1(n0, n1, dtype=np.float32)
    assert ours.shape == ref.shape and ours.dtype == np.float32
    np.testing.assert_allclose(ours, ref, rtol=0, atol=ATOL_PX)
    # and the accuracy of SOURCES.md's reference figure (0.14 px)
    flow, _ = tvl1(g0, g1)
    assert _mean_epe(flow, gt, known) <= 0.16


@pytest.mark.parametrize("params", [{}, {"attachment": 5.0, "tightness": 0.5, "num_warp": 2, "num_iter": 4}],
                         ids=["defaults", "other-params"])
def test_same_flow_as_scikit_image_large_motion_and_borders(make_pair, params):
    # 6 px to the left and 3.5 px down: the warp samples outside the frame near the borders
    f0, f1 = make_pair(translation(-6.0, 3.5))
    n0, n1 = _unit(f0, f1)
    np.testing.assert_allclose(tvl1_vu(n0, n1, **params), optical_flow_tvl1(n0, n1, dtype=np.float32, **params),
                               rtol=0, atol=ATOL_PX)


def test_known_translation_recovered(make_pair):
    f0, f1 = make_pair(translation(2.25, -1.5))
    flow, valid = tvl1(f0, f1)
    inner = flow[16:-16, 16:-16].reshape(-1, 2)
    np.testing.assert_allclose(np.median(inner, axis=0), [2.25, -1.5], atol=0.05)
    assert valid[16:-16, 16:-16].all()


def test_level_leaves_its_initial_flow_alone():
    rng = np.random.default_rng(3)
    img = rng.random((40, 48)).astype(np.float32)
    flow0 = np.full((2, 40, 48), 0.5, np.float32)
    tvl1_level(img, img, flow0, attachment=15, tightness=0.3, num_warp=1, num_iter=1, tol=1e-4)
    assert (flow0 == 0.5).all()


@pytest.mark.parametrize("kwargs, match", [
    ({"num_warp": 0}, "num_warp must be at least 1, got 0"),
    ({"num_iter": 0}, "num_iter must be at least 1, got 0"),
    ({"tightness": 0.0}, "attachment and tightness must be positive"),
])
def test_bad_parameters_rejected(kwargs, match):
    img = np.zeros((40, 40), np.float32)
    with pytest.raises(ValueError, match=match):
        tvl1_vu(img, img, **kwargs)


def test_frames_of_different_shapes_rejected():
    with pytest.raises(ValueError, match=r"expected two \(H, W\) frames of one shape, got \(40, 40\) and \(40, 41\)"):
        tvl1_vu(np.zeros((40, 40), np.float32), np.zeros((40, 41), np.float32))
