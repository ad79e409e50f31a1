"""Multi-object tracking scores from summed counts: CLEAR-MOT (MOTA, MOTP), identity (IDF1), HOTA.

A vehicle and a track correspond by the box-aware rules of :mod:`harness.metrics.matching`:
where the truth has a box, IoU >= 0.5 for a track that carries a box and the point inside
the box for a point track; the distance gate (``gate_px``, 20 px) where the truth has none.

What is truth, :mod:`harness.metrics.objects`: the objects are the visible vehicles that
move (``moving``, else ``parked`` == 0; a vehicle class; every row of real footage
without those columns); a track on a parked car is a false positive. Pedestrians,
cyclists and real footage's ignore regions are distractors (MOT16): an estimate on one
is removed from that frame before any count, and a distractor is never a miss.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

from harness.metrics.matching import correspondence
from harness.metrics.registry import _row, register_metric
from harness.metrics.matching import _linear_sum_assignment
from harness.metrics.trajectories import _mot_frames, _points_by_frame, by_tracker

_OBJ = (" (objects: visible vehicles that move, by `moving`, else `parked` == 0, any speed; parked cars are "
        "not objects; pedestrians, cyclists and ignore regions are distractors: a track on one is dropped)")
_MOT = "per sequence and tracker, from summed counts (never an average of per-sequence scores)"
register_metric("mota", "ratio", higher_is_better=True, weighting=_MOT + "; 1 - (FN + FP + IDSW) / objects",
                reduce="complement", description="CLEAR-MOT accuracy 1 - (misses + false positives + ID switches) "
                "/ counted vehicle-frames (Bernardin 2008)" + _OBJ + "; a track matches a boxed vehicle at IoU >= "
                "0.5 (boxed tracks) or with its point inside the box (point tracks), an unboxed one within the 20 px "
                "gate")
register_metric("motp", "px", higher_is_better=False, weighting=_MOT + "; per matched vehicle-frame",
                description="CLEAR-MOT precision: mean centre distance of matched track-vehicle pairs (Bernardin 2008), "
                "whichever rule matched them")
register_metric("idf1", "ratio", higher_is_better=True, weighting=_MOT + "; 2 IDTP / (objects + predictions)",
                description="identity F1: share of vehicle-frames and track-frames on the best one-to-one "
                "vehicle-track assignment (Ristani 2016); a pair counts where it matches by mota's rule (IoU, "
                "point in box, or the gate)")
register_metric("mot_misses", "count", higher_is_better=False, weighting=_MOT, reduce="total",
                description="CLEAR-MOT misses (FN): counted vehicle-frames no track matches (mota's rule)" + _OBJ)
register_metric("mot_false_positives", "count", higher_is_better=False, weighting=_MOT, reduce="total",
                description="CLEAR-MOT false positives (FP): track-frames matched to no counted vehicle (one on a "
                "parked car is one; one on a distractor is removed)")


@dataclass(frozen=True)
class MOTCounts:
    """Summed CLEAR-MOT and identity counts of one tracker on one sequence (or summed over many).

    objects: counted vehicle-frames (GT); predictions: estimated track-frames;
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


def mot_counts(est: pd.DataFrame, truth: pd.DataFrame, *, gate_px: float = 20.0,
               ignore: pd.DataFrame | None = None) -> MOTCounts:
    """CLEAR-MOT (Bernardin and Stiefelhagen 2008) and identity (Ristani et al. 2016) counts.

    Parameters
    ----------
    est : DataFrame
        One tracker's rows (``frame, track_id, x_filt_px, y_filt_px``); rows with
        a NaN position are not predictions.
    truth : DataFrame
        tracks.csv (``frame, vehicle_id, x_px, y_px, visible``, optional ``class``, ``parked``,
        ``moving``); the objects are its counted rows, estimates on its pedestrians and
        cyclists are removed (:mod:`harness.metrics.objects`).
        With ``bbox_x0_px .. bbox_y1_px`` on either side, the box-aware rules apply
        (:mod:`harness.metrics.matching`).
    gate_px : float
        A vehicle without a box and a track correspond only within this distance.
        The same rules decide both the frame matching and the identity matching.
    ignore : DataFrame or None
        ignore.csv of real footage (``frame, bbox_x0_px .. bbox_y1_px``): distractors too.

    The identity assignment pairs each vehicle with at most one track over the
    whole sequence so as to maximise IDTP, the number of frames where the pair
    is present and may correspond (equivalently, to minimise IDFN + IDFP);
    IDFN = objects - IDTP and IDFP = predictions - IDTP.
    """
    objects = predictions = matches = switches = 0
    dist_sum = 0.0
    overlap: dict[tuple[int, int], int] = {}
    for _f, vids, tids, D, match, switch, ok in _mot_frames(est, truth, gate_px=gate_px, ignore=ignore):
        objects += len(vids)
        predictions += len(tids)
        matches += len(match)
        switches += sum(switch.values())
        dist_sum += float(sum(D[a, b] for a, b in match.items()))
        for a, b in zip(*np.nonzero(ok)):
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


def mot_rows(est_tracks: pd.DataFrame, truth_tracks: pd.DataFrame, *, gate_px: float = 20.0,
             ignore: pd.DataFrame | None = None, trackers=()) -> list[dict]:
    """MOTA, MOTP, IDF1 and the FN / FP counts per tracker (``region`` = ``source``), as summable totals.

    One row per metric and tracker, no frame or track id. Each carries the
    counts its aggregate is recomputed from (:class:`MOTCounts`): ``mota`` sum =
    FN + FP + IDSW, count = objects (value 1 - sum / count, reduce
    ``complement``); ``motp`` sum = matched distances, count = matches; ``idf1``
    sum = 2 IDTP, count = objects + predictions; ``mot_misses``,
    ``mot_false_positives`` totals. Summed over cells or seeds these give the
    pooled scores, as py-motmetrics' overall row does. ``trackers``: the sources
    the pipeline ran (:func:`~harness.metrics.trajectories.by_tracker`).
    """
    rows: list[dict] = []
    for source, est in by_tracker(est_tracks, trackers):
        c = mot_counts(est, truth_tracks, gate_px=gate_px, ignore=ignore)
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


def hota_counts(est: pd.DataFrame, truth: pd.DataFrame, *, gate_px: float = 20.0,
                ignore: pd.DataFrame | None = None) -> HOTACounts:
    """HOTA totals (Luiten et al. 2021) of one tracker's points against the counted vehicles.

    Objects and distractors as :func:`mot_counts` (:mod:`harness.metrics.objects`).

    Similarity of a vehicle and a track in a frame (HOTA is defined for any similarity
    in [0, 1]), by :func:`harness.metrics.matching.correspondence`: the IoU of a boxed
    track and a boxed vehicle (the paper's); for a point track on a boxed vehicle
    ``max(0, 1 - n)``, n the point's offset from the box centre in half-extents (0 on the
    border); for a vehicle without a box ``S = max(0, 1 - d / gate_px)`` with d the
    distance of the true centre ``x_px, y_px`` and the estimate ``x_filt_px, y_filt_px``
    (a ramp that reaches 0 at the CLEAR-MOT gate).
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

    Parameters and row conventions as :func:`mot_counts`; the rows are :func:`hota_rows`.
    """
    if not gate_px > 0:
        raise ValueError(f"gate_px: expected > 0, got {gate_px}")
    by_frame = list(_points_by_frame(est, truth, boxes=True, ignore=ignore, gate_px=gate_px))
    vids = np.unique(np.concatenate([f[1] for f in by_frame] + [np.zeros(0, np.int64)]))
    tids = np.unique(np.concatenate([f[3] for f in by_frame] + [np.zeros(0, np.int64)]))
    na = len(HOTA_ALPHAS)
    tp, fn, fp = np.zeros(na), np.zeros(na), np.zeros(na)
    loc = np.zeros(na)
    frames = []
    for _f, v, P, t, Q, TB, EB in by_frame:
        a, b = np.searchsorted(vids, v), np.searchsorted(tids, t)
        frames.append((a, b, correspondence(P, TB, Q, EB, gate_px=gate_px)[3]))
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


# per-alpha totals of each HOTA row: (numerator, denominator) -> per-alpha score, and whether an alpha
# whose denominator is 0 counts as 0 (TrackEval's max(1, den)) or is left out of the mean
_ALPHA_RULES = {
    "hota": ("ass_sum", ("tp", "fn", "fp"), True, True),   # sqrt(ass_sum / (TP + FN + FP)) = sqrt(DetA AssA)
    "deta": ("tp", ("tp", "fn", "fp"), False, True),
    "assa": ("ass_sum", ("tp",), False, True),
    "loca": ("loc_sum", ("tp",), False, False),
}
_HOTA_W = ("per sequence and tracker, from the per-alpha counts summed over sequences, then the mean over the "
           "19 alphas 0.05..0.95 (Luiten 2021, eq. 12)")
_HOTA_MATCH = ("; similarity IoU (boxed track on a boxed vehicle), 1 - the point's offset from the box centre in "
               "half-extents (point track), or 1 - d / 20 px (vehicle without a box)")
register_metric("hota", "ratio", higher_is_better=True, weighting=_HOTA_W, reduce="alpha_mean",
                description="HOTA, sqrt(DetA AssA) averaged over the localisation thresholds (Luiten 2021)"
                + _HOTA_MATCH + "; objects and distractors as mota")
register_metric("deta", "ratio", higher_is_better=True, weighting=_HOTA_W, reduce="alpha_mean",
                description="HOTA detection accuracy TP / (TP + FN + FP), mean over alphas (Luiten 2021)")
register_metric("assa", "ratio", higher_is_better=True, weighting=_HOTA_W + "; each alpha TP-weighted",
                reduce="alpha_mean", description="HOTA association accuracy: mean over true positives of "
                "|TPA| / (|TPA| + |FNA| + |FPA|), mean over alphas (Luiten 2021); 0 at an alpha without TP")
register_metric("loca", "ratio", higher_is_better=True, weighting=_HOTA_W + "; each alpha TP-weighted",
                reduce="alpha_mean", description="HOTA localisation accuracy: mean similarity of the true "
                "positives, mean over the alphas that have any (TrackEval counts the others as 1)")


def alpha_mean_value(metric: str, num: np.ndarray, den: np.ndarray) -> float:
    """The value of a HOTA metric (``hota``, ``deta``, ``assa``, ``loca``) from its summed per-alpha totals.

    ``num``, ``den`` (19,) float: see :func:`hota_rows`. The mean over alphas of ``num / den``
    (its square root for ``hota``); an alpha with ``den`` 0 counts as 0 (TrackEval's
    convention), except for ``loca``, which leaves it out. NaN when every ``den`` is 0.
    """
    _, _, root, zero = _ALPHA_RULES[metric]
    num, den = np.asarray(num, np.float64), np.asarray(den, np.float64)
    if not (den > 0).any():
        return math.nan
    r = np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)
    if root:
        r = np.sqrt(r)
    return float(r.mean() if zero else r[den > 0].mean())


def hota_rows(est_tracks: pd.DataFrame, truth_tracks: pd.DataFrame, *, gate_px: float = 20.0,
              ignore: pd.DataFrame | None = None, trackers=()) -> list[dict]:
    """HOTA, DetA, AssA and LocA per tracker (``region`` = ``source``, motion "track"), poolable.

    One row per metric and tracker. HOTA is a mean over 19 alphas of per-alpha ratios, so a
    row's totals are the per-alpha numerators and denominators (:class:`HOTACounts`: HOTA
    and DetA over TP + FN + FP, AssA over TP with ``ass_sum``, LocA over TP with
    ``loc_sum``), stored in ``hist`` (:func:`harness.metrics.histogram.encode_alpha_totals`);
    :func:`harness.metrics.aggregate` sums them and takes :func:`alpha_mean_value`. ``sum``
    is NaN, ``count`` the counted vehicle-frames. ``trackers`` as :func:`mot_rows`.
    """
    from harness.metrics.histogram import encode_alpha_totals

    rows: list[dict] = []
    for source, est in by_tracker(est_tracks, trackers):
        c = hota_counts(est, truth_tracks, gate_px=gate_px, ignore=ignore)
        objects = float(c.tp[0] + c.fn[0])
        for metric, (num_name, den_names, _, _) in _ALPHA_RULES.items():
            num = getattr(c, num_name)
            den = sum(getattr(c, n) for n in den_names)
            rows.append(_row(metric, alpha_mean_value(metric, num, den), math.nan, objects, region=str(source),
                             motion="track", hist=encode_alpha_totals(num, den)))
    return rows
