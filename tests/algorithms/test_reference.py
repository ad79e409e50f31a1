"""Reference adapters: each gives our (u, v) layout and sign, zero for zero motion, invalid for flat frames."""

from __future__ import annotations

import numpy as np
import pytest
from tests.algorithms.synthetic import translation

from algorithms.reference import dis, farneback, ilk, tvl1
from algorithms.registry import get_flow_method

METHODS = [farneback, dis, tvl1, ilk]
M = 16


@pytest.mark.parametrize("method", METHODS, ids=lambda m: m.__name__)
def test_sign_and_layout(make_pair, method):
    """Content moving +x by 1.5 px and -y by 0.5 px: u ~ +1.5, v ~ -0.5, whatever the library's order."""
    f0, f1 = make_pair(translation(1.5, -0.5))
    flow, valid = method(np.round(f0).astype(np.uint8), np.round(f1).astype(np.uint8))
    assert flow.shape == (96, 96, 2) and flow.dtype == np.float32 and valid.dtype == bool
    np.testing.assert_allclose(np.median(flow[M:-M, M:-M], axis=(0, 1)), [1.5, -0.5], atol=0.1)
    assert get_flow_method(method.__name__) is method


@pytest.mark.parametrize("method", METHODS, ids=lambda m: m.__name__)
def test_float_input_same_sign(make_pair, method):
    f0, f1 = make_pair(translation(-1.0, 1.0))
    flow, _ = method(f0 / 255.0, f1 / 255.0)
    np.testing.assert_allclose(np.median(flow[M:-M, M:-M], axis=(0, 1)), [-1.0, 1.0], atol=0.1)


@pytest.mark.parametrize("method", METHODS, ids=lambda m: m.__name__)
def test_zero_motion(make_pair, method):
    f0, _ = make_pair()
    flow, valid = method(f0, f0.copy())
    assert np.abs(flow[M:-M, M:-M]).max() < 1e-3  # Farneback's border rows drift by ~0.1 px
    assert valid[M:-M, M:-M].all()


@pytest.mark.parametrize("method", METHODS, ids=lambda m: m.__name__)
def test_flat_frames_invalid(method):
    flat = np.full((48, 48), 9, np.uint8)
    flow, valid = method(flat, flat)
    assert not valid.any() and np.isfinite(flow).all()


@pytest.mark.parametrize("method", METHODS, ids=lambda m: m.__name__)
def test_shape_mismatch(method):
    with pytest.raises(ValueError, match="differ in size"):
        method(np.zeros((20, 20)), np.zeros((20, 22)))


def _small_car_pair(seed: int, motion_px=(1.2, 0.3)):
    """A 24 x 12 px car of its own texture moving ``motion_px`` over static ground (uint8 frames, its inner rows)."""
    import cv2
    from tests.algorithms.synthetic import wave_texture

    rng = np.random.default_rng(seed)
    ground, _ = wave_texture(rng, (96, 128))
    car0, car1 = wave_texture(rng, (96, 128), motion=translation(*motion_px), max_cycles_per_px=0.2)
    car0, car1 = 0.4 * car0 + 10, 0.4 * car1 + 10  # a dark car
    m0 = np.zeros((96, 128), np.float32)
    m0[42:54, 52:76] = 1
    m1 = cv2.warpAffine(m0, np.float32([[1, 0, motion_px[0]], [0, 1, motion_px[1]]]), (128, 96), flags=cv2.INTER_LINEAR)
    f0 = np.round(ground * (1 - m0) + car0 * m0).astype(np.uint8)
    f1 = np.round(ground * (1 - m1) + car1 * m1).astype(np.uint8)
    return f0, f1, (slice(44, 52), slice(55, 73))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_dis_at_full_resolution_follows_a_car_smaller_than_its_patch(seed):
    """finest_scale 0: a 24 x 12 px car moving (1.2, 0.3) px is followed within 0.2 px; the medium preset's flow from
    half resolution (8 px patches over 16 image px, more ground than car) gives it under 60 % of its motion."""
    f0, f1, inner = _small_car_pair(seed)
    full, _ = dis(f0, f1, finest_scale=0)
    np.testing.assert_allclose(np.median(full[inner].reshape(-1, 2), axis=0), [1.2, 0.3], atol=0.2)
    half, _ = dis(f0, f1)
    assert np.median(half[inner][..., 0]) < 0.6 * 1.2


@pytest.mark.parametrize("bad", [-1, 1.5, True, "0"])
def test_dis_rejects_a_bad_finest_scale(bad):
    f0, f1, _ = _small_car_pair(0)
    with pytest.raises(ValueError, match="finest_scale: expected None or an integer >= 0"):
        dis(f0, f1, finest_scale=bad)
