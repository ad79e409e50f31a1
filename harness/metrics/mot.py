"""Multi-object tracking scores from summed counts: CLEAR-MOT (MOTA, MOTP), identity (IDF1), HOTA."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

from harness.metrics.registry import _row, register_metric
from harness.metrics.trajectories import _linear_sum_assignment, _mot_frames, _points_by_frame, position_error_px

_MOT = "per sequence and tracker, from summed counts (never an average of per-sequence scores)"
register_metric("mota", "ratio", higher_is_better=True, weighting=_MOT + "; 1 - (FN + FP + IDSW) / objects",
                reduce="complement", description="CLEAR-MOT accuracy 1 - (misses + false positives + ID switches) "
                "/ visible vehicle-frames (Bernardin 2008), match within the association gate")
register_metric("motp", "px", higher_is_better=False, weighting=_MOT + "; per matched vehicle-frame",
                description="CLEAR-MOT precision: mean distance of matched track-vehicle pairs (Bernardin 2008)")
register_metric("idf1", "ratio", higher_is_better=True, weighting=_MOT + "; 2 IDTP / (objects + predictions)",
                description="identity F1: share of vehicle-frames and track-frames on the best one-to-one "
                "vehicle-track assignment (Ristani 2016)")
register_metric("mot_misses", "count", higher_is_better=False, weighting=_MOT, reduce="total",
                description="CLEAR-MOT misses (FN): visible vehicle-frames without a track within the gate")
register_metric("mot_false_positives", "count", higher_is_better=False, weighting=_MOT, reduce="total",
                description="CLEAR-MOT false positives (FP): track-frames matched to no vehicle")


@dataclass(frozen=True)
class MOTCounts:
    """Summed CLEAR-MOT and identity counts of one tracker on one sequence (or summed over many).

    objects: visible vehicle-frames (GT); predictions: estimated track-frames;
    matches: corresponding pairs, switches included (py-motmetrics' num_detections); misses (FN), false_positives (FP), switches (IDSW); dist_sum_px: sum
    of the matched distances; idtp, idfn, idfp: identity true positives, false
    negatives, false positives of the best one-to-one vehicle-track assignment
    over the whole sequence (Ristani et al. 2016).
    """

    objects: int
    predictions: int
    matches: int
    misses: int
    false_positives: int
    switches: int
    dist_sum_px: float
    idtp: int
    idfn: int
    idfp: int

    @property
    def mota(self) -> float:
        """MOTA = 1 - (FN + FP + IDSW) / GT (Bernardin 2008, eq. 2); NaN without objects."""
        return 1.0 - (self.misses + self.false_positives + self.switches) / self.objects if self.objects else math.nan

    @property
    def motp_px(self) -> float:
        """MOTP = sum of matched distances / matches (Bernardin 2008, eq. 1), px; NaN without matches."""
        return self.dist_sum_px / self.matches if self.matches else math.nan

    @property
    def idf1(self) -> float:
        """IDF1 = 2 IDTP / (2 IDTP + IDFP + IDFN) (Ristani 2016, eq. 7); NaN when both sides are empty."""
        den = 2 * self.idtp + self.idfp + self.idfn
        return 2 * self.idtp / den if den else math.nan


def mot_counts(est: pd.DataFrame, truth: pd.DataFrame, *, gate_px: float = 20.0) -> MOTCounts:
    """CLEAR-MOT (Bernardin and Stiefelhagen 2008) and identity (Ristani et al. 2016) counts.

    Parameters
    ----------
    est : DataFrame
        One tracker's rows (``frame, track_id, x_filt_px, y_filt_px``); rows with
        a NaN position are not predictions.
    truth : DataFrame
        tracks.csv (``frame, vehicle_id, x_px, y_px, visible``); visible rows are objects.
    gate_px : float
        A vehicle and a track correspond only within this distance (the
        threshold of both the frame matching and the identity matching).

    The identity assignment pairs each vehicle with at most one track over the
    whole sequence so as to maximise IDTP, the number of frames where the pair
    is present and within the gate (equivalently, to minimise IDFN + IDFP);
    IDFN = objects - IDTP and IDFP = predictions - IDTP.
    """
    objects = predictions = matches = switches = 0
    dist_sum = 0.0
    overlap: dict[tuple[int, int], int] = {}
    for _f, vids, tids, D, match, switch in _mot_frames(est, truth, gate_px=gate_px):
        objects += len(vids)
        predictions += len(tids)
        matches += len(match)
        switches += sum(switch.values())
        dist_sum += float(sum(D[a, b] for a, b in match.items()))
        for a, b in zip(*np.nonzero(D <= gate_px)):
            key = (int(vids[a]), int(tids[b]))
            overlap[key] = overlap.get(key, 0) + 1
    idtp = 0
    if overlap:
        vs = sorted({k[0] for k in overlap})
        ts = sorted({k[1] for k in overlap})
        W = np.zeros((len(vs), len(ts)))
        for (v, t), n in overlap.items():
            W[vs.index(v), ts.index(t)] = n
        ia, ib = _linear_sum_assignment(-W)
        idtp = int(W[ia, ib].sum())
    return MOTCounts(objects=objects, predictions=predictions, matches=matches, misses=objects - matches,
                     false_positives=predictions - matches, switches=switches, dist_sum_px=dist_sum,
                     idtp=idtp, idfn=objects - idtp, idfp=predictions - idtp)


def mot_rows(est_tracks: pd.DataFrame, truth_tracks: pd.DataFrame, *, gate_px: float = 20.0) -> list[dict]:
    """MOTA, MOTP, IDF1 and the FN / FP counts per tracker (``region`` = ``source``), as summable totals.

    One row per metric and tracker, no frame or track id. Each carries the
    counts its aggregate is recomputed from (:class:`MOTCounts`): ``mota`` sum =
    FN + FP + IDSW, count = objects (value 1 - sum / count, reduce
    ``complement``); ``motp`` sum = matched distances, count = matches; ``idf1``
    sum = 2 IDTP, count = objects + predictions; ``mot_misses``,
    ``mot_false_positives`` totals. Summed over cells or seeds these give the
    pooled scores, as py-motmetrics' overall row does.
    """
    rows: list[dict] = []
    if est_tracks is None or est_tracks.empty:
        return rows
    for source, est in est_tracks.groupby("source"):
        c = mot_counts(est, truth_tracks, gate_px=gate_px)
        kw = {"region": str(source), "motion": "track"}
        errors = c.misses + c.false_positives + c.switches
        rows += [
            _row("mota", c.mota, errors, c.objects, **kw),
            _row("motp", c.motp_px, c.dist_sum_px, c.matches, **kw),
            _row("idf1", c.idf1, 2 * c.idtp, c.objects + c.predictions, **kw),
            _row("mot_misses", c.misses, c.misses, c.objects, **kw),
            _row("mot_false_positives", c.false_positives, c.false_positives, c.predictions, **kw),
        ]
    return rows


# HOTA's localisation thresholds alpha = 0.05, 0.10, ..., 0.95 (Luiten et al. 2021, sec. 5)
HOTA_ALPHAS = np.round(np.arange(1, 20) * 0.05, 2)


@dataclass(frozen=True)
class HOTACounts:
    """HOTA totals of one tracker on one sequence, per alpha (Luiten et al. 2021); ``+`` pools sequences.

    Arrays of shape (19,), one entry per alpha in :data:`HOTA_ALPHAS`: ``tp``, ``fn``,
    ``fp`` (detection true positives, misses, false positives at that alpha),
    ``ass_sum`` (sum over the true positives c of the association score
    A(c) = |TPA(c)| / (|TPA(c)| + |FNA(c)| + |FPA(c)|), eq. 9), ``loc_sum`` (sum
    of their similarities). Every score is a ratio of such sums, so pooling
    sequences is adding their counts (TrackEval sums TP, FN, FP and weights AssA
    and LocA by TP, which is the same):

        DetA = TP / (TP + FN + FP)                              (eq. 4)
        AssA = ass_sum / TP                                     (eq. 10)
        HOTA_alpha = sqrt(DetA AssA) = sqrt(ass_sum / (TP + FN + FP))
        HOTA = mean over alpha of HOTA_alpha                    (eq. 12)

    HOTA_alpha is one sum / count pair (reduce ``rms``); HOTA, a mean of 19
    square roots, is not: it needs the 19 pairs.
    """

    tp: np.ndarray
    fn: np.ndarray
    fp: np.ndarray
    ass_sum: np.ndarray
    loc_sum: np.ndarray

    def __add__(self, other: "HOTACounts") -> "HOTACounts":
        return HOTACounts(*(getattr(self, k) + getattr(other, k) for k in ("tp", "fn", "fp", "ass_sum", "loc_sum")))

    def _ratio(self, num: np.ndarray, den: np.ndarray) -> np.ndarray:
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(den > 0, num / np.where(den > 0, den, 1), np.nan)

    @property
    def deta(self) -> np.ndarray:
        """DetA per alpha; NaN where there is nothing to detect or predict."""
        return self._ratio(self.tp, self.tp + self.fn + self.fp)

    @property
    def assa(self) -> np.ndarray:
        """AssA per alpha; NaN without true positives."""
        return self._ratio(self.ass_sum, self.tp)

    @property
    def loca(self) -> np.ndarray:
        """LocA per alpha: mean similarity of the true positives; NaN without them."""
        return self._ratio(self.loc_sum, self.tp)

    @property
    def hota_alpha(self) -> np.ndarray:
        """HOTA per alpha, sqrt(DetA AssA) (0 where there are objects but no true positive)."""
        return np.sqrt(self._ratio(self.ass_sum, self.tp + self.fn + self.fp))

    @property
    def hota(self) -> float:
        """HOTA: the mean of HOTA_alpha over the 19 alphas (eq. 12)."""
        return float(np.mean(self.hota_alpha))


def hota_counts(est: pd.DataFrame, truth: pd.DataFrame, *, gate_px: float = 20.0) -> HOTACounts:
    """HOTA totals (Luiten et al. 2021) of one tracker's points against the visible vehicles.

    Similarity of a vehicle and a track in a frame: ``S = max(0, 1 - d / gate_px)``
    with d the distance of the true centre ``x_px, y_px`` and the estimate
    ``x_filt_px, y_filt_px`` (HOTA is defined for any similarity in [0, 1]; boxes
    use IoU, points here a distance ramp that reaches 0 at the CLEAR-MOT gate).
    Matching as TrackEval does it: per frame one Hungarian assignment
    maximising ``global_alignment(vehicle, track) * S``, where the global
    alignment score is the pair's soft overlap over the sequence,
    ``sum_t S~ / (n_vehicle + n_track - sum_t S~)`` with ``S~ = S / (row sum +
    column sum - S)`` of the frame's similarity matrix; at each alpha a matched
    pair with ``S >= alpha`` is a true positive. A(c) of a true positive of the
    pair (vehicle, track) is ``n_matched / (n_vehicle + n_track - n_matched)``,
    the counts over the sequence at that alpha.

    Two differences from TrackEval's ``hota.py``, both at edges: the alphas are
    exact (its ``np.arange(0.05, 0.99, 0.05)`` holds 0.30000000000000004 and the
    like, so a similarity equal to such an alpha fails there), and a sequence
    with neither vehicles nor tracks gives NaN, not 0 (as MOTA does here).

    Parameters and row conventions as :func:`mot_counts`. Not yet a results-table
    row: HOTA_alpha is one sum / count pair (``ass_sum``, ``tp + fn + fp``, reduce
    ``rms``), but HOTA itself needs all 19 after pooling.
    """
    if not gate_px > 0:
        raise ValueError(f"gate_px: expected > 0, got {gate_px}")
    by_frame = list(_points_by_frame(est, truth))
    vids = np.unique(np.concatenate([v for _, v, _, _, _ in by_frame] + [np.zeros(0, np.int64)]))
    tids = np.unique(np.concatenate([t for _, _, _, t, _ in by_frame] + [np.zeros(0, np.int64)]))
    na = len(HOTA_ALPHAS)
    tp, fn, fp = np.zeros(na), np.zeros(na), np.zeros(na)
    loc = np.zeros(na)
    frames = []
    for _f, v, P, t, Q in by_frame:
        a, b = np.searchsorted(vids, v), np.searchsorted(tids, t)
        D = position_error_px(P[:, None, 0], P[:, None, 1], Q[None, :, 0], Q[None, :, 1]).reshape(len(P), len(Q))
        frames.append((a, b, np.maximum(0.0, 1.0 - D / gate_px)))
    # pass 1: global alignment score of every (vehicle, track) pair
    n_v, n_t = np.zeros(len(vids)), np.zeros(len(tids))
    soft = np.zeros((len(vids), len(tids)))
    for a, b, S in frames:
        n_v[a] += 1
        n_t[b] += 1
        den = S.sum(axis=0)[None, :] + S.sum(axis=1)[:, None] - S
        soft[np.ix_(a, b)] += np.where(den > 0, S / np.where(den > 0, den, 1), 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        align = soft / (n_v[:, None] + n_t[None, :] - soft)
    # pass 2: per frame one assignment, thresholded at each alpha
    matched = np.zeros((na, len(vids), len(tids)))
    for a, b, S in frames:
        if len(a) == 0 or len(b) == 0:
            fn += len(a)
            fp += len(b)
            continue
        ra, rb = _linear_sum_assignment(-(align[np.ix_(a, b)] * S))
        s = S[ra, rb]
        for k, alpha in enumerate(HOTA_ALPHAS):
            ok = s >= alpha - 1e-10
            tp[k] += ok.sum()
            fn[k] += len(a) - ok.sum()
            fp[k] += len(b) - ok.sum()
            loc[k] += s[ok].sum()
            np.add.at(matched[k], (a[ra[ok]], b[rb[ok]]), 1)
    # sum over true positives of A(c) = sum over pairs of n_matched * n_matched / (n_v + n_t - n_matched)
    union = n_v[None, :, None] + n_t[None, None, :] - matched
    ass = (matched * np.where(union > 0, matched / np.where(union > 0, union, 1), 0.0)).sum(axis=(1, 2))
    return HOTACounts(tp=tp, fn=fn, fp=fp, ass_sum=ass, loc_sum=loc)
