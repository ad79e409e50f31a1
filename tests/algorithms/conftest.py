"""Fixtures of the algorithms tests (the synthetic frames themselves are in ``synthetic.py``)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.algorithms.synthetic import wave_texture


@pytest.fixture
def make_pair():
    """``make_pair(motion, shape=(96, 96), seed=0)`` -> frames t, t+1 (float32 0..255)."""
    def make(motion: np.ndarray | None = None, shape: tuple[int, int] = (96, 96), seed: int = 0, **kw):
        return wave_texture(np.random.default_rng(seed), shape, motion=motion, **kw)
    return make
