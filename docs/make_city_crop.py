"""Draw docs/img/city.png: a 100 % crop (640 x 360 px) of frame 0 of the ``city`` preset, the README's
picture of city traffic.

    PYOPENGL_PLATFORM=egl python docs/make_city_crop.py [--out docs/img/city.png]

The sequence is rendered into (or read from) ``$AEROBENCH_CACHE`` as ``aerobench run`` does (20 frames:
the world depends on the flight's footprint, so on the frame count); the crop is the 640 x 360 window
of frame 0 holding the most visible road users.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CROP_PX = (360, 640)  # rows, columns
N_FRAMES = 20


def best_window(centres: np.ndarray, shape: tuple[int, int], crop: tuple[int, int] = CROP_PX,
                step_px: int = 20) -> tuple[int, int]:
    """(row, column) of the top-left corner of the ``crop`` window of an image of ``shape`` that holds
    the most of ``centres`` (N, 2) (x, y) px; the first such window in row-major order."""
    h, w = shape
    best, at = -1, (0, 0)
    for r in range(0, h - crop[0] + 1, step_px):
        for c in range(0, w - crop[1] + 1, step_px):
            n = int(((centres[:, 0] >= c) & (centres[:, 0] < c + crop[1])
                     & (centres[:, 1] >= r) & (centres[:, 1] < r + crop[0])).sum())
            if n > best:
                best, at = n, (r, c)
    return at


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(ROOT / "docs" / "img" / "city.png"))
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT))
    from scenes import cached_sequence, load_scene_spec
    from scenes.sequence import Sequence

    spec = load_scene_spec("city", {"image.n_frames": N_FRAMES})
    cache = Path(os.environ.get("AEROBENCH_CACHE", Path.home() / ".cache" / "aerobench"))
    seq = Sequence(cached_sequence(spec, cache))
    rgb = seq.frame(0)
    t = seq.tracks
    t = t[(t["frame"] == 0) & (t["visible"] > 0)]
    r, c = best_window(t[["x_px", "y_px"]].to_numpy(float), rgb.shape[:2])
    crop = rgb[r:r + CROP_PX[0], c:c + CROP_PX[1]]
    cv2.imwrite(args.out, cv2.cvtColor(np.ascontiguousarray(crop), cv2.COLOR_RGB2BGR))
    print(f"wrote {args.out}: frame 0 of city, rows {r}-{r + CROP_PX[0]}, columns {c}-{c + CROP_PX[1]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
