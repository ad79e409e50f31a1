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
