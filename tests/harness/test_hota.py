"""HOTA (Luiten et al. 2021) on tiny hand-made cases, every number worked out by hand from the paper's
definitions and TrackEval's matching (TrackEval itself is not a dependency), and pooling by summed counts."""

import math

import numpy as np
import pandas as pd
import pytest

from harness.metrics import HOTA_ALPHAS, hota_counts


def _frames(truth_rows, est_rows):
    truth = pd.DataFrame(truth_rows, columns=["frame", "vehicle_id", "x_px", "y_px", "visible"])
    est = pd.DataFrame(est_rows, columns=["frame", "track_id", "x_filt_px", "y_filt_px"])
    return est, truth


def _per_alpha(*pieces):
    """[(n_alphas, value), ...] -> (19,) array, alphas in ascending order."""
    out = np.concatenate([np.full(n, v, dtype=float) for n, v in pieces])
    assert out.shape == (19,)
    return out


def test_hota_of_a_hand_made_case_with_an_identity_jump():
    # gate 20 px, S = 1 - d / 20. Vehicles A (1) and B (2), tracks 10 and 11:
    #   frame 0: A-10 d 0 (S 1),  B-11 d 10 (S 0.5)
    #   frame 1: A-10 d 10 (S .5), B-11 d 0 (S 1)
    #   frame 2: B not visible, 10 absent; 11 jumps to A, d 2 (S 0.9)
    # n_A = 3, n_B = 2, n_10 = 2, n_11 = 3. Each frame has one feasible assignment.
    # alpha <= 0.5 (10 alphas): TP 5, FN 0, FP 0; matches A-10 2, B-11 2, A-11 1;
    #   A(c) = 2/(3+2-2), 2/(2+3-2), 1/(3+3-1): sum over TPs 2*2/3 + 2*2/3 + 1/5 = 43/15; HOTA = sqrt(43/15 / 5)
    # 0.5 < alpha <= 0.9 (8): TP 3 (S 1, 1, 0.9), FN 2, FP 2; A = 1/4, 1/4, 1/5: sum 0.7; HOTA = sqrt(0.7 / 7)
    # alpha = 0.95 (1): TP 2, FN 3, FP 3; sum 1/4 + 1/4; HOTA = sqrt(0.5 / 8) = 0.25
    est, truth = _frames(
        [(0, 1, 0.0, 0.0, 1), (0, 2, 100.0, 0.0, 1), (1, 1, 0.0, 0.0, 1), (1, 2, 100.0, 0.0, 1),
         (2, 1, 0.0, 0.0, 1), (2, 2, 100.0, 0.0, 0)],
        [(0, 10, 0.0, 0.0), (0, 11, 100.0, 10.0), (1, 10, 0.0, 10.0), (1, 11, 100.0, 0.0), (2, 11, 0.0, 2.0)])
    c = hota_counts(est, truth, gate_px=20.0)
    assert list(HOTA_ALPHAS) == pytest.approx([0.05 * k for k in range(1, 20)])
    np.testing.assert_allclose(c.tp, _per_alpha((10, 5), (8, 3), (1, 2)))
    np.testing.assert_allclose(c.fn, _per_alpha((10, 0), (8, 2), (1, 3)))
    np.testing.assert_allclose(c.fp, _per_alpha((10, 0), (8, 2), (1, 3)))
    np.testing.assert_allclose(c.ass_sum, _per_alpha((10, 43 / 15), (8, 0.7), (1, 0.5)))
    np.testing.assert_allclose(c.deta, _per_alpha((10, 1.0), (8, 3 / 7), (1, 2 / 8)))
    np.testing.assert_allclose(c.assa, _per_alpha((10, 43 / 75), (8, 0.7 / 3), (1, 0.25)))
    np.testing.assert_allclose(c.loca[0], (1 + 0.5 + 0.5 + 1 + 0.9) / 5)
    hota_alpha = _per_alpha((10, math.sqrt(43 / 75)), (8, math.sqrt(0.1)), (1, 0.25))
    np.testing.assert_allclose(c.hota_alpha, hota_alpha)
    np.testing.assert_allclose(c.hota_alpha, np.sqrt(c.deta * c.assa))   # eq. 11 form
    assert c.hota == pytest.approx((10 * math.sqrt(43 / 75) + 8 * math.sqrt(0.1) + 0.25) / 19)   # 0.54483


def test_hota_matching_prefers_the_track_aligned_over_the_sequence():
    # Vehicle A for 3 frames; track 10 on it (d 0, 0, then 8: S 1, 1, 0.6); a one-frame track 12 at d 6 (S 0.7)
    # in frame 2. Nearest-first would give frame 2 to 12. TrackEval's global alignment:
    #   frame 2: S~(A,10) = .6/(1.3+.6-.6) = 6/13, S~(A,12) = 7/13
    #   align(A,10) = (2 + 6/13)/(3 + 3 - (2 + 6/13)) = 32/46 = 0.696; align(A,12) = (7/13)/(3 + 1 - 7/13) = 7/45
    #   scores 0.696 * 0.6 = 0.417 > 7/45 * 0.7 = 0.109: frame 2 goes to track 10.
    # alpha <= 0.6 (12): TP 3, FN 0, FP 1 (track 12); A-10 3 matches, A = 3/(3+3-3) = 1; HOTA = sqrt(3/4)
    # alpha > 0.6 (7):  TP 2, FN 1, FP 2; A = 2/(3+3-2) = 1/2, sum 1; HOTA = sqrt(1/5)
    est, truth = _frames(
        [(0, 1, 50.0, 50.0, 1), (1, 1, 51.0, 50.0, 1), (2, 1, 52.0, 50.0, 1)],
        [(0, 10, 50.0, 50.0), (1, 10, 51.0, 50.0), (2, 10, 52.0, 58.0), (2, 12, 52.0, 44.0)])
    c = hota_counts(est, truth, gate_px=20.0)
    np.testing.assert_allclose(c.tp, _per_alpha((12, 3), (7, 2)))
    np.testing.assert_allclose(c.fn, _per_alpha((12, 0), (7, 1)))
    np.testing.assert_allclose(c.fp, _per_alpha((12, 1), (7, 2)))
    np.testing.assert_allclose(c.hota_alpha, _per_alpha((12, math.sqrt(0.75)), (7, math.sqrt(0.2))))
    assert c.hota == pytest.approx((12 * math.sqrt(0.75) + 7 * math.sqrt(0.2)) / 19)   # 0.71173


def test_hota_pools_sequences_by_adding_counts_and_handles_empty_sides():
    est1, truth1 = _frames([(0, 1, 0.0, 0.0, 1), (1, 1, 1.0, 0.0, 1), (2, 1, 2.0, 0.0, 1)],
                           [(0, 5, 0.0, 3.0), (1, 5, 1.0, 1.0), (2, 6, 2.0, 9.0)])
    est2, truth2 = _frames([(0, 3, 30.0, 0.0, 1), (1, 3, 31.0, 0.0, 1)],
                           [(1, 8, 31.0, 12.0), (1, 9, 90.0, 90.0)])
    both = hota_counts(est1, truth1) + hota_counts(est2, truth2)
    # the two as one sequence (later frames, other ids): the same counts, so pooling is adding
    shifted_e = est2.assign(frame=est2["frame"] + 10, track_id=est2["track_id"] + 100)
    shifted_t = truth2.assign(frame=truth2["frame"] + 10, vehicle_id=truth2["vehicle_id"] + 100)
    one = hota_counts(pd.concat([est1, shifted_e]), pd.concat([truth1, shifted_t]))
    for k in ("tp", "fn", "fp", "ass_sum", "loc_sum"):
        np.testing.assert_allclose(getattr(both, k), getattr(one, k), err_msg=k)
    assert both.hota == pytest.approx(one.hota)
    # nothing tracked: HOTA 0 (all misses); nothing at all: undefined, not 0
    none = hota_counts(est1.iloc[:0], truth1)
    assert none.hota == 0.0 and (none.fn == 3).all()
    assert math.isnan(hota_counts(est1.iloc[:0], truth1.iloc[:0]).hota)
    with pytest.raises(ValueError, match="gate_px: expected > 0"):
        hota_counts(est1, truth1, gate_px=0.0)
