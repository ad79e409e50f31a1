"""Draw docs/img/world_before_after.png: the same 100 % crop of the world from an older generator, from
this one, and a real KIT AIS frame at the same vehicle size.

    PYOPENGL_PLATFORM=egl python docs/make_world_before_after.py --before ../old-checkout \\
        [--kit ../shared/external/kit_ais/MOS74-93/MOS74.png] [--out docs/img/world_before_after.png]

``--before`` is a checkout of the older generator (e.g. ``git worktree add ../old main``): its crop is
rendered by a child process that imports that checkout's ``scenes``. Both render frame 0 of the
``nominal`` preset flown at 78 m, where a 4.5 m car is about 32 px long, as in the KIT AIS frames
(median box about 34 px); the real crop is taken at its own pixels. Tiles are 100 %, no scaling.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OVERRIDES = {"camera.altitude_m": 78.0, "image.n_frames": 2, "vehicles.count": 14, "world.trees.density_per_ha": 20.0,
             "world.wood_fraction": 0.2, "world.built_fraction": 0.3, "seed": 3}
CROP = (slice(120, 360), slice(60, 380))  # rows, columns of the 640x480 frame
KIT_CROP = (slice(150, 390), slice(120, 440))


def render_crop(out: str) -> None:
    """Render the crop with the ``scenes`` found first on sys.path; save it as .npy (child process)."""
    from scenes.generate import SceneGenerator
    from scenes.spec import load_scene_spec

    spec = load_scene_spec("nominal", dict(OVERRIDES))
    rgb = next(SceneGenerator(spec).frames()).rgb
    np.save(out, np.ascontiguousarray(rgb[CROP]))


def _crop_from(checkout: Path, tmp: Path) -> np.ndarray:
    out = tmp / f"crop-{abs(hash(str(checkout)))}.npy"
    code = (f"import sys; sys.path.insert(0, {str(checkout)!r}); sys.path.insert(1, {str(ROOT / 'docs')!r}); "
            f"import make_world_before_after as m; m.render_crop({str(out)!r})")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=checkout)
    return np.load(out)


def _label(tile: np.ndarray, text: str) -> np.ndarray:
    tile = np.ascontiguousarray(tile)
    cv2.rectangle(tile, (0, 0), (tile.shape[1] - 1, 17), (0, 0, 0), -1)
    cv2.putText(tile, text, (4, 13), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (255, 255, 255), 1, cv2.LINE_AA)
    return np.pad(tile, ((2, 2), (2, 2), (0, 0)), constant_values=255)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", required=True, help="a checkout of the older generator")
    ap.add_argument("--kit", default=str(ROOT.parent / "shared" / "external" / "kit_ais" / "MOS74-93" / "MOS74.png"))
    ap.add_argument("--out", default=str(ROOT / "docs" / "img" / "world_before_after.png"))
    ap.add_argument("--tmp", default="/tmp")
    args = ap.parse_args()
    tmp = Path(args.tmp)
    before = _crop_from(Path(args.before).resolve(), tmp)
    after = _crop_from(ROOT, tmp)
    real = cv2.imread(args.kit)
    if real is None:
        sys.exit(f"--kit: cannot read {args.kit}")
    kit = cv2.cvtColor(real, cv2.COLOR_BGR2RGB)[KIT_CROP]
    sheet = np.hstack([_label(before, "before"), _label(after, "after"), _label(kit, "real: KIT AIS, same car size")])
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(args.out, cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR))
    print(json.dumps({"out": args.out, "size": [sheet.shape[1], sheet.shape[0]]}))


if __name__ == "__main__":
    main()
