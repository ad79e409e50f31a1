"""Real footage in the report: which scenes are real, their metric table, and a frame with boxes and tracks.

A real sequence (``scenes.footage``; ``meta.json`` ``"source": "real"``) carries only the truths
its annotations give, so its table shows the metrics it has and "n/a" for the rest, never a
zero. Its picture is one annotated frame per pipeline: the ground-truth boxes (tracks.csv
boxes with identities, or the YOLO boxes of boxes.csv) in white, and the pipeline's tracks on
that frame in the pipeline's colour: the multi-target tracker's boxes with their ids, the point
tracker's positions as crosses.

Public functions
----------------
real_scenes(data) -> [scene label]                      the real scenes, in the run's scene order
picture_frame(data, scene) -> int | None                 the frame the pictures show (the middle one)
truth_boxes(seq, frame) -> DataFrame                     ground-truth boxes of one frame (x0, y0, x1, y1)
cell_tracks_at(cell_dir, frame) -> DataFrame             a cell's estimated tracks on one frame, boxes where kept
draw_boxes_and_tracks(rgb, truth, tracks, *, color_rgb) -> rgb
real_metric_table(data, scene) -> MetricTable            pipelines x metrics (pooled), n/a where absent
"""

from __future__ import annotations

import cv2
import numpy as np
import pandas as pd

from harness import cell_artifacts as artifacts
from reports.load import RunData, open_scene_sequence
from reports.tables import Column, MetricTable, metric_table

__all__ = ["TRUTH_RGB", "real_scenes", "picture_frame", "truth_boxes", "cell_tracks_at", "draw_boxes_and_tracks",
           "real_metric_table", "REAL_METRIC_ORDER"]

TRUTH_RGB = (255, 255, 255)
_BOX = ["bbox_x0_px", "bbox_y0_px", "bbox_x1_px", "bbox_y1_px"]
# the metrics a real clip can have, first in its table (others follow in the table's order)
REAL_METRIC_ORDER = ["mota", "idf1", "hota", "deta", "assa", "motp", "mot_false_positives", "mot_misses",
                     "id_switches", "det_precision", "det_recall", "photometric_residual", "stab_itf_db",
                     "stab_stability", "epe_mean", "time_total_ms"]


def real_scenes(data: RunData) -> list[str]:
    """Scene labels of ``data`` that are real footage (run.json's cells say so), in the run's scene order."""
    real = set(data.folder.real_scenes)
    return [s for s in data.scenes if s in real]


def picture_frame(data: RunData, scene: str) -> int | None:
    """The frame the real-footage pictures of ``scene`` show: the middle frame of its sequence."""
    seed = data.table.loc[data.table["scene"] == scene, "seed"].iloc[0]
    seq = open_scene_sequence(data, scene=scene, seed=seed)
    return None if seq is None else len(seq) // 2


def truth_boxes(seq, frame: int) -> pd.DataFrame:
    """The ground-truth boxes of ``frame``: ``x0, y0, x1, y1`` px (and ``id`` where the truth has identities).

    tracks.csv (MOTChallenge-like truth, visible rows) where it exists, else boxes.csv (YOLO boxes
    without identities); empty without either.
    """
    cols = ["x0", "y0", "x1", "y1", "id"]
    tracks = getattr(seq, "tracks", None)
    if tracks is not None and set(_BOX) <= set(tracks.columns):
        t = tracks[(tracks["frame"] == frame) & (tracks["visible"].astype(int) > 0)]
        out = pd.DataFrame(t[_BOX].to_numpy(float), columns=cols[:4])
        out["id"] = t["vehicle_id"].to_numpy()
        return out
    boxes = getattr(seq, "boxes", None)
    if boxes is not None and len(boxes):
        b = boxes[boxes["frame"] == frame]
        out = pd.DataFrame(b[_BOX].to_numpy(float), columns=cols[:4])
        out["id"] = -1
        return out
    return pd.DataFrame(columns=cols)


def cell_tracks_at(cell_dir, frame: int) -> pd.DataFrame:
    """A cell's estimated tracks on ``frame``: ``source, track_id, x, y`` (filtered position, px) and the
    box ``x0, y0, x1, y1`` where the tracker keeps one (NaN otherwise)."""
    df = artifacts.read_tracks(cell_dir)
    cols = ["source", "track_id", "x", "y", "x0", "y0", "x1", "y1"]
    if df is None or df.empty:
        return pd.DataFrame(columns=cols)
    df = df[df["frame"] == frame]
    out = pd.DataFrame({"source": df["source"].astype(str).to_numpy(), "track_id": df["track_id"].to_numpy(),
                        "x": df["x_filt_px"].to_numpy(float), "y": df["y_filt_px"].to_numpy(float)})
    for short, col in zip(("x0", "y0", "x1", "y1"), _BOX):
        out[short] = df[col].to_numpy(float) if col in df.columns else np.nan
    return out[cols]


def draw_boxes_and_tracks(rgb: np.ndarray, truth: pd.DataFrame, tracks: pd.DataFrame, *,
                          color_rgb: tuple[int, int, int]) -> np.ndarray:
    """``rgb`` (H, W, 3) uint8 with the truth's boxes (white, 1 px) and the tracks (``color_rgb``, 2 px).

    Boxed tracks are drawn as rectangles labelled with their track id; tracks without a box as
    crosses. Boxes are continuous in pixel-centre coordinates (``x0`` is the left edge of the first column
    inside the box, half a pixel left of its centre); a rectangle is drawn on the outermost pixels inside.
    """
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
        raise ValueError(f"draw_boxes_and_tracks: expected (H, W, 3) uint8, got {rgb.shape} {rgb.dtype}")
    out = np.ascontiguousarray(rgb).copy()

    def pt(x, y):
        return int(round(float(x))), int(round(float(y)))

    for b in truth.itertuples(index=False):
        cv2.rectangle(out, pt(b.x0 + 0.5, b.y0 + 0.5), pt(b.x1 - 0.5, b.y1 - 0.5), TRUTH_RGB, 1, cv2.LINE_8)
    color = tuple(int(c) for c in color_rgb)
    for t in tracks.itertuples(index=False):
        if np.isfinite([t.x0, t.y0, t.x1, t.y1]).all():
            cv2.rectangle(out, pt(t.x0 + 0.5, t.y0 + 0.5), pt(t.x1 - 0.5, t.y1 - 0.5), color, 2, cv2.LINE_8)
            cv2.putText(out, str(int(t.track_id)), pt(t.x0 + 0.5, t.y0 - 2.5), cv2.FONT_HERSHEY_SIMPLEX, 0.4, color, 1,
                        cv2.LINE_AA)
        elif np.isfinite([t.x, t.y]).all():
            cv2.drawMarker(out, pt(t.x, t.y), color, cv2.MARKER_CROSS, 9, 2, cv2.LINE_8)
    return out


def real_metric_table(data: RunData, scene: str) -> MetricTable:
    """Pipelines x metrics of ``scene``, pooled from sums and counts, with the best marked per column.

    Each metric in its headline view (:func:`reports.load.primary_rows`); a track metric that the
    multi-target tracker has is shown for it alone (not pooled with the point tracker's). Metrics
    that matter on real footage first (:data:`REAL_METRIC_ORDER`), then the rest the scene has,
    timings but the total left out; a pipeline without a row shows "n/a" (no truth, no value).
    """
    rows = data.ok[data.ok["scene"] == scene]
    tracked = set(pd.unique(rows.loc[rows["region"] == "multi", "metric"]))
    rows = rows[~(rows["metric"].isin(tracked) & (rows["region"] == "point"))]
    first = rows.drop_duplicates("metric")
    present = first["metric"].astype(str).tolist()
    order = [m for m in REAL_METRIC_ORDER if m in present] + [m for m in present if m not in REAL_METRIC_ORDER
                                                            and not m.startswith("time_")]
    info = first.set_index("metric")
    cols = [Column(m, m, str(info.at[m, "unit"]), bool(info.at[m, "higher_is_better"])) for m in order]
    all_rows = data.table.loc[data.table["scene"] == scene, ["pipeline", "cell_id"]]
    return metric_table(data, rows, cols, all_rows=all_rows)
