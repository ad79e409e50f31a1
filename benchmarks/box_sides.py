"""Where detection boxes are off: each side's offset from the truth box of the vehicle it found.

Not a speed benchmark: the check of the detection box (``algorithms.detection``, step 6 and the cast-shadow
trim) against the vehicles' boxes, side by side. Run from the project root:

    python benchmarks/box_sides.py [--scene nominal ...] [--seq DIR ...] [--pipeline dis ...] [--frames 30]
                                   [--set detection.shadow_trim_rel=0.35 ...]

Per scene (a preset rendered into ``$AEROBENCH_CACHE``, or a rendered sequence folder with ``--seq``, its first
``--frames`` frames) and pipeline, the detections of each pair are matched one to one to the moving vehicles
visible in frame t (Hungarian on box IoU, pairs under IoU 0.1 left out). Of each matched pair, each side's
**excess** in px: how far the detection's side lies outside the truth's (left ``tx0 - dx0``, top ``ty0 - dy0``,
right ``dx1 - tx1``, bottom ``dy1 - ty1``; positive: the box too large there, the side a cast shadow would grow).
Printed: MOTA and IDF1 of the ``multi`` tracks against the moving vehicles (as ``tracking_quality.py`` scores
them), the matched count, the share at IoU >= 0.5 (what the metrics count a fit), the mean IoU and each side's
median excess and its share over 2 px.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.optimize import linear_sum_assignment

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

from algorithms.pipeline import PIPELINES  # noqa: E402
from benchmarks._overrides import pipeline_with, scene_overrides  # noqa: E402
from benchmarks.tracking_quality import _det_boxes, run_multi  # noqa: E402
from harness.metrics import mot_counts  # noqa: E402
from harness.metrics.matching import box_iou, boxes_of  # noqa: E402

SIDES = ("left", "top", "right", "bottom")


def side_excess(det: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(N, 4) px each side of ``det`` (N, 4) lies outside ``truth`` (N, 4): left, top, right, bottom."""
    return np.stack([truth[:, 0] - det[:, 0], truth[:, 1] - det[:, 1], det[:, 2] - truth[:, 2],
                     det[:, 3] - truth[:, 3]], 1)


def match_sides(dets: list, truth: pd.DataFrame, *, min_iou: float = 0.1) -> pd.DataFrame:
    """One row per detection matched to a vehicle: frame, vehicle_id, iou and the four excesses."""
    rows = []
    for f, d_f in enumerate(dets):
        t_f = truth[truth["frame"] == f]
        if not len(d_f) or not len(t_f):
            continue
        db, tb = _det_boxes(d_f), boxes_of(t_f)
        iou = np.nan_to_num(box_iou(tb, db))
        ti, di = linear_sum_assignment(-iou)
        ok = iou[ti, di] >= min_iou
        ti, di = ti[ok], di[ok]
        ex = side_excess(db[di], tb[ti])
        for k in range(len(ti)):
            rows.append({"frame": f, "vehicle_id": int(t_f["vehicle_id"].iloc[ti[k]]), "iou": iou[ti[k], di[k]],
                         **{s: ex[k, j] for j, s in enumerate(SIDES)}})
    return pd.DataFrame(rows, columns=["frame", "vehicle_id", "iou", *SIDES])


def summary(m: pd.DataFrame) -> dict:
    out = {"matched": len(m), "fit": float((m["iou"] >= 0.5).mean()) if len(m) else np.nan,
           "iou": float(m["iou"].mean()) if len(m) else np.nan}
    for s in SIDES:
        out[s] = float(m[s].median()) if len(m) else np.nan
        out[s + ">2"] = float((m[s] > 2).mean()) if len(m) else np.nan
    return out


def main(argv: list[str] | None = None) -> int:
    from scenes import load_scene_spec, open_sequence
    from scenes.cache import cached_sequence

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", nargs="*", default=[], help="preset names or YAML paths")
    ap.add_argument("--seq", nargs="*", default=[], help="rendered sequence folders")
    ap.add_argument("--pipeline", nargs="+", default=["dis"], choices=sorted(PIPELINES))
    ap.add_argument("--frames", type=int, default=None)
    ap.add_argument("--seed", type=int, default=None)
    ap.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    args = ap.parse_args(argv)
    cache = os.environ.get("AEROBENCH_CACHE", ".aerobench-cache")
    paths = [(s, cached_sequence(load_scene_spec(s, scene_overrides(frames=args.frames, seed=args.seed)), cache))
             for s in args.scene] + [(Path(p).name, Path(p)) for p in args.seq]
    rows = []
    for label, path in paths:
        seq = open_sequence(path)
        n = min(len(seq), args.frames or len(seq))
        frames = [seq.frame(i) for i in range(n)]
        truth = seq.tracks
        truth = truth[truth["frame"] < n]
        if "parked" in truth.columns:
            truth = truth[truth["parked"].astype(int) == 0]
        moving, truth = truth, truth[truth["visible"].astype(bool)]
        for name in args.pipeline:
            tracks, dets, _, _ = run_multi(pipeline_with(name, args.set), frames, gsd_m_per_px=seq.meta.get("gsd_m"))
            cm = mot_counts(tracks, moving)
            row = {"scene": label, "pipeline": name, "mota": cm.mota, "idf1": cm.idf1,
                   **summary(match_sides(dets, truth))}
            rows.append(row)
            print("  ".join(f"{k} {v:.3f}" if isinstance(v, float) else f"{k} {v}" for k, v in row.items()),
                  flush=True)
    print(pd.DataFrame(rows).round(3).to_string(index=False))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
