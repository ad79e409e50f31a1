"""Flow pictures: total and local motion rows, true local = flow - flow_camera, enlarged, old run folders."""

from __future__ import annotations

import base64
import re
import shutil

import cv2
import numpy as np
import pytest

from reports import write_report
from reports.pictures import display_scale, upscale_nearest
from tests.reports.conftest import H, PICTURE_FRAME, W


def _picture(html_text: str, alt: str) -> np.ndarray:
    """The first <img> with this alt text, decoded to RGB."""
    m = re.search(rf'<img class="[^"]*" src="data:image/png;base64,([^"]+)" alt="{re.escape(alt)}">', html_text)
    assert m, f"no picture {alt!r}"
    buf = np.frombuffer(base64.b64decode(m.group(1)), np.uint8)
    return cv2.cvtColor(cv2.imdecode(buf, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)


@pytest.fixture(scope="module")
def html_text(fixture_report) -> str:
    return fixture_report["html"].read_text()


def test_true_local_motion_is_flow_minus_camera_flow(html_text):
    k = display_scale(W, min_width_px=320)
    local = _picture(html_text, "true local flow")
    assert local.shape == (H * k, W * k, 3), "enlarged by an integer factor"
    # the fixture's static world moves with the camera only: zero local flow, white in the colour coding
    assert (local[:4 * k, :4 * k] >= 250).all()
    # the vehicle (rows 8..13, cols 10..17) moves on its own: saturated colour
    vehicle = local[10 * k, 12 * k].astype(int)
    assert vehicle.max() - vehicle.min() > 100
    # the total-motion truth is dominated by the camera: no white anywhere in the valid part
    total = _picture(html_text, "true total flow")
    assert (total[:, : (W - 3) * k].min(axis=2) < 200).all()


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
