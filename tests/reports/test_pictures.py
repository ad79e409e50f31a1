"""Flow pictures: total and local motion rows, true local = flow - flow_camera, enlarged, old run folders."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from reports import write_report
from reports.pictures import DISPLAY_WIDTH_PX, WEBP_QUALITY, display_scale, picture_file, upscale_nearest
from tests.reports.conftest import H, PICTURE_FRAME, W


def _picture(html_path: Path, alt: str) -> np.ndarray:
    """The file of the first <img> with this alt text, decoded to RGB; checks the size it is shown at."""
    m = re.search(rf'<img class="([^"]*)" src="(report_files/[0-9a-f]+\.png)" width="(\d+)" height="(\d+)" '
                  rf'loading="lazy" decoding="async" alt="{re.escape(alt)}">', html_path.read_text())
    assert m, f"no picture {alt!r}"
    rgb = cv2.cvtColor(cv2.imread(str(html_path.parent / m.group(2)), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    k = display_scale(rgb.shape[1], min_width_px=320)
    assert (int(m.group(3)), int(m.group(4))) == (rgb.shape[1] * k, rgb.shape[0] * k), "shown enlarged k x"
    assert ("pix" in m.group(1).split()) == (k > 1), "enlarged pixel by pixel, never interpolated"
    return rgb


@pytest.fixture(scope="module")
def report_html(fixture_report) -> Path:
    return fixture_report["html"]


@pytest.fixture(scope="module")
def html_text(report_html) -> str:
    return report_html.read_text()


def test_true_local_motion_is_flow_minus_camera_flow(report_html):
    local = _picture(report_html, "true local flow")
    assert local.shape == (H, W, 3), "a small picture is stored as it is, lossless (the browser enlarges it)"
    # the fixture's static world moves with the camera only: zero local flow, white in the colour coding
    assert (local[:4, :4] >= 250).all()
    # the vehicle (rows 8..13, cols 10..17) moves on its own: saturated colour
    vehicle = local[10, 12].astype(int)
    assert vehicle.max() - vehicle.min() > 100
    # the total-motion truth is dominated by the camera: no white anywhere in the valid part
    total = _picture(report_html, "true total flow")
    assert (total[:, : W - 3].min(axis=2) < 200).all()


def test_local_row_per_method_with_error_maps(html_text):
    for pipe in ("lk_thesis", "dis"):
        assert f'alt="{pipe} local flow"' in html_text
        assert f'alt="{pipe} local endpoint error"' in html_text
        assert f'alt="{pipe} total flow"' in html_text
    assert "Local motion (global motion taken out)" in html_text


def test_run_without_local_flow_files_says_so(run_dir, tmp_path):
    old = tmp_path / "run"
    shutil.copytree(run_dir, old)
    for p in old.glob("cells/*/local_flow_*.flo"):
        p.unlink()
    text = write_report(old)["html"].read_text()
    assert f"The cells saved no local flow (local_flow_{PICTURE_FRAME:06d}.flo" in text
    assert 'alt="true local flow"' in text          # the truth still shows where vehicles move
    assert 'alt="dis local flow"' not in text
    assert 'alt="dis total endpoint error"' in text  # the total-motion rows are unchanged


def test_nearest_neighbour_enlargement():
    a = np.arange(6, dtype=np.uint8).reshape(2, 3)
    b = upscale_nearest(a, 3)
    assert b.shape == (6, 9) and (b[::3, ::3] == a).all() and (b[2::3, 2::3] == a).all()
    assert display_scale(160, min_width_px=320) == 2 and display_scale(161, min_width_px=320) == 2
    assert display_scale(640, min_width_px=320) == 1
    with pytest.raises(ValueError, match="factor >= 1"):
        upscale_nearest(a, 0)


def test_error_maps_tell_no_ground_truth_from_zero_error():
    from reports.pictures import NO_TRUTH_RGB, epe_map

    truth = np.zeros((4, 6, 2), np.float32)
    valid = np.ones((4, 6), bool)
    valid[:, -2:] = False  # no ground truth in the last two columns
    rgb, mean = epe_map(truth.copy(), truth, max_epe_px=1.0, valid=valid)
    assert mean == 0.0
    assert (rgb[:, :4] <= 4).all(), "zero error is black (magma starts at (0, 0, 4))"
    assert (rgb[:, 4:] == NO_TRUTH_RGB).all(), "no ground truth has its own colour"
    assert tuple(NO_TRUTH_RGB) != (0, 0, 0)


def test_the_error_row_names_both_colours(html_text):
    assert "black = zero error" in html_text and "teal = no ground truth" in html_text


def test_a_picture_wider_than_shown_is_downscaled_to_the_shown_width():
    rng = np.random.default_rng(3)
    yy, xx = np.mgrid[0:480, 0:640]
    smooth = np.stack([xx * 255 // 639, yy * 255 // 479, np.full_like(xx, 90)], axis=-1).astype(np.uint8)
    pic = picture_file(smooth)
    assert (pic.width_px, pic.height_px) == (DISPLAY_WIDTH_PX, 240) and pic.name.endswith(".webp")
    back = cv2.cvtColor(cv2.imdecode(np.frombuffer(pic.data, np.uint8), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    assert back.shape == (240, 320, 3)
    # area averaging then WebP at quality WEBP_QUALITY: a smooth picture within a few levels of the original's
    expected = cv2.resize(smooth, (320, 240), interpolation=cv2.INTER_AREA).astype(int)
    assert np.abs(back.astype(int) - expected).mean() < 2.0, WEBP_QUALITY
    assert len(pic.data) < 0.05 * smooth.nbytes
    # the same picture, the same file; another picture, another name
    assert picture_file(smooth) == pic
    assert picture_file(255 - smooth).name != pic.name
    small = (rng.random((120, 160, 3)) * 255).astype(np.uint8)
    kept = picture_file(small)
    assert kept.name.endswith(".png") and (kept.width_px, kept.height_px) == (160, 120)
    assert (cv2.cvtColor(cv2.imdecode(np.frombuffer(kept.data, np.uint8), cv2.IMREAD_COLOR),
                         cv2.COLOR_BGR2RGB) == small).all(), "no wider than shown: lossless"
    with pytest.raises(ValueError, match=r"expected uint8 \(H, W, 3\) or \(H, W\), got float64"):
        picture_file(np.zeros((4, 4, 3)))
