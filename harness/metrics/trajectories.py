"""Trajectories: a track's position error, the frame-by-frame CLEAR-MOT association, per-vehicle rows."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from harness.metrics.matching import _linear_sum_assignment, boxes_of, correspondence
from harness.metrics.objects import counted_objects, distractor_table, keep_estimates
from harness.metrics.registry import _row, register_metric


_TRK = "per counted vehicle (visible and moving, as for mota) and frame where tracked, pooled"
register_metric("track_error", "px", higher_is_better=False, weighting=_TRK,
                description="|filtered track position - true vehicle centre|")
register_metric("track_raw_error", "px", higher_is_better=False, weighting=_TRK,
                description="|measured (unfiltered) track position - true vehicle centre|")
register_metric("track_pred_error", "px", higher_is_better=False, weighting=_TRK,
                description="|one-step Kalman prediction for the frame - true vehicle centre|")
register_metric("track_ate_rmse", "px", higher_is_better=False, weighting=_TRK + " (RMS)", reduce="rms",
                description="absolute trajectory error: RMS of filtered position error")
register_metric("track_fde", "px", higher_is_better=False, weighting="per counted vehicle, mean over vehicles",
                description="final displacement error: filtered position error on the last tracked frame")
register_metric("track_completeness", "%", higher_is_better=True,
                weighting="per counted vehicle-frame, pooled", reduce="rate",
                description="share of frames where a counted vehicle (visible, moving: no parked car, pedestrian "
                "or cyclist) has a track assigned")
register_metric("id_switches", "count", higher_is_better=False, weighting="summed over vehicles",
                reduce="total", description="identity switches of the multi-target tracker (CLEAR-MOT), per counted "
                "vehicle")


def position_error_px(x_est, y_est, x_true, y_true) -> np.ndarray:
    """Track position error ``|p_est - p_true|`` (Euclidean, px), elementwise, float64; NaN where either is NaN.

    The one definition of a trajectory's error used by every track metric (and
    by reports that show per-frame track errors).
    """
    return np.hypot(np.asarray(x_est, np.float64) - np.asarray(x_true, np.float64),
                    np.asarray(y_est, np.float64) - np.asarray(y_true, np.float64))


_ASSOC_COLUMNS = ["frame", "vehicle_id", "track_id", "dist_px", "switch"]


def _points_by_frame(est: pd.DataFrame, truth: pd.DataFrame, *, boxes: bool = False,
                     ignore: pd.DataFrame | None = None, gate_px: float = 20.0):
    """Per frame with a counted vehicle or a finite estimate, ascending: ``(frame, vehicle_ids, P, track_ids, Q)``.

    vehicle_ids (V,) int64 and P (V, 2) ``x_px, y_px`` of the counted rows of ``truth``
    (:func:`harness.metrics.objects.counted_objects`: visible vehicles that move);
    track_ids (T,) int64 and Q (T, 2) ``x_filt_px, y_filt_px`` of the rows of ``est`` with a
    finite position that do not fall on a distractor (a pedestrian or cyclist of ``truth``,
    a row of ``ignore``: :func:`harness.metrics.objects.keep_estimates`, by the rules of
    :func:`harness.metrics.matching.correspondence` with ``gate_px``); each in table order
    (as ``groupby("frame")`` gives them), from numpy arrays taken once (a per-frame
    DataFrame selection costs ~1 ms each). With ``boxes`` each tuple also carries the
    true boxes (V, 4) and the estimated boxes (T, 4) (``bbox_x0_px .. bbox_y1_px``; NaN
    where a side has none): ``(frame, vehicle_ids, P, track_ids, Q, true_boxes, est_boxes)``.
    """
    vis = counted_objects(truth)
    vf = truth["frame"].to_numpy()[vis]
    vv = truth["vehicle_id"].to_numpy(np.int64)[vis]
    vp = np.stack([truth["x_px"].to_numpy(np.float64)[vis], truth["y_px"].to_numpy(np.float64)[vis]], 1)
    ex, ey = est["x_filt_px"].to_numpy(np.float64), est["y_filt_px"].to_numpy(np.float64)
    ok = np.isfinite(ex) & np.isfinite(ey)
    ef = est["frame"].to_numpy()[ok]
    et = est["track_id"].to_numpy(np.int64)[ok]
    eq = np.stack([ex[ok], ey[ok]], 1)
    vb, eb = boxes_of(truth, vis), boxes_of(est, ok)
    dist = distractor_table(truth, ignore)
    df_ = dist["frame"].to_numpy(np.int64)
    dp, db, dr = dist[["x_px", "y_px"]].to_numpy(np.float64), boxes_of(dist), dist["region"].to_numpy(bool)
    ov, oe, od = (np.argsort(x, kind="stable") for x in (vf, ef, df_))
    vf_s, ef_s, df_s = vf[ov], ef[oe], df_[od]
    for f in np.union1d(vf, ef):
        iv = ov[np.searchsorted(vf_s, f, "left"):np.searchsorted(vf_s, f, "right")]
        ie = oe[np.searchsorted(ef_s, f, "left"):np.searchsorted(ef_s, f, "right")]
        idd = od[np.searchsorted(df_s, f, "left"):np.searchsorted(df_s, f, "right")]
        if len(idd) and len(ie):
            ie = ie[keep_estimates(vp[iv], vb[iv], eq[ie], eb[ie], dp[idd], db[idd], dr[idd], gate_px=gate_px)]
        if boxes:
            yield f, vv[iv], vp[iv], et[ie], eq[ie], vb[iv], eb[ie]
        else:
            yield f, vv[iv], vp[iv], et[ie], eq[ie]


def _mot_frames(est: pd.DataFrame, truth: pd.DataFrame, *, gate_px: float, ignore: pd.DataFrame | None = None):
    """Frame by frame CLEAR-MOT correspondences (Bernardin and Stiefelhagen 2008, sec. 2.1.1).

    Yields ``(frame, vehicle_ids, track_ids, D, match, switch, feasible)`` for every frame
    that has a counted vehicle or a finite estimate (after distractor removal, see
    :func:`_points_by_frame`; ``ignore``: ignore.csv rows or None): ``D`` (V, T) Euclidean distances
    between true centres ``x_px, y_px`` and filtered estimates ``x_filt_px, y_filt_px``;
    ``feasible`` (V, T) where a pair may correspond, by the box-aware rules of
    :func:`harness.metrics.matching.correspondence` (IoU >= 0.5 for a boxed track on a
    boxed vehicle, the point inside the box for a point track, ``gate_px`` for a vehicle
    without a box); ``match`` maps row -> column. A vehicle's last correspondence (of
    any earlier frame) is kept while the same track is present and feasible; the rest
    are matched by the Hungarian method on the rules' cost. ``switch`` flags: the
    vehicle's track differs from its last matched track.
    """
    if not gate_px > 0:
        raise ValueError(f"gate_px: expected > 0, got {gate_px}")
    last: dict[int, int] = {}   # vehicle -> last matched track ever (Bernardin's M_{t-1}, carried on)
    for f, vids, P, tids, Q, TB, EB in _points_by_frame(est, truth, boxes=True, ignore=ignore, gate_px=gate_px):
        D, ok, C, _ = correspondence(P, TB, Q, EB, gate_px=gate_px)
        match: dict[int, int] = {}
        switch: dict[int, bool] = {}
        for a, vid in enumerate(vids):
            t = last.get(int(vid))
            if t is not None and t in tids:
                b = int(np.flatnonzero(tids == t)[0])
                if ok[a, b] and b not in match.values():
                    match[a], switch[a] = b, False
        ra = [a for a in range(len(vids)) if a not in match]
        rb = [b for b in range(len(tids)) if b not in match.values()]
        if ra and rb:
            sub, sub_ok = C[np.ix_(ra, rb)], ok[np.ix_(ra, rb)]
            big = 1e6 * (1.0 + float(np.max(sub, initial=0.0, where=sub_ok)))
            ia, ib = _linear_sum_assignment(np.where(sub_ok, sub, big))
            for x, y in zip(ia, ib):
                if sub_ok[x, y]:
                    a, b = ra[x], rb[y]
                    match[a] = b
                    switch[a] = int(vids[a]) in last and last[int(vids[a])] != int(tids[b])
        for a, b in match.items():
            last[int(vids[a])] = int(tids[b])
        yield f, vids, tids, D, match, switch, ok


def associate_tracks(est: pd.DataFrame, truth: pd.DataFrame, *, gate_px: float = 20.0,
                     ignore: pd.DataFrame | None = None) -> pd.DataFrame:
    """Match estimated tracks to the counted vehicles frame by frame (CLEAR-MOT, Bernardin 2008).

    Counted vehicles and distractors (``truth``'s pedestrians and cyclists, ``ignore``'s
    rows) as :mod:`harness.metrics.objects` says.

    In each frame a vehicle's last correspondence is kept while that track is
    present and may still correspond; the remaining tracks and vehicles are
    matched by the Hungarian method on the cost of
    :func:`harness.metrics.matching.correspondence`, pairs that may not correspond
    rejected (the rules of py-motmetrics' ``MOTAccumulator``). Where the truth has a
    box (``bbox_*_px``) a boxed track corresponds at IoU >= 0.5 and a point track
    inside the box; elsewhere within ``gate_px`` of the centre. ``dist_px``:
    estimated ``x_filt_px, y_filt_px`` vs truth ``x_px, y_px``.

    Returns
    -------
    DataFrame with columns frame, vehicle_id, track_id, dist_px, switch (bool:
    the vehicle's track differs from its last matched track).
    """
    out = []
    for f, vids, tids, D, match, switch, _ in _mot_frames(est, truth, gate_px=gate_px, ignore=ignore):
        for a, b in sorted(match.items()):
            out.append({"frame": int(f), "vehicle_id": int(vids[a]), "track_id": int(tids[b]),
                        "dist_px": float(D[a, b]), "switch": bool(switch[a])})
    return pd.DataFrame(out, columns=_ASSOC_COLUMNS)


def by_tracker(est_tracks: pd.DataFrame | None, trackers=()) -> list[tuple[str, pd.DataFrame]]:
    """``(source, its rows)`` for every tracker in ``est_tracks`` and every one named in ``trackers`` (the trackers
    the pipeline ran), sorted: a tracker that ran and output nothing is scored on no rows (every counted vehicle a
    miss), so the metrics a cell gives do not depend on whether a track was confirmed."""
    est = est_tracks if est_tracks is not None else pd.DataFrame(columns=["source"])
    groups = dict(tuple(est.groupby("source"))) if len(est) else {}
    return [(str(s), groups[s] if s in groups else est.iloc[0:0]) for s in sorted(set(groups) | set(trackers))]


def track_rows(est_tracks: pd.DataFrame, truth_tracks: pd.DataFrame, *, gate_px: float = 20.0,
               ignore: pd.DataFrame | None = None, trackers=()) -> list[dict]:
    """Trajectory rows per counted vehicle; ``region`` is the tracker (``source``: "point" or "multi").

    Counted vehicles: :func:`harness.metrics.objects.counted_objects` (visible vehicles that
    move; parked cars, pedestrians and cyclists have no rows); ``ignore``: ignore.csv rows.

    Point-tracker rows map to vehicles by ``seed_vehicle_id``; multi-target rows
    through :func:`associate_tracks`. Errors count the frames where the vehicle
    is visible and a track is assigned; ``x_pred_px`` on frame t is the one-step
    prediction for frame t made from frame t-1. ``track_id`` of a row is the
    vehicle id; per-frame rows (track_error, track_raw_error, track_pred_error)
    carry the frame, per-vehicle rows (ate, fde, completeness, id_switches) not.
    ``trackers``: the sources the pipeline ran (:func:`by_tracker`).
    """
    counted = truth_tracks[counted_objects(truth_tracks)]
    vis_n = counted.groupby("vehicle_id").size()
    rows: list[dict] = []
    for source, est in by_tracker(est_tracks, trackers):
        if source == "point":
            m = est.dropna(subset=["seed_vehicle_id"]).copy()
            m["vehicle_id"] = m["seed_vehicle_id"].astype(np.int64)
            m = m[np.isfinite(m["x_filt_px"]) & np.isfinite(m["y_filt_px"])]
            switches = None
        else:
            assoc = associate_tracks(est, truth_tracks, gate_px=gate_px, ignore=ignore)
            m = assoc.merge(est, on=["frame", "track_id"], how="left")
            switches = assoc.groupby("vehicle_id")["switch"].sum()
        m = m.merge(counted[["frame", "vehicle_id", "x_px", "y_px"]],
                    on=["frame", "vehicle_id"], suffixes=("_est", "_true"))
        kw = {"region": str(source), "motion": "track"}
        for vid, g in m.sort_values("frame").groupby("vehicle_id"):
            vid = int(vid)
            xt, yt = g["x_px_true"].to_numpy(float), g["y_px_true"].to_numpy(float)
            err = position_error_px(g["x_filt_px"], g["y_filt_px"], xt, yt)
            raw = position_error_px(g["x_px_est"], g["y_px_est"], xt, yt)
            pred = position_error_px(g["x_pred_px"], g["y_pred_px"], xt, yt)
            for f, e1, e2, e3 in zip(g["frame"].to_numpy(), err, raw, pred):
                rows.append(_row("track_error", e1, e1, 1, frame=int(f), track_id=vid, **kw))
                if np.isfinite(e2):
                    rows.append(_row("track_raw_error", e2, e2, 1, frame=int(f), track_id=vid, **kw))
                if np.isfinite(e3):
                    rows.append(_row("track_pred_error", e3, e3, 1, frame=int(f), track_id=vid, **kw))
            sq = float((err ** 2).sum())
            rows.append(_row("track_ate_rmse", math.sqrt(sq / len(err)), sq, len(err), track_id=vid, **kw))
            rows.append(_row("track_fde", err[-1], err[-1], 1, track_id=vid, **kw))
        tracked = m.groupby("vehicle_id")["frame"].nunique()
        for vid, n in vis_n.items():
            k = int(tracked.get(vid, 0))
            rows.append(_row("track_completeness", 100.0 * k / n, k, n, track_id=int(vid), **kw))
            if switches is not None:
                s = int(switches.get(vid, 0))
                rows.append(_row("id_switches", s, s, 1, track_id=int(vid), **kw))
    return rows
