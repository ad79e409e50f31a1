"""benchmarks/realism.py: each image and scene statistic on images whose answer is known."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

_PATH = Path(__file__).resolve().parents[2] / "benchmarks" / "realism.py"
_spec = importlib.util.spec_from_file_location("realism_benchmark", _PATH)
realism = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = realism  # dataclasses look their module up there
_spec.loader.exec_module(realism)


def _power_law_noise(shape, exponent: float, seed: int) -> np.ndarray:
    """Gaussian noise whose power spectrum falls as f^exponent (amplitude f^(exponent / 2))."""
    rng = np.random.default_rng(seed)
    h, w = shape
    f = np.hypot(np.fft.fftfreq(h)[:, None], np.fft.fftfreq(w)[None, :])
    f[0, 0] = 1.0
    F = np.fft.fft2(rng.standard_normal(shape)) * f ** (exponent / 2)
    F[0, 0] = 0.0
    img = np.real(np.fft.ifft2(F))
    return 128.0 + 40.0 * img / img.std()


@pytest.mark.parametrize("exponent", [-2.0, -3.0, -1.0])
def test_spectrum_slope_of_power_law_noise_is_its_exponent(exponent):
    slopes = [realism.spectrum_slope(_power_law_noise((256, 320), exponent, seed)) for seed in range(3)]
    assert abs(np.mean(slopes) - exponent) < 0.1, slopes


def test_spectrum_slope_rejects_a_small_or_colour_image():
    with pytest.raises(ValueError, match=r"expected an \(H, W\) image with H, W >= 32, got shape \(16, 64\)"):
        realism.spectrum_slope(np.zeros((16, 64)))
    with pytest.raises(ValueError, match=r"got shape \(64, 64, 3\)"):
        realism.spectrum_slope(np.zeros((64, 64, 3)))


def test_white_noise_has_the_same_power_in_every_octave_and_a_blur_takes_it_from_the_fine_ones():
    rng = np.random.default_rng(3)
    white = rng.normal(128.0, 10.0, (512, 512))
    bands = realism.band_powers(*realism.power_spectrum(white))
    assert bands.shape == (len(realism.BANDS_PX) - 1,)
    # power per frequency bin is the variance (the spectrum is normalised by the window's energy); the
    # coarsest octave (4-8 bins of 512) is left out: the window's leakage from the mean reaches it
    np.testing.assert_allclose(bands[:-1], 100.0, rtol=0.1)
    # a Gaussian blur of sigma 1 px keeps exp(-4 pi^2 f^2) of the power: 0.7 % to 7 % at 2-4 px, over 90 %
    # at 32-64 px
    blurred = realism.band_powers(*realism.power_spectrum(cv2.GaussianBlur(white, (0, 0), 1.0)))
    kept = blurred / bands
    assert kept[0] < 0.02 and kept[4] > 0.9 and (np.diff(kept) > 0).all()


def test_the_radial_average_of_an_empty_ring_is_nan_not_zero():
    f, P = np.array([0.1, 0.12, 0.3]), np.array([1.0, 3.0, 5.0])
    fm, pm = realism.radial_average(f, P, np.array([0.05, 0.2, 0.25, 0.4]))
    np.testing.assert_allclose(fm[[0, 2]], [0.11, 0.3])
    np.testing.assert_allclose(pm[[0, 2]], [2.0, 5.0])
    assert np.isnan(fm[1]) and np.isnan(pm[1])


def test_gradient_of_a_ramp_is_its_slope_everywhere():
    ramp = np.add.outer(0.75 * np.arange(50.0), 1.0 * np.arange(60.0))  # d/dy 0.75, d/dx 1
    med, p90 = realism.gradient_stats(ramp)
    assert med == pytest.approx(1.25) and p90 == pytest.approx(1.25)


def test_local_contrast_of_a_checkerboard_and_of_noise():
    board = 100.0 + 30.0 * np.where(np.add.outer(np.arange(90), np.arange(90)) % 2 == 0, 1.0, -1.0)
    assert realism.local_contrast(board) == pytest.approx(30.0, rel=0.01)
    assert realism.local_contrast(np.full((40, 40), 7.0)) == pytest.approx(0.0, abs=1e-3)
    noise = np.random.default_rng(2).normal(100.0, 5.0, (200, 200))
    assert realism.local_contrast(noise) == pytest.approx(5.0, rel=0.05)


def test_saturation_of_gray_red_and_a_mixed_colour():
    img = np.zeros((2, 2, 3), np.uint8)
    img[0, 0] = (90, 90, 90)
    img[0, 1] = (255, 0, 0)
    img[1, 0] = (200, 100, 100)
    img[1, 1] = (0, 0, 0)  # black counts as unsaturated
    assert realism.saturation(img) == pytest.approx((0.0 + 1.0 + 0.5 + 0.0) / 4)


@pytest.mark.parametrize("sigma", [1.0, 3.0, 8.0])
def test_noise_sigma_is_recovered_within_ten_percent_on_an_image_with_edges(sigma):
    rng = np.random.default_rng(int(sigma * 10))
    h, w = 240, 320
    img = np.add.outer(0.2 * np.arange(h), 0.1 * np.arange(w)) + 40.0  # a ramp: the mask cancels it
    img[60:180, 100:220] += 80.0  # a square: edges, kept out by the flat-region selection
    img[:, 260:] += 50.0 * (np.arange(w - 260) % 8 < 4)  # stripes
    est = realism.noise_sigma(img + rng.normal(0.0, sigma, (h, w)))
    assert abs(est / sigma - 1) < 0.10, (sigma, est)
    assert realism.noise_sigma(img) < 0.05  # no noise, structure alone


def _jpeg(img: np.ndarray, quality: int) -> np.ndarray:
    ok, data = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, quality])
    assert ok
    return cv2.imdecode(data, cv2.IMREAD_GRAYSCALE).astype(np.float64)


def test_blockiness_grows_as_jpeg_quality_falls_and_is_one_without_blocks():
    texture = np.clip(_power_law_noise((256, 256), -2.5, 7), 0, 255).astype(np.uint8)
    b95, b20 = realism.blockiness(_jpeg(texture, 95)), realism.blockiness(_jpeg(texture, 20))
    assert b20 > b95 * 1.15, (b20, b95)
    assert abs(realism.blockiness(texture.astype(float)) - 1.0) < 0.05
    # shifting the image by 4 px moves the blocks off the grid
    assert realism.blockiness(_jpeg(texture, 20)[4:, 4:]) < b20


def test_global_shift_and_box_matching_find_the_moving_box():
    rng = np.random.default_rng(3)
    ground = cv2.GaussianBlur(rng.uniform(0, 255, (220, 300)), (0, 0), 2.0)
    M = np.float64([[1, 0, 3.0], [0, 1, -2.0]])  # the ground moves by (3, -2) px
    moved = cv2.warpAffine(ground, M, (300, 220), borderMode=cv2.BORDER_REFLECT)
    dx, dy = realism.global_shift_px(ground[10:-10, 10:-10], moved[10:-10, 10:-10])
    assert dx == pytest.approx(3.0, abs=0.1) and dy == pytest.approx(-2.0, abs=0.1)
    c0 = np.array([[50.0, 60.0], [150.0, 100.0], [250.0, 30.0]])
    c1 = c0 + (3.0, -2.0)
    c1[1] += (6.0, 8.0)  # box 1 drives 10 px relative to the ground
    pairs = realism.match_boxes(c0, c1[::-1], (dx, dy))  # order of frame 1 scrambled
    by_i = {i: (j, r) for i, j, r in pairs}
    assert sorted(by_i) == [0, 1, 2]
    assert by_i[1][0] == 1 and by_i[1][1] == pytest.approx(10.0, abs=0.2)
    assert by_i[0][1] < 0.2 and by_i[2][1] < 0.2
    assert realism.match_boxes(c0, c1 + 100.0, (dx, dy)) == []  # beyond the gate


def test_yolo_boxes_are_read_in_pixels(tmp_path):
    label = tmp_path / "f.txt"
    label.write_text("0 0.5 0.25 0.1 0.2\n2 0.1 0.9 0.05 0.04\n")
    b = realism.read_yolo_boxes(label, 200, 100)
    np.testing.assert_allclose(b.centres, [[100.0, 25.0], [20.0, 90.0]])
    np.testing.assert_allclose(b.sizes, [[20.0, 20.0], [10.0, 4.0]])


def test_verdict_is_pass_within_a_quarter_and_na_without_a_number():
    assert realism.verdict(1.25) == "PASS" and realism.verdict(0.75) == "PASS"
    assert realism.verdict(1.26) == "FAIL" and realism.verdict(0.7) == "FAIL"
    assert realism.verdict(float("nan")) == "n/a"


def test_side_by_side_puts_the_crops_next_to_each_other_around_the_vehicles():
    a = np.zeros((300, 400, 3), np.uint8)
    a[250:260, 350:360] = 200  # a vehicle near the corner
    b = np.full((40, 120, 3), 50, np.uint8)  # lower than the crop: cropped to its short side
    pic = realism.side_by_side(a, b, crop_px=64, centres=(np.array([[355.0, 255.0]]), None))
    assert pic.shape == (64, 64 + 8 + 40, 3)
    assert (pic[:64, :64] == 200).any()  # the vehicle is in the left crop
    assert (pic[:, 64:72] == 255).all() and (pic[:40, 72:] == 50).all()


def test_moving_fraction_pools_every_frame_and_skips_unknown_motion():
    b0 = realism.SceneBoxes(np.zeros((3, 2)), np.ones((3, 2)), moving=np.array([True, False, True]),
                            moving_known=np.array([True, True, False]))
    b1 = realism.SceneBoxes(np.zeros((2, 2)), np.ones((2, 2)), moving=np.array([False, False]),
                            moving_known=np.array([True, True]))
    b2 = realism.SceneBoxes(np.zeros((1, 2)), np.ones((1, 2)))  # nothing known (a real frame without a next)
    side = realism.Side("s", [np.zeros((8, 8, 3), np.uint8)] * 3, [b0, b1, b2])
    assert realism.moving_fraction([side]) == pytest.approx(1 / 4)
    assert np.isnan(realism.moving_fraction([realism.Side("t", [], [])]))


def test_several_seeds_are_rendered_each_and_pooled_into_one_side(monkeypatch):
    calls = []

    def one(arg, frames=None, *, seed=None):
        calls.append((arg, frames, seed))
        n = seed or 1  # the seed's number of boxes, to tell the worlds apart
        b = realism.SceneBoxes(np.zeros((n, 2)), np.ones((n, 2)))
        return realism.Side(f"{arg}-{seed}", [np.full((4, 4, 3), n, np.uint8)], [b])

    monkeypatch.setattr(realism, "synthetic_side", one)
    side = realism.synthetic_sides("city", 20, [3, 5])
    assert calls == [("city", 20, 3), ("city", 20, 5)]
    assert [int(f[0, 0, 0]) for f in side.frames] == [3, 5] and [len(b.centres) for b in side.boxes] == [3, 5]
    assert side.name == "city seeds 3, 5"
    # without seeds: the spec's own world, once
    calls.clear()
    realism.synthetic_sides("city", None, None)
    assert calls == [("city", None, None)]


def _side(name: str, frame: np.ndarray, length_px: float, speeds_mps=()) -> "realism.Side":
    n = len(speeds_mps)
    b = realism.SceneBoxes(centres=np.full((n, 2), 20.0), sizes=np.tile([length_px, length_px / 2], (n, 1)))
    b.moving = np.asarray(speeds_mps, float) > realism.MOVING_SPEED_MPS
    b.moving_known = np.full(n, True)
    return realism.Side(name, [frame], [b])


def test_each_sequence_is_scaled_by_its_own_factor_and_stopped_vehicles_are_not_moving():
    rng = np.random.default_rng(5)
    img = np.clip(cv2.GaussianBlur(rng.uniform(0, 255, (128, 128)), (0, 0), 1.0), 0, 255).astype(np.uint8)
    rgb = np.repeat(img[..., None], 3, axis=2)
    a = _side("a", rgb, 20.0, speeds_mps=(0.0, 0.0, 0.0, 8.0))  # a queue of three and one driving
    b = _side("b", rgb, 40.0, speeds_mps=(12.0, 0.2))
    stats = realism.side_statistics([a, b], [1.0, 0.5])
    # both at the same vehicle size: 20 px each, one in three of the six moving
    assert stats["vehicle_length_px"] == pytest.approx(20.0)
    assert stats["moving_fraction"] == pytest.approx(2 / 6)
    # the scale changes the size-dependent statistics: b at half size has larger gradients
    half = realism.side_statistics([b], [0.5])["gradient_p90"]
    assert half > realism.side_statistics([b], [1.0])["gradient_p90"]
    with pytest.raises(ValueError, match=r"expected one scale per sequence \(2\), got 3"):
        realism.side_statistics([a, b], [1.0, 1.0, 1.0])
