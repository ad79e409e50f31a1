"""Detection quality per scene and pipeline: is each moving vehicle found, and does its box fit?

Not a speed benchmark: the accuracy check of the detection stage (``algorithms.detection``)
alone, before any tracker, over whole synthetic sequences. Run from the project root:

    python benchmarks/detection_quality.py [--scene nominal ...] [--pipeline dis ...] [--frames 30]
        [--seed 1] [--gate 20] [--set detection.core_rel=0.4 ...] [--scene-set image.width_px=1920 ...]
        [--csv out.csv]

Renders (or reuses from ``$AEROBENCH_CACHE``, default ``.aerobench-cache``) each scene
(default ``nominal realistic urban-parallax fast-vehicles city``, ``--frames`` frames,
default 30; ``--scene-set`` overrides any scene key, e.g. the image size to check that the
defaults hold at another resolution), runs each pipeline (default ``dis pyramidal-lk pyramidal-hs tv-l1 farneback``)
with the sequence's ground sampling distance, and scores the detections of pair t against
frame t's vehicles that move (:func:`harness.metrics.detection.moving_vehicles`: not parked,
at least 0.5 m/s in that frame). In each frame the detections are assigned one-to-one to
those vehicles by the Hungarian method twice (:func:`match_frame`): on centre distance, a
detection within ``--gate`` px of the vehicle's centre or inside its box; and on IoU. Per
scene and pipeline:

- ``recall``: share of moving vehicle-frames with a detection found on them (the first rule);
- ``iou50``: share of moving vehicle-frames whose detection's box overlaps the vehicle's box at
  IoU >= 0.5 (the box-aware scoring rule; boxes as :mod:`harness.metrics.matching` takes them:
  the truth's continuous extent, the detection's inclusive pixel range widened by half a pixel);
- ``iou_med``, ``iou_p25``: median and 25th percentile IoU of the vehicles found;
- ``w_ratio``, ``h_ratio``: median detection width / true width and height / true height of the
  matched pairs (``w_sd_px``, ``h_sd_px``: the standard deviation of the width and height
  differences, px);
- ``fp/frame``: detections found on no moving vehicle, per frame (on parked cars, roofs,
  trees, noise; a second detection on one vehicle);
- ``dets/frame``, ``cars/frame``: detections and moving vehicles per frame;
- ``det_ms``: the detection stage's mean wall-clock ms per pair in this process (indicative only;
  ``benchmarks/pipeline_speed.py`` times pipelines properly).

The last table pools each pipeline over the scenes (sums of counts, medians of the pooled pairs).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

from algorithms.pipeline import PIPELINES, SequenceEstimate  # noqa: E402
from harness.metrics.detection import detection_boxes, moving_vehicles  # noqa: E402
from harness.metrics.matching import BOX_COLUMNS, _linear_sum_assignment, box_iou  # noqa: E402
from benchmarks._overrides import pipeline_with, scene_overrides  # noqa: E402

SCENES = ("nominal", "realistic", "urban-parallax", "fast-vehicles", "city")
DEFAULT_PIPELINES = ("dis", "pyramidal-lk", "pyramidal-hs", "tv-l1", "farneback")


def match_frame(detections, truth_frame: pd.DataFrame, *, gate_px: float) -> tuple[list[dict], int]:
    """One frame's moving vehicles, each with its detection, and the false positives.

    Two one-to-one assignments (Hungarian method): *found*, a detection whose centre lies within
    ``gate_px`` of the vehicle's centre or inside its box (the gate alone is too tight for the
    large vehicles of a high resolution, the box alone too strict for a small one); *box*, on
    IoU, the scoring rule. Returns ``(rows, false_positives)``: a row per moving vehicle,
    ``dist_px`` (NaN: not found), ``iou`` (of its box assignment, 0 without one), true and
    detected width and height (px, continuous extents; the detected ones of the box assignment,
    else of the found one); false positives are the detections found on no moving vehicle.
    """
    counted, _ = moving_vehicles(truth_frame)
    t = truth_frame[counted]
    tb = np.stack([t[c].to_numpy(np.float64) for c in BOX_COLUMNS], 1) if len(t) else np.zeros((0, 4))
    centres, boxes = detection_boxes(detections)
    P = np.stack([(tb[:, 0] + tb[:, 2]) / 2, (tb[:, 1] + tb[:, 3]) / 2], 1)
    found_of = np.full(len(t), -1)
    box_of = np.full(len(t), -1)
    iou = np.zeros((len(t), len(centres)))
    if len(t) and len(centres):
        D = np.hypot(P[:, None, 0] - centres[None, :, 0], P[:, None, 1] - centres[None, :, 1])
        inside = ((tb[:, None, 0] <= centres[None, :, 0]) & (centres[None, :, 0] <= tb[:, None, 2])
                  & (tb[:, None, 1] <= centres[None, :, 1]) & (centres[None, :, 1] <= tb[:, None, 3]))
        ok = (D <= gate_px) | inside
        ia, ib = _linear_sum_assignment(np.where(ok, D, 1e9))
        hit = ok[ia, ib]
        found_of[ia[hit]] = ib[hit]
        iou = np.nan_to_num(box_iou(tb, boxes))
        ia, ib = _linear_sum_assignment(-iou)
        hit = iou[ia, ib] > 0
        box_of[ia[hit]] = ib[hit]
    rows = []
    for v in range(len(t)):
        row = {"tw": tb[v, 2] - tb[v, 0], "th": tb[v, 3] - tb[v, 1], "dist_px": np.nan, "iou": 0.0,
               "dw": np.nan, "dh": np.nan}
        j = found_of[v]
        if j >= 0:
            row["dist_px"] = float(np.hypot(*(centres[j] - P[v])))
        k = box_of[v] if box_of[v] >= 0 else j
        if k >= 0:
            row.update(iou=float(iou[v, k]), dw=boxes[k, 2] - boxes[k, 0], dh=boxes[k, 3] - boxes[k, 1])
        rows.append(row)
    return rows, int(len(centres) - (found_of >= 0).sum())


def summarise(rows: pd.DataFrame, n_frames: int, n_dets: int, fp: int) -> dict:
    """The figures of the module docstring from the per-vehicle rows of one or more runs."""
    m = rows.dropna(subset=["dist_px"])
    n = max(1, len(rows))
    return {"recall": len(m) / n, "iou50": float((rows["iou"] >= 0.5).sum()) / n,
            "iou_med": float(m["iou"].median()) if len(m) else np.nan,
            "iou_p25": float(m["iou"].quantile(0.25)) if len(m) else np.nan,
            "w_ratio": float((m["dw"] / m["tw"]).median()) if len(m) else np.nan,
            "h_ratio": float((m["dh"] / m["th"]).median()) if len(m) else np.nan,
            "w_sd_px": float((m["dw"] - m["tw"]).std()) if len(m) > 1 else np.nan,
            "h_sd_px": float((m["dh"] - m["th"]).std()) if len(m) > 1 else np.nan,
            "fp/frame": fp / max(1, n_frames), "dets/frame": n_dets / max(1, n_frames),
            "cars/frame": len(rows) / max(1, n_frames)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", nargs="+", default=list(SCENES), help="preset names or YAML paths")
    ap.add_argument("--pipeline", nargs="+", default=list(DEFAULT_PIPELINES), choices=sorted(PIPELINES))
    ap.add_argument("--frames", type=int, default=30, help="image.n_frames override (0: the preset's)")
    ap.add_argument("--seed", type=int, default=None, help="seed override")
    ap.add_argument("--gate", type=float, default=20.0, help="centre distance within which a detection finds a "
                    "vehicle, px")
    ap.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                    help="pipeline override, e.g. detection.core_rel=0.4")
    ap.add_argument("--scene-set", action="append", default=[], metavar="KEY=VALUE",
                    help="scene override, e.g. image.width_px=1920 (with image.height_px=1080)")
    ap.add_argument("--csv", default=None, help="also write the per-vehicle rows here")
    args = ap.parse_args(argv)
    if not args.gate > 0:
        print(f"--gate: expected > 0, got {args.gate}", file=sys.stderr)
        return 2
    try:
        pipes = {name: pipeline_with(name, args.set) for name in args.pipeline}
    except Exception as e:  # a bad override: one line naming it
        print(f"--set: {e}".splitlines()[0], file=sys.stderr)
        return 2

    from scenes import load_scene_spec, open_sequence
    from scenes.cache import cached_sequence

    cache = os.environ.get("AEROBENCH_CACHE", ".aerobench-cache")
    summary, all_rows = [], []
    for scene in args.scene:
        try:
            over = scene_overrides(frames=args.frames, seed=args.seed, sets=args.scene_set)
        except ValueError as e:
            print(f"--scene-set: {e}", file=sys.stderr)
            return 2
        seq = open_sequence(cached_sequence(load_scene_spec(scene, over), cache))
        frames = [seq.frame(i) for i in range(len(seq))]
        truth, gsd = seq.tracks, seq.meta.get("gsd_m")
        by_frame = dict(tuple(truth.groupby("frame")))
        for name, pipe in pipes.items():
            rows, fp, n_dets, det_ms = [], 0, 0, []
            for e in pipe.run(frames, gsd_m_per_px=gsd):
                if isinstance(e, SequenceEstimate):
                    continue
                r, f = match_frame(e.detections, by_frame.get(e.index, truth.iloc[:0]), gate_px=args.gate)
                rows += [{**x, "scene": scene, "pipeline": name, "frame": e.index} for x in r]
                fp, n_dets = fp + f, n_dets + len(e.detections)
                det_ms.append(e.stage_ms.get("detection", np.nan))
            df = pd.DataFrame(rows, columns=["tw", "th", "dist_px", "iou", "dw", "dh", "scene", "pipeline", "frame"])
            all_rows.append(df)
            s = {"scene": scene, "pipeline": name, **summarise(df, len(frames) - 1, n_dets, fp),
                 "det_ms": float(np.mean(det_ms)), "_n": len(frames) - 1, "_dets": n_dets, "_fp": fp}
            summary.append(s)
            print("  ".join(f"{k} {v:.3f}" if isinstance(v, float) else f"{k} {v}" for k, v in s.items()
                            if not k.startswith("_")), flush=True)
    table = pd.DataFrame(summary)
    rows = pd.concat(all_rows, ignore_index=True)
    pooled = []
    for name, g in table.groupby("pipeline", sort=False):
        pooled.append({"pipeline": name, **summarise(rows[rows["pipeline"] == name], int(g["_n"].sum()),
                                                     int(g["_dets"].sum()), int(g["_fp"].sum())),
                       "det_ms": float(g["det_ms"].mean())})
    pd.set_option("display.width", 250)
    print()
    print(table.drop(columns=["_n", "_dets", "_fp"]).round(3).to_string(index=False))
    print()
    print("pooled over scenes")
    print(pd.DataFrame(pooled).round(3).to_string(index=False))
    if args.csv:
        rows.to_csv(args.csv, index=False)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
