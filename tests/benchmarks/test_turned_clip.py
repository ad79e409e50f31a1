"""benchmarks/turned_clip.py: a clip turned about its centre, its truth boxes turned with the frames."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

_PATH = Path(__file__).resolve().parents[2] / "benchmarks" / "turned_clip.py"
_spec = importlib.util.spec_from_file_location("turned_clip_benchmark", _PATH)
turned_clip = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = turned_clip
_spec.loader.exec_module(turned_clip)

H, W = 120, 160


def _clip(folder: Path, n: int = 3) -> None:
    """``n`` grey frames with one bright 20 x 10 px block at (100, 30), and its truth box in every frame."""
    (folder / "img1").mkdir(parents=True)
    (folder / "gt").mkdir()
    for t in range(n):
        img = np.full((H, W), 60, np.uint8)
        img[30:40, 100:120] = 220
        cv2.imwrite(str(folder / "img1" / f"{t + 1:06d}.png"), img)
    np.savetxt(folder / "gt" / "gt.txt", [[t + 1, 7, 100, 30, 20, 10, 1, 3, 1.0] for t in range(n)], delimiter=",",
               fmt="%g")


def test_each_frame_turns_by_its_index_times_the_rate_and_its_boxes_hold_the_turned_block(tmp_path):
    _clip(tmp_path / "clip")
    assert turned_clip.main([str(tmp_path / "clip"), str(tmp_path / "out"), "--deg-per-frame", "10"]) == 0
    gt = np.loadtxt(tmp_path / "out" / "gt" / "gt.txt", delimiter=",")
    assert gt.shape == (3, 9) and list(gt[:, 0]) == [1, 2, 3] and set(gt[:, 1]) == {7}
    assert list(gt[0, 2:6]) == pytest.approx([100, 30, 20, 10])  # frame 0 is not turned
    for t in range(3):
        img = cv2.imread(str(tmp_path / "out" / "img1" / f"{t + 1:06d}.png"), cv2.IMREAD_GRAYSCALE)
        ys, xs = np.nonzero(img > 140)  # the block, turned with the frame
        x, y, w, h = gt[t, 2:6]
        assert xs.min() >= x - 1 and xs.max() <= x + w and ys.min() >= y - 1 and ys.max() <= y + h, t
        # the box is the turned block's bounding box: 20 cos a + 10 sin a wide at a = 10 t degrees
        a = np.radians(10 * t)
        assert (w, h) == pytest.approx((20 * np.cos(a) + 10 * np.sin(a), 20 * np.sin(a) + 10 * np.cos(a)), abs=1e-3)
    # other columns are kept
    assert list(gt[2, 6:]) == [1, 3, 1.0]


def test_a_folder_without_frames_or_truth_and_a_used_output_are_refused(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    assert turned_clip.main([str(tmp_path / "empty"), str(tmp_path / "out"), "--deg-per-frame", "1"]) == 2
    assert "expected img1/ with .png or .jpg frames and gt/gt.txt" in capsys.readouterr().err
    _clip(tmp_path / "clip")
    (tmp_path / "used").mkdir()
    (tmp_path / "used" / "x").write_text("keep me")
    assert turned_clip.main([str(tmp_path / "clip"), str(tmp_path / "used"), "--deg-per-frame", "1"]) == 2
    assert "exists and is not empty" in capsys.readouterr().err
    assert (tmp_path / "used" / "x").read_text() == "keep me"
    assert turned_clip.main([str(tmp_path / "clip"), str(tmp_path / "out2"), "--deg-per-frame", "nan"]) == 2
    assert "--deg-per-frame: expected a finite number" in capsys.readouterr().err
