"""Multi-target tracking quality per pipeline: MOTA, IDF1, false positives, identity switches.

Not a speed benchmark: the accuracy check of the detection stage and the multi-target
tracker (``tracking.multi``) over whole synthetic sequences, and on KIT AIS frames.
Run from the project root:

    python benchmarks/tracking_quality.py [--scene nominal ...] [--pipeline dis ...] [--frames 30] [--seed 1]
    python benchmarks/tracking_quality.py --kit-ais [--pipeline dis ...]

Synthetic: renders (or reuses from ``$AEROBENCH_CACHE``, default ``.aerobench-cache``)
each scene (default ``nominal realistic urban-parallax fast-vehicles``; ``--frames``
and ``--seed`` override the preset's), runs each pipeline with the sequence's ground
sampling distance (``meta.json`` ``gsd_m``), and scores its ``multi`` tracks with
:func:`harness.metrics.mot_counts` (box-aware: a track's box corresponds to a
vehicle's box at IoU >= 0.5, as the harness scores; ``mota_pt``, ``idf1_pt``: the
centre rule alone, a track point within ``--gate`` px of the vehicle's centre) against
the vehicles that move (``parked == 0``; what a motion detector can find, the figure
the targets are about), and against every visible vehicle (``mota_all``). Also the detections per frame and the tracker's output per frame.
With ``--breakdown``, where the misses and false positives come from (:func:`error_breakdown`): per vehicle its
missed frames by cause (under half its box in the image: older renders only, no detection, a detection box under IoU 0.5, the tracker),
per track its false-positive frames and the vehicle it lay on.

KIT AIS (``--kit-ais``, ``../shared/external/kit_ais`` beside the clone, or ``--kit-dir``): three
Munich street sequences, YOLO boxes of every vehicle, parked or moving, without
identities. Which vehicles move is told from the boxes alone: consecutive frames are
registered by the global shift (the pipeline's own pass-1 NCC shift, the cumulative
path), every box is moved into frame 0's ground-fixed coordinates, boxes of consecutive
frames are chained by nearest centre (Hungarian, within ``--kit-link-px``, wide enough
for a vehicle's step between these frames), and a chain of at least 3 boxes whose
median ground-fixed step exceeds ``--kit-move-px`` (the labels jitter by 1-4 px) is a
moving vehicle, else a parked one; boxes of shorter chains count as unknown and are
left out of both precision and recall. A detection
is a true positive when its centre lies inside a moving vehicle's box (one detection
per box), a false positive when it lies in no moving vehicle's box; the boxes of
parked vehicles that a detection hits are counted separately.

The same detections are also scored against the vehicles that move at **some time** in the
sequence (the median of some three consecutive steps of the chain above ``--kit-move-px``), counted
in all their frames: the harness's own rule (``harness.metrics.objects``: a car queued at a light is
counted whatever its speed in that frame). The chain's median alone calls a car that brakes to a stop
half-way (MOS74-93: 33 px a frame down to 1) or pulls away from a light (MunichStreet02: 5 to 16 px)
parked in every frame, so the detections of it while it drives count as false ones: 74 of the 2,593
boxes. That figure is printed beside the first, which stays as it was (the figures quoted over the
project's history are the first). What the KIT truth leaves out counts against the detector either way:
pedestrians and cyclists (the class list has ``cyclist``; no box of one in these three sequences), a
tram (MunichStreet02), a trailer boxed apart from the van that tows it (MOS155-179); and at the
sequences' 2-3 frames a second a moving vehicle covers 10-50 px a frame (median 38), often more than its length.

A tracking figure on real footage: MOTA and IDF1 of the ``multi`` tracks against a
pseudo-MOT truth (:func:`pseudo_truth`): the moving chains taken as identities, one
vehicle id per chain, the parked chains' boxes as vehicles that do not move (a track on
one is a false positive), the unknown boxes as ignore regions (a track inside one that no
moving vehicle took is left out). It is a pseudo-truth, not an annotation: a chain breaks
where a label is missing or the chaining pairs the wrong boxes, and every break is a new
identity, so IDF1 and the switches are pessimistic where chains break and MOTA is only as
good as the moving/parked call. Box-aware as the synthetic figures (IoU >= 0.5 with the
YOLO box), and by the centre rule (the track point inside the box). Pooled over the three
sequences from summed counts.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

from algorithms.pipeline import PIPELINES, Pipeline, SequenceEstimate  # noqa: E402
from harness.metrics import MOTCounts, mot_counts  # noqa: E402
from harness.metrics.detection import detection_boxes  # noqa: E402
from benchmarks._overrides import pipeline_with as _pipeline, scene_overrides  # noqa: E402

SCENES = ("nominal", "realistic", "urban-parallax", "fast-vehicles")
KIT_DIR = Path(__file__).resolve().parents[2] / "shared" / "external" / "kit_ais"  # shared/ beside the clone
BOXES = ["bbox_x0_px", "bbox_y0_px", "bbox_x1_px", "bbox_y1_px"]


def run_multi(pipeline: Pipeline, frames, *, gsd_m_per_px=None):
    """(multi tracks DataFrame, detections per pair, SequenceEstimate, seconds)."""
    t0 = time.perf_counter()
    dets, est = [], None
    for e in pipeline.run(frames, gsd_m_per_px=gsd_m_per_px):
        if isinstance(e, SequenceEstimate):
            est = e
        else:
            dets.append(e.detections)
    tracks = est.tracks[est.tracks["source"] == "multi"]
    return tracks, dets, est, time.perf_counter() - t0


def error_breakdown(tracks: pd.DataFrame, dets: list, truth: pd.DataFrame, *, frame_shape, gate_px: float = 20.0,
                    everything: pd.DataFrame | None = None) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Where the misses and false positives of :func:`harness.metrics.mot_counts` come from, row by row.

    ``(misses, false_positives)``. A miss is a counted vehicle of a frame that no track corresponds
    to (the CLEAR-MOT frame matching itself); its ``cause``: ``out of frame`` when under half its
    box lies in the ``frame_shape`` (H, W) image (no box inside the image reaches IoU 0.5 with it; none
    since GENERATOR_VERSION 2.7.0, whose boxes are clipped to the image and whose rows under half
    visible are distractors, never misses), else ``no detection`` (no detection of that frame overlaps it by IoU 0.1), ``detection box``
    (one overlaps it, none by 0.5), ``tracker`` (a detection fits it, no track does). A false
    positive is a track row no vehicle took (after the metric's distractor removal), with the
    row of ``everything`` (all of tracks.csv, parked vehicles too; default ``truth``) its box overlaps
    most and that IoU. ``dets``: the detections of each frame (pair t's lie in frame t).
    """
    from harness.metrics.matching import box_iou, boxes_of
    from harness.metrics.trajectories import _mot_frames  # the metric's own frame matching

    h, w = frame_shape
    tb_all = boxes_of(truth)
    every = truth if everything is None else everything
    eb_all = boxes_of(every)
    fn, fp = [], []
    est = tracks.dropna(subset=["x_filt_px"])
    for f, vids, tids, _D, match, _sw, _ok in _mot_frames(tracks, truth, gate_px=gate_px):
        rows_f = truth["frame"].to_numpy() == f
        d_f = dets[f] if 0 <= f < len(dets) else []
        db = detection_boxes(d_f)[1]
        e_f = est[est["frame"] == f]
        for a, vid in enumerate(vids):
            if a in match:
                continue
            sel = rows_f & (truth["vehicle_id"].to_numpy() == vid)
            b = tb_all[sel][0]
            area = (b[2] - b[0]) * (b[3] - b[1])
            inside = (max(0.0, min(b[2], w) - max(b[0], 0.0)) * max(0.0, min(b[3], h) - max(b[1], 0.0)) / area
                      if area > 0 else 1.0)
            det_iou = float(np.nanmax(box_iou(b, db))) if len(db) else 0.0
            trk = boxes_of(e_f[e_f["track_id"].isin(tids)])
            trk_iou = float(np.nanmax(box_iou(b, trk))) if len(trk) else 0.0
            cause = ("out of frame" if inside < 0.5 else "no detection" if det_iou < 0.1 else
                     "detection box" if det_iou < 0.5 else "tracker")
            fn.append({"frame": int(f), "vehicle_id": int(vid), "class": truth.loc[sel, "class"].iloc[0]
                       if "class" in truth.columns else "car", "w_px": b[2] - b[0], "h_px": b[3] - b[1],
                       "in_image": inside, "det_iou": det_iou, "track_iou": trk_iou, "cause": cause})
        matched = set(match.values())
        for bi, tid in enumerate(tids):
            if bi in matched:
                continue
            eb = boxes_of(e_f[e_f["track_id"] == tid])[:1]
            in_f = every["frame"].to_numpy() == f
            ious = box_iou(eb, eb_all[in_f])[0] if in_f.any() else np.zeros(0)
            j = int(np.nanargmax(ious)) if len(ious) and np.isfinite(ious).any() and np.nanmax(ious) > 0 else -1
            near = every[in_f].iloc[j] if j >= 0 else None
            fp.append({"frame": int(f), "track_id": int(tid), "w_px": eb[0, 2] - eb[0, 0],
                       "h_px": eb[0, 3] - eb[0, 1], "best_iou": float(ious[j]) if j >= 0 else 0.0,
                       "vehicle_id": int(near["vehicle_id"]) if near is not None else -1,
                       "parked": int(near["parked"]) if near is not None and "parked" in every.columns else -1})
    return (pd.DataFrame(fn, columns=["frame", "vehicle_id", "class", "w_px", "h_px", "in_image", "det_iou",
                                      "track_iou", "cause"]),
            pd.DataFrame(fp, columns=["frame", "track_id", "w_px", "h_px", "best_iou", "vehicle_id", "parked"]))


def _print_breakdown(fn: pd.DataFrame, fp: pd.DataFrame) -> None:
    """Per vehicle: its missed frames by cause; per track: its false-positive frames and the vehicle it lay on."""
    if len(fn):
        by = fn.groupby(["vehicle_id", "class", "cause"]).agg(frames=("frame", "size"), first=("frame", "min"),
                                                             last=("frame", "max"), w_px=("w_px", "mean"),
                                                             h_px=("h_px", "mean"), det_iou=("det_iou", "mean"))
        print("    misses:\n" + "\n".join("      " + line for line in by.round(2).to_string().splitlines()))
    if len(fp):
        by = fp.groupby("track_id").agg(frames=("frame", "size"), first=("frame", "min"), last=("frame", "max"),
                                        w_px=("w_px", "mean"), h_px=("h_px", "mean"), best_iou=("best_iou", "mean"),
                                        on_vehicle=("vehicle_id", lambda s: int(s.mode().iat[0])),
                                        parked=("parked", "max"))
        print("    false positives:\n" + "\n".join("      " + line for line in by.round(2).to_string().splitlines()))


def synthetic(args) -> int:
    from scenes import load_scene_spec, open_sequence
    from scenes.cache import cached_sequence

    cache = os.environ.get("AEROBENCH_CACHE", ".aerobench-cache")
    rows = []
    for scene in args.scene:
        over = scene_overrides(frames=args.frames, seed=args.seed)
        seq = open_sequence(cached_sequence(load_scene_spec(scene, over), cache))
        frames = [seq.frame(i) for i in range(len(seq))]
        truth = seq.tracks
        moving = truth[truth["parked"].astype(int) == 0] if "parked" in truth.columns else truth
        vis = moving[moving["visible"].astype(bool)]
        n_moving = vis.groupby("frame").size().reindex(range(len(seq)), fill_value=0)
        gsd = seq.meta.get("gsd_m")
        print(f"scene {scene} {over}: {len(seq)} frames, {n_moving.mean():.1f} moving vehicles visible a frame, "
              f"gsd {gsd} m/px", flush=True)
        for name in args.pipeline:
            tracks, dets, _, secs = run_multi(_pipeline(name, args.set), frames, gsd_m_per_px=gsd)
            cm = mot_counts(tracks, moving, gate_px=args.gate)
            ca = mot_counts(tracks, truth, gate_px=args.gate)
            # the centre rule alone (no boxes on either side): a track point within the gate of the centre
            cp = mot_counts(tracks.drop(columns=BOXES, errors="ignore"), moving.drop(columns=BOXES, errors="ignore"),
                            gate_px=args.gate)
            row = {"scene": scene, "pipeline": name, "mota": cm.mota, "idf1": cm.idf1, "fp": cm.false_positives,
                   "fn": cm.misses, "idsw": cm.switches, "motp_px": cm.motp_px,
                   "dets/frame": np.mean([len(d) for d in dets]),
                   "tracks/frame": tracks.dropna(subset=["x_filt_px"]).groupby("frame").size().mean()
                   if len(tracks) else 0.0,
                   "mota_all": ca.mota, "idf1_all": ca.idf1, "mota_pt": cp.mota, "idf1_pt": cp.idf1, "s": secs}
            rows.append(row)
            print("  " + "  ".join(f"{k} {v:.3f}" if isinstance(v, float) else f"{k} {v}" for k, v in row.items()),
                  flush=True)
            if args.breakdown:
                _print_breakdown(*error_breakdown(tracks, dets, moving, frame_shape=frames[0].shape[:2],
                                                  gate_px=args.gate, everything=truth))
    df = pd.DataFrame(rows)
    print()
    print(df.round(3).to_string(index=False))
    return 0


# ------------------------------------------------------------------------------------------- KIT AIS

def _read_yolo(path: Path, w: int, h: int) -> np.ndarray:
    """(N, 4) boxes x0, y0, x1, y1 in px of a YOLO label file (``class cx cy w h`` as fractions of the image's
    edges), in pixel-centre coordinates as a sequence's boxes (pixel i spans [i - 0.5, i + 0.5])."""
    if not path.is_file():
        return np.zeros((0, 4))
    a = np.loadtxt(path, ndmin=2)
    if a.size == 0:
        return np.zeros((0, 4))
    cx, cy, bw, bh = a[:, 1] * w, a[:, 2] * h, a[:, 3] * w, a[:, 4] * h
    return np.stack([cx - bw / 2, cy - bh / 2, cx + bw / 2, cy + bh / 2], axis=1) - 0.5


def moving_labels(boxes: list[np.ndarray], path_px: np.ndarray, *, link_px: float, move_px: float,
                  min_frames: int = 3) -> list[np.ndarray]:
    """Per frame, a label per box: 1 moving, 0 parked, -1 unknown (see the module docstring)."""
    return moving_chains(boxes, path_px, link_px=link_px, move_px=move_px, min_frames=min_frames)[0]


def moving_chains(boxes: list[np.ndarray], path_px: np.ndarray, *, link_px: float, move_px: float,
                  min_frames: int = 3, rule: str = "median") -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Per frame, a label per box (1 moving, 0 parked, -1 unknown) and the id of its chain (from 1).

    ``path_px`` (N, 2): cumulative global shift of frame t (ground content displacement since frame 0).
    Boxes of consecutive frames are paired by the Hungarian method on the distance of their
    ground-fixed centres within ``link_px`` (wide enough for a vehicle's motion between frames);
    a chain of at least ``min_frames`` boxes is moving when its median step exceeds ``move_px``
    (``rule="median"``), or (``rule="ever"``) when the median of some three consecutive steps does: a
    vehicle that moves at some time in the sequence, counted in all its frames (the harness's rule,
    ``harness.metrics.objects``: a car queued at a light is counted whatever its speed in that frame).
    """
    if rule not in ("median", "ever"):
        raise ValueError(f"rule: expected median or ever, got {rule!r}")
    from scipy.optimize import linear_sum_assignment

    centres = [np.stack([(b[:, 0] + b[:, 2]) / 2, (b[:, 1] + b[:, 3]) / 2], 1) - path_px[t] if len(b)
               else np.zeros((0, 2)) for t, b in enumerate(boxes)]
    chain_of = [np.full(len(b), -1) for b in boxes]
    chains: list[list[tuple[int, int]]] = []
    for j in range(len(centres[0])):
        chain_of[0][j] = len(chains)
        chains.append([(0, j)])
    for t in range(1, len(boxes)):
        a, b = centres[t - 1], centres[t]
        if len(a) and len(b):
            D = np.hypot(a[:, None, 0] - b[None, :, 0], a[:, None, 1] - b[None, :, 1])
            r, q = linear_sum_assignment(np.where(D <= link_px, D, 1e9))
            for i, j in zip(r, q):
                if D[i, j] <= link_px:
                    chain_of[t][j] = chain_of[t - 1][i]
                    chains[chain_of[t][j]].append((t, int(j)))
        for j in np.flatnonzero(chain_of[t] < 0):
            chain_of[t][j] = len(chains)
            chains.append([(t, int(j))])
    labels = [np.full(len(b), -1) for b in boxes]
    for ch in chains:
        if len(ch) < min_frames:
            continue
        steps = [float(np.hypot(*(centres[t1][j1] - centres[t0][j0]))) for (t0, j0), (t1, j1) in zip(ch, ch[1:])]
        moving = float(np.median(steps)) > move_px if rule == "median" else any(
            float(np.median(steps[max(0, i - 1):i + 2])) > move_px for i in range(len(steps)))
        for t, j in ch:
            labels[t][j] = 1 if moving else 0
    return labels, [c + 1 for c in chain_of]


def score_points(points: list, boxes: list[np.ndarray], labels: list[np.ndarray]) -> tuple[int, int, int]:
    """``(tp, fp, on parked)`` of points against the labelled boxes (the module docstring's rule).

    ``points[t]``: the (x, y) of frame t's detections (or track points); a point inside an unused
    moving box is a true positive (one per box), one in no moving box a false positive unless it
    lies in an unknown box; ``on parked``: the false ones inside a parked vehicle's box.
    """
    tp = fp = parked_hits = 0
    for t, pts in enumerate(points):
        b, lab = boxes[t], labels[t]
        used = set()
        for x, y in pts:
            inside = np.flatnonzero((b[:, 0] <= x) & (x <= b[:, 2]) & (b[:, 1] <= y) & (y <= b[:, 3])) if len(b) else []
            mov = [j for j in inside if lab[j] == 1 and j not in used]
            if mov:
                tp += 1
                used.add(mov[0])
            elif any(lab[j] == 0 for j in inside):
                parked_hits += 1
                fp += 1
            elif not any(lab[j] == -1 for j in inside):
                fp += 1
    return tp, fp, parked_hits


def pseudo_truth(boxes: list[np.ndarray], labels: list[np.ndarray], chains: list[np.ndarray],
                 n_frames: int) -> tuple[pd.DataFrame, pd.DataFrame]:
    """A pseudo-MOT truth of the moving chains, and the unknown boxes as ignore regions.

    ``(truth, ignore)``: truth has a row per box of a moving chain (``vehicle_id`` its chain,
    ``moving`` 1) and per box of a parked one (``moving`` 0: a track on it is a false positive);
    ignore (``frame, bbox_*``) the boxes of chains too short to tell, which a track may cover
    without counting either way. Only the first ``n_frames`` frames.
    """
    rows, ign = [], []
    for t in range(min(n_frames, len(boxes))):
        for (x0, y0, x1, y1), lab, cid in zip(boxes[t], labels[t], chains[t]):
            if lab < 0:
                ign.append({"frame": t, "bbox_x0_px": x0, "bbox_y0_px": y0, "bbox_x1_px": x1, "bbox_y1_px": y1,
                            "class": "car"})
                continue
            rows.append({"frame": t, "vehicle_id": int(cid), "x_px": (x0 + x1) / 2, "y_px": (y0 + y1) / 2,
                         "bbox_x0_px": x0, "bbox_y0_px": y0, "bbox_x1_px": x1, "bbox_y1_px": y1, "visible": 1,
                         "class": "car", "moving": int(lab)})
    cols = ["frame", "vehicle_id", "x_px", "y_px", *BOXES, "visible", "class", "moving"]
    return pd.DataFrame(rows, columns=cols), pd.DataFrame(ign, columns=["frame", *BOXES, "class"])


def kit_ais(args) -> int:
    import cv2

    root = Path(args.kit_dir)
    seqs = sorted(p for p in root.iterdir() if p.is_dir())
    if not seqs:
        print(f"--kit-dir: no sequence folders in {root}", file=sys.stderr)
        return 2
    total: dict[str, dict[str, int]] = {}
    for folder in seqs:
        pngs = sorted(folder.glob("*.png"), key=lambda p: int("".join(ch for ch in p.stem.split("MOS")[-1]
                                                                          if ch.isdigit()) or 0))
        frames = [cv2.cvtColor(cv2.imread(str(p)), cv2.COLOR_BGR2RGB) for p in pngs]
        h, w = frames[0].shape[:2]
        boxes = [_read_yolo(p.with_suffix(".txt"), w, h) for p in pngs]
        for name in args.pipeline:
            _, dets, est, secs = run_multi(_pipeline(name, args.set), frames)
            labels, chains = moving_chains(boxes, est.cumulative_px, link_px=args.kit_link_px,
                                           move_px=args.kit_move_px)
            tracks = est.tracks[est.tracks["source"] == "multi"]
            # MOTA / IDF1 against the pseudo-MOT truth of the moving chains (box-aware, and the centre rule)
            ptruth, pignore = pseudo_truth(boxes, labels, chains, len(frames))
            cm = mot_counts(tracks, ptruth, gate_px=args.gate, ignore=pignore)
            cp = mot_counts(tracks.drop(columns=BOXES, errors="ignore"), ptruth.drop(columns=BOXES), gate_px=args.gate,
                            ignore=pignore)
            n_moving = sum(int((lab == 1).sum()) for lab in labels[:len(dets)])
            n_parked = sum(int((lab == 0).sum()) for lab in labels[:len(dets)])
            # pair t's detections lie in frame t
            tp, fp, parked_hits = score_points([[(d[0], d[1]) for d in dd] for dd in dets], boxes, labels)
            ttp = tfp = 0
            for t in range(len(dets)):
                b, lab = boxes[t], labels[t]
                # confirmed tracks' points of this frame, scored the same way
                tt = tracks[(tracks["frame"] == t)].dropna(subset=["x_filt_px"])
                used = set()
                for x, y in zip(tt["x_filt_px"], tt["y_filt_px"]):
                    inside = np.flatnonzero((b[:, 0] <= x) & (x <= b[:, 2]) & (b[:, 1] <= y) & (y <= b[:, 3])) \
                        if len(b) else []
                    mov = [j for j in inside if lab[j] == 1 and j not in used]
                    if mov:
                        ttp += 1
                        used.add(mov[0])
                    elif not any(lab[j] == -1 for j in inside):
                        tfp += 1
            n_mov_pairs = sum(int((labels[t] == 1).sum()) for t in range(len(dets)))
            # the same detections against the vehicles that move at some time in the sequence (the harness's rule)
            ever = moving_chains(boxes, est.cumulative_px, link_px=args.kit_link_px, move_px=args.kit_move_px,
                                 rule="ever")[0]
            etp, efp, _ = score_points([[(d[0], d[1]) for d in dd] for dd in dets], boxes, ever)
            n_ever = sum(int((ever[t] == 1).sum()) for t in range(len(dets)))
            prec = tp / (tp + fp) if tp + fp else math.nan
            rec = tp / n_mov_pairs if n_mov_pairs else math.nan
            tprec = ttp / (ttp + tfp) if ttp + tfp else math.nan
            trec = ttp / n_mov_pairs if n_mov_pairs else math.nan
            print(f"{folder.name} {w}x{h} {len(frames)} frames, {name}: moving boxes {n_moving}, parked {n_parked}; "
                  f"detections precision {prec:.3f} recall {rec:.3f} (tp {tp}, fp {fp} of which on parked {parked_hits}); "
                  f"tracks precision {tprec:.3f} recall {trec:.3f}; pseudo-MOT: MOTA {cm.mota:.3f} IDF1 {cm.idf1:.3f} "
                  f"(fp {cm.false_positives}, fn {cm.misses}, idsw {cm.switches}), centre rule MOTA {cp.mota:.3f} "
                  f"IDF1 {cp.idf1:.3f}; moving at some time: detections precision {etp / max(1, etp + efp):.3f} "
                  f"recall {etp / max(1, n_ever):.3f}; {secs:.1f} s", flush=True)
            agg = total.setdefault(name, {"tp": 0, "fp": 0, "n": 0, "ttp": 0, "tfp": 0, "parked": 0, "mot": [],
                                          "mot_pt": [], "etp": 0, "efp": 0, "en": 0})
            for k, v in (("tp", tp), ("fp", fp), ("n", n_mov_pairs), ("ttp", ttp), ("tfp", tfp),
                         ("parked", parked_hits), ("etp", etp), ("efp", efp), ("en", n_ever)):
                agg[k] += v
            agg["mot"].append(cm)
            agg["mot_pt"].append(cp)
    print()
    for name, a in total.items():
        print(f"all KIT AIS, {name}: detections precision {a['tp'] / max(1, a['tp'] + a['fp']):.3f} "
              f"recall {a['tp'] / max(1, a['n']):.3f} (on parked vehicles {a['parked']}); tracks precision "
              f"{a['ttp'] / max(1, a['ttp'] + a['tfp']):.3f} recall {a['ttp'] / max(1, a['n']):.3f}; pseudo-MOT "
              f"MOTA {_summed(a['mot']).mota:.3f} IDF1 {_summed(a['mot']).idf1:.3f}, centre rule MOTA "
              f"{_summed(a['mot_pt']).mota:.3f} IDF1 {_summed(a['mot_pt']).idf1:.3f}; moving at some time: detections "
              f"precision {a['etp'] / max(1, a['etp'] + a['efp']):.3f} recall {a['etp'] / max(1, a['en']):.3f}")
    return 0


def _summed(counts):
    """The sequences' MOT counts summed: the pooled MOTA and IDF1 come from sums, never an average of scores."""
    from dataclasses import fields

    return MOTCounts(*(sum(getattr(c, f.name) for c in counts) for f in fields(MOTCounts)))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", nargs="+", default=list(SCENES), help="preset names or YAML paths")
    ap.add_argument("--pipeline", nargs="+", default=sorted(PIPELINES), choices=sorted(PIPELINES))
    ap.add_argument("--frames", type=int, default=None, help="image.n_frames override")
    ap.add_argument("--seed", type=int, default=None, help="seed override")
    ap.add_argument("--gate", type=float, default=20.0, help="MOT correspondence gate, px")
    ap.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                    help="pipeline override, e.g. detection.close_px=3 or tracking.multi.gate_px=15")
    ap.add_argument("--breakdown", action="store_true",
                    help="synthetic: print each pipeline's misses per vehicle and cause, and false positives per "
                         "track")
    ap.add_argument("--kit-ais", action="store_true", help="score on the KIT AIS frames instead")
    ap.add_argument("--kit-dir", default=str(KIT_DIR))
    ap.add_argument("--kit-link-px", type=float, default=60.0, help="box chaining radius, px (ground-fixed)")
    ap.add_argument("--kit-move-px", type=float, default=8.0,
                    help="median step of a chain above which it moves, px/frame (label jitter: 1-4 px)")
    args = ap.parse_args(argv)
    return kit_ais(args) if args.kit_ais else synthetic(args)


if __name__ == "__main__":
    raise SystemExit(main())
