"""Draw docs/img/sensor_effects.png: one 100 % crop of the nominal scene, clean and under each sensor effect.

    PYOPENGL_PLATFORM=egl python docs/make_sensor_effects.py [--out docs/img/sensor_effects.png]

Every tile is the same crop (the top-left corner, where distortion and a rolling
shutter show most) of frame 1 of the nominal preset, at its native pixels; the
effects are stronger than the ``realistic`` preset's so that they read at a glance.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from scenes.generate import SceneGenerator  # noqa: E402
from scenes.spec import load_scene_spec  # noqa: E402

CROP = (slice(0, 180), slice(0, 240))  # rows, columns of the 640x480 frame
# label -> overrides; a sideways flight shows the rolling shutter's shear
TILES = {
    "clean": {},
    "motion blur 50 ms": {"sensor.motion_blur.exposure_s": 0.05, "sensor.motion_blur.subframes": 9},
    "rolling shutter 200 us/row": {"sensor.rolling_shutter.line_delay_s": 2e-4,
                                   "sensor.rolling_shutter.band_rows": 4},
    "lens k1 -0.2, k2 0.04": {"sensor.lens.k1": -0.2, "sensor.lens.k2": 0.04},
    "haze 6/km": {"sensor.haze.extinction_per_km": 6.0},
    "noise: 500 e-, read 3": {"sensor.noise.full_well_e": 500.0, "sensor.noise.gaussian_std": 3.0},
    "JPEG q 15": {"sensor.compression.codec": "jpeg", "sensor.compression.jpeg_quality": 15},
    "H.264 crf 40": {"sensor.compression.codec": "h264", "sensor.compression.h264_crf": 40},
}
SCENE = {"image.n_frames": 3, "camera.ground_speed_mps": 40.0, "camera.heading_deg": 90.0,
         "camera.drift.crab_deg": -90.0}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "img" / "sensor_effects.png"))
    args = ap.parse_args()
    tiles = []
    for label, overrides in TILES.items():
        spec = load_scene_spec("nominal", {**SCENE, **overrides})
        frames = SceneGenerator(spec).frames()
        next(frames)
        tile = np.ascontiguousarray(next(frames).rgb[CROP])
        cv2.rectangle(tile, (0, 0), (tile.shape[1] - 1, 17), (0, 0, 0), -1)
        cv2.putText(tile, label, (4, 13), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (255, 255, 255), 1, cv2.LINE_AA)
        tiles.append(np.pad(tile, ((2, 2), (2, 2), (0, 0)), constant_values=255))
    rows = [np.hstack(tiles[k:k + 4]) for k in range(0, len(tiles), 4)]
    sheet = np.vstack(rows)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(args.out, cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR))
    print(f"{args.out}: {sheet.shape[1]}x{sheet.shape[0]}")


if __name__ == "__main__":
    main()
