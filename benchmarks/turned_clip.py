"""A camera that turns: a MOTChallenge clip (``img1/`` frames, ``gt/gt.txt``) turned at a steady rate.

    python benchmarks/turned_clip.py CLIP OUT --deg-per-frame 0.08
    aerobench eval-video OUT/img1 --gt OUT/gt/gt.txt --pipelines dis --fps 25 --out RUN

Frame ``t`` (counted from 0) is turned by ``t`` times the rate about the image centre (bilinear; what
the turn brings into view is the frame's own content mirrored at its border). Each box of the truth
becomes the bounding box of its four corners turned (a box grows by up to its side times the sine of
the angle). The vehicles, the ground and the sensor stay what they were: only the camera's yaw
differs, so a pipeline scored on both clips shows what a turning camera costs it. 0.08 degree a
frame is 2 degrees a second at 25 fps; a drone holding its position turns far less, a pilot panning
more. The clip ``aerobench export`` or ``benchmarks/heldout_rehearsal.py`` writes is such a folder.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import cv2
import numpy as np


def turn_matrix(deg: float, shape: tuple[int, int]) -> np.ndarray:
    """The (2, 3) map of a turn by ``deg`` (counter-clockwise on the screen) about the centre of an (H, W) image."""
    h, w = shape
    return cv2.getRotationMatrix2D(((w - 1) / 2, (h - 1) / 2), deg, 1.0)


def turned_boxes(rows: np.ndarray, M: np.ndarray) -> np.ndarray:
    """MOT rows (frame, id, x, y, w, h, ...) with each box the bounding box of its corners mapped by ``M``."""
    out = np.array(rows, dtype=np.float64, copy=True).reshape(-1, rows.shape[-1])
    x0, y0, x1, y1 = out[:, 2], out[:, 3], out[:, 2] + out[:, 4], out[:, 3] + out[:, 5]
    corners = np.stack([np.stack([x0, y0], -1), np.stack([x1, y0], -1), np.stack([x0, y1], -1),
                        np.stack([x1, y1], -1)], 1)  # (n, 4, 2)
    mapped = corners @ M[:, :2].T + M[:, 2]
    lo, hi = mapped.min(axis=1), mapped.max(axis=1)
    out[:, 2:4], out[:, 4:6] = lo, hi - lo
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("clip", type=Path, help="a folder with img1/ (frames, in name order) and gt/gt.txt")
    ap.add_argument("out", type=Path, help="the turned clip's folder (must not exist or be empty)")
    ap.add_argument("--deg-per-frame", type=float, required=True, help="the turn a frame, degrees")
    args = ap.parse_args(argv)
    frames = sorted(p for p in (args.clip / "img1").glob("*") if p.suffix.lower() in (".png", ".jpg", ".jpeg"))
    gt_path = args.clip / "gt" / "gt.txt"
    if not frames or not gt_path.is_file():
        print(f"{args.clip}: expected img1/ with .png or .jpg frames and gt/gt.txt", file=sys.stderr)
        return 2
    if not math.isfinite(args.deg_per_frame):
        print(f"--deg-per-frame: expected a finite number, got {args.deg_per_frame}", file=sys.stderr)
        return 2
    if args.out.exists() and any(args.out.iterdir()):
        print(f"{args.out}: exists and is not empty", file=sys.stderr)
        return 2
    gt = np.loadtxt(gt_path, delimiter=",", ndmin=2)
    (args.out / "img1").mkdir(parents=True, exist_ok=True)
    (args.out / "gt").mkdir(parents=True, exist_ok=True)
    rows = []
    for t, path in enumerate(frames):
        img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if img is None:
            print(f"{path}: not an image OpenCV reads", file=sys.stderr)
            return 2
        M = turn_matrix(args.deg_per_frame * t, img.shape[:2])
        turned = cv2.warpAffine(img, M, (img.shape[1], img.shape[0]), flags=cv2.INTER_LINEAR,
                                borderMode=cv2.BORDER_REFLECT101)
        cv2.imwrite(str(args.out / "img1" / f"{t + 1:06d}.png"), turned)
        rows.append(turned_boxes(gt[gt[:, 0] == t + 1], M))
        print(f"\rturned {t + 1}/{len(frames)} frames", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)
    out = np.concatenate(rows)
    fmt = ["%d", "%d"] + ["%.4f"] * 4 + ["%g"] * (out.shape[1] - 6)  # frame and id stay integers
    np.savetxt(args.out / "gt" / "gt.txt", out, delimiter=",", fmt=fmt)
    print(f"{args.out}: {len(frames)} frames turned {args.deg_per_frame} degree a frame "
          f"({args.deg_per_frame * (len(frames) - 1):.2f} in all)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
