"""Global motion: NCC shift (thesis 3.1, eq. 3.1), ECC affine/homography model, model -> flow field."""

from __future__ import annotations

import numpy as np
import pytest
from tests.algorithms.synthetic import affine_field, rotation_about, translation

from algorithms.global_motion import GlobalMotion, affine_global_motion, global_flow, ncc_global_motion


def test_integer_shift_recovered_exactly_with_sign(make_pair):
    f0, f1 = make_pair(translation(5.0, -7.0), shape=(128, 128))
    g = ncc_global_motion(f0, f1)
    assert g.shift_px == (5.0, -7.0)
    assert g.valid and g.peak > 0.99


def test_cropped_template_finds_the_same_shift_as_the_whole_central_part(make_pair):
    f0, f1 = make_pair(translation(-9.0, 4.0), shape=(200, 240))
    cropped = ncc_global_motion(f0, f1, template_px=40, subpixel=True)  # 84 x 104 px of 168 x 208
    whole = ncc_global_motion(f0, f1, template_px=None, subpixel=True)
    assert cropped.valid and whole.valid
    np.testing.assert_allclose(cropped.shift_px, (-9.0, 4.0), atol=0.05)
    np.testing.assert_allclose(whole.shift_px, (-9.0, 4.0), atol=0.05)
    with pytest.raises(ValueError, match="template_px: expected at least 8"):
        ncc_global_motion(f0, f1, template_px=4)


def test_subpixel_peak(make_pair):
    f0, f1 = make_pair(translation(3.3, -2.6), shape=(128, 128))
    integer = ncc_global_motion(f0, f1)
    assert integer.shift_px == (3.0, -3.0)
    refined = ncc_global_motion(f0, f1, subpixel=True)
    np.testing.assert_allclose(refined.shift_px, (3.3, -2.6), atol=0.1)


def test_zero_motion(make_pair):
    f0, _ = make_pair(shape=(128, 128))
    g = ncc_global_motion(f0, f0)
    assert g.shift_px == (0.0, 0.0) and g.valid
    assert g.peak == pytest.approx(1.0, abs=1e-4)
    # the parabola sees float32 rounding of a symmetric peak: a few thousandths
    np.testing.assert_allclose(ncc_global_motion(f0, f0, subpixel=True).shift_px, (0.0, 0.0), atol=0.01)


def test_flat_image_has_no_peak():
    flat = np.full((64, 64), 3, np.uint8)
    g = ncc_global_motion(flat, flat)
    assert not g.valid


def test_shift_beyond_search_range_is_invalid(make_pair):
    f0, f1 = make_pair(translation(12.0, 0.0), shape=(128, 128))
    assert not ncc_global_motion(f0, f1, max_shift=4).valid


def test_too_small_for_search_range():
    with pytest.raises(ValueError, match="too small for max_shift"):
        ncc_global_motion(np.zeros((30, 30)), np.zeros((30, 30)), max_shift=16)


@pytest.mark.parametrize("model", ["affine", "homography"])
def test_ecc_recovers_rotation_and_shift(make_pair, model):
    motion = translation(2.0, -1.5) @ rotation_about(63.5, 63.5, 2.0)
    f0, f1 = make_pair(motion, shape=(128, 128))
    g = affine_global_motion(f0, f1, model=model)
    assert g.valid
    err = np.hypot(*(global_flow(g, f0.shape) - affine_field(motion, f0.shape)).transpose(2, 0, 1))
    assert err.mean() < 0.03
    assert err.max() < 0.15  # the homography's perspective terms wander most at the corners


def test_ecc_unknown_model():
    with pytest.raises(ValueError, match="model: expected one of"):
        affine_global_motion(np.zeros((40, 40)), np.zeros((40, 40)), model="similarity")


def test_global_flow_of_shift_and_matrix():
    f = global_flow(GlobalMotion((1.5, -2.0), 1.0, True), (4, 5))
    assert f.shape == (4, 5, 2) and f.dtype == np.float32
    assert (f[..., 0] == 1.5).all() and (f[..., 1] == -2.0).all()
    M = rotation_about(2.0, 1.5, 90.0)
    np.testing.assert_allclose(global_flow(M, (4, 5)), affine_field(M, (4, 5)), atol=1e-5)
    with pytest.raises(ValueError, match=r"\(3, 3\) matrix"):
        global_flow(np.eye(2), (4, 5))


def test_global_flow_of_a_translation_matrix_is_the_general_formula_bit_for_bit():
    # the translation path builds one row and one column; the general projective expression on the
    # full grid must give exactly the same float32 values (the pipeline's flow_global)
    rng = np.random.default_rng(3)
    ys, xs = np.meshgrid(np.arange(7, dtype=np.float64), np.arange(9, dtype=np.float64), indexing="ij")
    for tx, ty in [(0.0, 0.0), (-0.0, 3.0), (1.0 / 3.0, -2.7), *rng.normal(0, 20, (20, 2))]:
        M = np.array([[1.0, 0.0, tx], [0.0, 1.0, ty], [0.0, 0.0, 1.0]])
        Z = M[2, 0] * xs + M[2, 1] * ys + M[2, 2]
        want = np.stack([(M[0, 0] * xs + M[0, 1] * ys + M[0, 2]) / Z - xs,
                         (M[1, 0] * xs + M[1, 1] * ys + M[1, 2]) / Z - ys], axis=-1).astype(np.float32)
        assert np.array_equal(global_flow(M, (7, 9)), want)
