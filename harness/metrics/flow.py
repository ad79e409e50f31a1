"""Flow metrics: per-pixel errors, pixel regions, and the rows of one frame pair.

Regions of a flow field (see :func:`region_masks`): ``all`` (every valid
pixel), ``background`` (instance 0), ``vehicles`` (instance > 0), ``interior``
(valid pixels farther than ``boundary_px`` = 3 px, Chebyshev distance, from an
invalid pixel or an instance edge: occlusion boundaries excluded).

Motions: ``total`` scores ``flow_total`` against the ground-truth ``flow``;
``local`` scores ``flow_total - flow_global`` against ``flow - flow_camera``,
so a stabilisation error and a flow error can be told apart.

The pass over the pixels is numba (:mod:`harness._flow_kernels`, imported on first use).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import cv2
import numpy as np

from algorithms.flow import check_flow
from harness.metrics.histogram import HIST_BIN_PX, HIST_NBINS, encode_hist, epe_histogram, overflow_tail
from harness.metrics.registry import _row, register_metric, timing_rows

REGIONS = ("all", "background", "vehicles", "interior")
MOTIONS = ("total", "local")

_PIX = "per ground-truth-valid pixel (dense: the method's own valid mask does not exclude any), pooled over frames"
register_metric("epe_mean", "px", higher_is_better=False, weighting=_PIX,
                description="mean endpoint error |w_est - w_true|")
register_metric("epe_rms", "px", higher_is_better=False, weighting=_PIX, reduce="rms",
                description="root mean square endpoint error")
register_metric("epe_median", "px", higher_is_better=False, weighting=_PIX + " (summed 0.01 px histogram)",
                reduce="quantile", q=0.5, description="median endpoint error")
register_metric("epe_p95", "px", higher_is_better=False, weighting=_PIX + " (summed 0.01 px histogram)",
                reduce="quantile", q=0.95, description="95th percentile of the endpoint error")
register_metric("ae_mean", "deg", higher_is_better=False, weighting=_PIX,
                description="mean angular error between (u, v, 1) vectors (Barron 1994, Baker 2011)")
for _t in (1, 3, 5):
    register_metric(f"outlier_{_t}px", "%", higher_is_better=False, weighting=_PIX, reduce="rate",
                    description=f"share of pixels with endpoint error > {_t} px")
register_metric("fl_all", "%", higher_is_better=False, weighting=_PIX, reduce="rate",
                description="KITTI Fl: share of pixels with EPE > 3 px and > 5 % of the true magnitude")
register_metric("coverage", "%", higher_is_better=True, weighting="per ground-truth-valid pixel, pooled",
                reduce="rate", description="share of ground-truth-valid pixels the method marks valid "
                "(the flow errors still score every ground-truth-valid pixel)")


# --------------------------------------------------------------------------- per-pixel errors

# endpoint_error (per-pixel EPE) lives in algorithms.flow, its one home, re-exported by harness.metrics.


def angular_error_deg(flow_est: np.ndarray, flow_true: np.ndarray) -> np.ndarray:
    """Angular error between the 3-D vectors ``(u, v, 1)`` (Barron et al. 1994), ``(H, W)`` degrees.

    ``AE = arccos((u_e u_t + v_e v_t + 1) / sqrt((u_e^2 + v_e^2 + 1)(u_t^2 + v_t^2 + 1)))``
    """
    e = np.asarray(flow_est, np.float64)
    t = np.asarray(flow_true, np.float64)
    num = e[..., 0] * t[..., 0] + e[..., 1] * t[..., 1] + 1.0
    den = np.sqrt((e[..., 0] ** 2 + e[..., 1] ** 2 + 1.0) * (t[..., 0] ** 2 + t[..., 1] ** 2 + 1.0))
    return np.degrees(np.arccos(np.clip(num / den, -1.0, 1.0)))


def boundary_mask(valid: np.ndarray, instances: np.ndarray | None = None, *, boundary_px: int = 3) -> np.ndarray:
    """Pixels within ``boundary_px`` (Chebyshev distance) of an invalid pixel or an instance edge.

    An instance edge is a pixel whose instance id differs from one of its four
    neighbours (both sides of the edge are edge pixels). Returns ``(H, W)`` bool.
    """
    valid = np.asarray(valid, bool)
    bad = ~valid
    if instances is not None:
        ids = np.asarray(instances)
        if ids.shape != valid.shape:
            raise ValueError(f"instances: expected shape {valid.shape}, got {ids.shape}")
        edge = np.zeros_like(valid)
        dy = ids[1:, :] != ids[:-1, :]
        dx = ids[:, 1:] != ids[:, :-1]
        edge[1:, :] |= dy
        edge[:-1, :] |= dy
        edge[:, 1:] |= dx
        edge[:, :-1] |= dx
        bad = bad | edge
    if boundary_px <= 0:
        return bad
    kernel = np.ones((2 * boundary_px + 1, 2 * boundary_px + 1), np.uint8)
    return cv2.dilate(bad.astype(np.uint8), kernel, borderType=cv2.BORDER_CONSTANT, borderValue=0).astype(bool)


def region_masks(valid: np.ndarray, instances: np.ndarray | None = None, *, boundary_px: int = 3,
                 regions: Iterable[str] = REGIONS) -> dict[str, np.ndarray]:
    """The scored pixels of each region (see the module docstring), ``name -> (H, W) bool``.

    Without ``instances`` every pixel counts as background.
    """
    valid = np.asarray(valid, bool)
    out: dict[str, np.ndarray] = {}
    for r in regions:
        if r == "all":
            out[r] = valid
        elif r == "background":
            out[r] = valid if instances is None else valid & (np.asarray(instances) == 0)
        elif r == "vehicles":
            out[r] = np.zeros_like(valid) if instances is None else valid & (np.asarray(instances) > 0)
        elif r == "interior":
            out[r] = valid & ~boundary_mask(valid, instances, boundary_px=boundary_px)
        else:
            raise ValueError(f"unknown region {r!r}; valid: {', '.join(REGIONS)}")
    return out


def flow_rows(flow_est: np.ndarray, flow_true: np.ndarray, mask: np.ndarray, *, region: str = "all",
              motion: str = "total", frame: int | None = None) -> list[dict]:
    """The flow metrics of one field over the pixels of ``mask``.

    An empty mask gives rows with ``count`` 0 and NaN values (they add nothing
    to an aggregate). Fl follows KITTI: EPE > 3 px and EPE > 0.05 |w_true|.
    """
    m = np.asarray(mask, bool)
    e = np.asarray(flow_est, np.float64)[m]
    t = np.asarray(flow_true, np.float64)[m]
    return error_rows(np.hypot(e[:, 0] - t[:, 0], e[:, 1] - t[:, 1]), angular_error_deg(e, t),
                      np.hypot(t[:, 0], t[:, 1]), region=region, motion=motion, frame=frame)


def error_rows(epe: np.ndarray, ae_deg: np.ndarray, true_mag: np.ndarray, *, region: str = "all",
               motion: str = "total", frame: int | None = None) -> list[dict]:
    """The flow metric rows from per-pixel endpoint errors, angular errors and true magnitudes (1-D)."""
    n = int(epe.size)
    if n:
        # nearest-rank quantiles (the sample of rank ceil(q n)), as hist_quantile reads them
        k50, k95 = _rank_index(0.5, n), _rank_index(0.95, n)
        part = np.partition(epe, (k50, k95))
        med, p95 = float(part[k50]), float(part[k95])
    else:
        med = p95 = float("nan")
    over = [int(np.count_nonzero(epe > thr)) for thr in OUTLIER_PX]
    fl = int(np.count_nonzero((epe > 3.0) & (epe > 0.05 * true_mag)))
    hist = epe_histogram(epe)
    return _error_rows_from_totals(n, float(epe.sum()), float(epe @ epe), float(ae_deg.sum()), over, fl, med, p95,
                                   hist, region=region, motion=motion, frame=frame,
                                   tail=overflow_tail(epe) if hist[-1] else None)


OUTLIER_PX = (1, 3, 5)


def _rank_index(q: float, n: int) -> int:
    """0-based index of the nearest-rank ``q`` quantile of ``n`` sorted samples (rank ceil(q n))."""
    return max(1, math.ceil(q * n)) - 1


def _error_rows_from_totals(n: int, s_epe: float, s_sq: float, s_ae: float, over: list[int], fl: int,
                            med: float, p95: float, hist: np.ndarray, *, region: str, motion: str,
                            frame: int | None, tail: tuple[np.ndarray, np.ndarray] | None = None) -> list[dict]:
    """The flow metric rows of one region from its totals (one place builds them, whichever path counted).

    ``tail``: the overflow bin's samples (:func:`harness.metrics.histogram.overflow_tail`), kept in
    the quantile rows' ``hist`` so that a pooled quantile above 100 px is read from them.
    """
    nan = float("nan")
    kw = {"region": region, "motion": motion, "frame": frame}

    def mean(s: float) -> float:
        return s / n if n else nan

    packed = encode_hist(hist, tail=tail)  # one bytes object shared by both quantile rows
    rows = [
        _row("epe_mean", mean(s_epe), s_epe, n, **kw),
        _row("epe_rms", math.sqrt(s_sq / n) if n else nan, s_sq, n, **kw),
        _row("epe_median", med, nan, n, hist=packed, **kw),
        _row("epe_p95", p95, nan, n, hist=packed, **kw),
        _row("ae_mean", mean(s_ae), s_ae, n, **kw),
    ]
    for thr, k in zip(OUTLIER_PX, over):
        rows.append(_row(f"outlier_{thr}px", 100.0 * mean(k), k, n, **kw))
    # KITTI Fl: EPE > 3 px and EPE > 5 % of |w_true|
    rows.append(_row("fl_all", 100.0 * mean(fl), fl, n, **kw))
    return rows


def _quantile_targets(hist: np.ndarray, qs: tuple[float, ...]):
    """Where the nearest-rank quantiles lie: bin, rank within the bin and size of the bin, each ``(M, R, len(qs))``.

    ``hist`` is ``(M, R, nbins)``; the bin is -1 for an empty histogram.
    """
    from harness._flow_kernels import quantile_targets

    n = hist.sum(axis=-1)
    rank = np.array([[[_rank_index(q, int(c)) if c else -1 for q in qs] for c in row] for row in n], np.int64)
    rank = rank.reshape(hist.shape[:2] + (len(qs),))
    target = np.full(rank.shape, -1, np.int64)
    below, sizes = np.zeros_like(target), np.zeros_like(target)
    quantile_targets(np.ascontiguousarray(hist), rank, target, below, sizes)
    return target, np.where(target >= 0, rank - below, 0), sizes


def _quantiles(e, g, t, tl, bits, bits_l, bins, hist_code, hist, qs: tuple[float, ...]):
    """Exact nearest-rank quantiles ``(2, R, len(qs))`` of each motion's and region's EPE (NaN when empty),
    and the tail of each (motion, region) whose overflow bin holds samples (``{(m, r): (bins, counts)}``).

    ``hist_code`` (2, 2**R, nbins) is the histogram of each membership pattern, ``hist``
    (2, R, nbins) of each region (the sum of its patterns').
    """
    from harness._flow_kernels import values_in_bins

    target, rank, _ = _quantile_targets(hist, qs)
    out = np.full(target.shape, np.nan)
    n_m, n_codes, nbins = hist_code.shape
    # the samples of each target bin are collected once per pixel, by membership pattern (a
    # pixel is in several regions; an almost constant error puts most pixels in one bin)
    slot = np.full((n_m, nbins), -1, np.int16)  # a target bin's index among its motion's
    kept = [np.unique(target[m][target[m] >= 0]) for m in range(n_m)]
    # the overflow bin's samples are collected too, wherever there are any: they are the tail
    kept = [np.union1d(ks, [nbins - 1]).astype(ks.dtype) if hist[m, :, -1].any() else ks for m, ks in enumerate(kept)]
    sizes = np.zeros((n_m, max(1, max(len(k) for k in kept)), n_codes), np.int64)
    for m, ks in enumerate(kept):
        slot[m, ks] = np.arange(len(ks))
        sizes[m, :len(ks), 1:] = hist_code[m, 1:, ks]  # pattern 0: not scored, not collected
    start = np.zeros(sizes.size, np.int64)
    start[1:] = np.cumsum(sizes.ravel())[:-1]
    start = start.reshape(sizes.shape)
    values = np.empty(int(sizes.sum()), np.float64)
    values_in_bins(e, g, t, tl, bits, bits_l, bins, slot, start, values)
    # the selection, per region and bin, with Python's lists (numpy's scalars cost more than the work here)
    sizes_l, start_l, slot_l = sizes.tolist(), start.tolist(), [dict(zip(ks.tolist(), range(len(ks)))) for ks in kept]
    for m, by_region in enumerate(target.tolist()):
        for r, bins_r in enumerate(by_region):
            for k in dict.fromkeys(k for k in bins_r if k >= 0):  # each bin once, in order
                size, first = sizes_l[m][slot_l[m][k]], start_l[m][slot_l[m][k]]
                parts = [values[first[b]:first[b] + size[b]] for b in range(1, n_codes) if (b >> r) & 1 and size[b]]
                # a pattern's segment serves several regions: partitioned in place only as a copy
                samples = parts[0].copy() if len(parts) == 1 else np.concatenate(parts)
                js = [j for j, kj in enumerate(bins_r) if kj == k]  # the quantiles read from this bin
                samples.partition(rank[m, r, js])
                out[m, r, js] = samples[rank[m, r, js]]
    tails = {}
    for m, r in zip(*np.nonzero(hist[:, :, -1])):
        size, first = sizes_l[m][slot_l[m][nbins - 1]], start_l[m][slot_l[m][nbins - 1]]
        tails[int(m), int(r)] = overflow_tail(np.concatenate(
            [values[first[b]:first[b] + size[b]] for b in range(1, n_codes) if (b >> r) & 1 and size[b]]),
            collected=True)
    return out, tails


@dataclass(frozen=True, eq=False)
class PreparedTruth:
    """Everything of a pair's scoring that depends on the ground truth only (:func:`prepare_pair_truth`).

    Shared by every estimate of the same pair (the runner scores several pipelines against
    one truth); its arrays are read-only views.

    Attributes
    ----------
    regions : tuple of str
        The regions scored, in row order.
    boundary_px : int
        The ``interior`` region's margin (:func:`boundary_mask`).
    flow : (H, W, 2) float32
        The true (total) flow, C-contiguous; NaN where unknown.
    flow_local : (H, W, 2) float32
        ``flow - flow_camera`` in float32: the true local motion.
    bits, bits_local : (H, W) uint8
        Bit j set where the pixel is scored in ``regions[j]`` for the total / local motion
        (0: not scored). The same array when the two motions score the same pixels.
    """

    regions: tuple[str, ...]
    boundary_px: int
    flow: np.ndarray
    flow_local: np.ndarray
    bits: np.ndarray
    bits_local: np.ndarray

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)`` of the pair."""
        return self.bits.shape


def _read_only(a: np.ndarray) -> np.ndarray:
    v = a.view()
    v.flags.writeable = False
    return v


def prepare_pair_truth(truth, *, regions: Iterable[str] = REGIONS, boundary_px: int = 3) -> PreparedTruth:
    """The truth side of :func:`score_pair`, computed once for every estimate of the pair.

    Parameters
    ----------
    truth : PairTruth
        ``flow``, ``flow_camera`` (H, W, 2) float, ``valid`` (H, W) bool, ``instances`` (H, W) int or None.
    regions : iterable of str
        Regions to score (at most 8), from :data:`REGIONS`.
    boundary_px : int
        Margin of the ``interior`` region, px.

    Returns
    -------
    PreparedTruth
        Scored pixels of the total motion: valid and finite in ``flow``; of the local motion:
        valid and finite in ``flow - flow_camera``. Each motion's regions are built from its
        scored pixels (:func:`region_masks`).
    """
    regions = tuple(regions)
    from harness._flow_kernels import truth_local  # numba: on the first scoring, not with the module

    # read-only views: one compiled signature of the kernels whatever the caller's arrays
    t = _read_only(np.ascontiguousarray(check_flow(truth.flow, name="flow_true", allow_nan=True)))
    vt0 = np.asarray(truth.valid, bool)
    if vt0.shape != t.shape[:2]:
        raise ValueError(f"valid_true: expected shape {t.shape[:2]}, got {vt0.shape}")

    # local motion: the camera's field taken out of the truth (float32, as t - np.float32(flow_camera))
    cam = np.asarray(truth.flow_camera, np.float32)
    if cam.shape != t.shape:  # as numpy's t - cam broadcasts it
        cam = np.broadcast_to(cam, t.shape)
    t_local = np.empty_like(t)
    vt, vt_local = np.empty(vt0.shape, bool), np.empty(vt0.shape, bool)
    truth_local(t, _read_only(np.ascontiguousarray(cam)), _read_only(np.ascontiguousarray(vt0)), t_local, vt, vt_local)
    masks = region_masks(vt, truth.instances, boundary_px=boundary_px, regions=regions)
    bits = _region_bits(masks) if regions else np.zeros(vt.shape, np.uint8)
    if np.array_equal(vt, vt_local):  # the regions depend on the scored pixels only
        bits_local = bits
    else:
        masks_local = region_masks(vt_local, truth.instances, boundary_px=boundary_px, regions=regions)
        bits_local = _region_bits(masks_local) if regions else bits
    same = bits_local is bits
    bits = _read_only(np.ascontiguousarray(bits))
    bits_local = bits if same else _read_only(np.ascontiguousarray(bits_local))
    return PreparedTruth(regions=regions, boundary_px=int(boundary_px), flow=_read_only(t),
                         flow_local=_read_only(t_local), bits=bits, bits_local=bits_local)


def _score_motions(e: np.ndarray, g: np.ndarray, truth: PreparedTruth, ve: np.ndarray, *, frame: int | None,
                   motions: tuple[str, ...] = MOTIONS) -> tuple[list[dict], int]:
    """Flow rows of both motions in every region, and the number of non-finite estimate pixels.

    e, g : (H, W, 2) float32 C-contiguous estimate and global field (local estimate = e - g);
    ve : (H, W) bool. ``motions`` names motion 0 (total) and, if two, motion 1 (local); with
    one, the local motion is left unscored. When the count returned is not 0 the rows are
    meaningless: the caller raises.
    """
    from harness._flow_kernels import pair_totals, region_hists  # numba: on the first scoring, not with the module

    names = truth.regions
    h, w = truth.shape
    n_codes = 1 << len(names)
    stats = np.zeros((2, n_codes, 9), np.float64)
    hist_code = np.zeros((2, n_codes, HIST_NBINS), np.int32)
    bins = np.empty((2, h, w), np.uint16)
    bits_l = truth.bits_local if len(motions) > 1 else _read_only(np.zeros_like(truth.bits))
    bad = pair_totals(e, g, truth.flow, truth.flow_local, truth.bits, bits_l, ve, HIST_BIN_PX, HIST_NBINS,
                      stats, hist_code, bins)
    if bad:
        return [], bad
    hist = np.zeros((2, len(names), HIST_NBINS), np.int64)
    region_hists(hist_code, stats[:, :, _N], hist)
    quant, tails = _quantiles(e, g, truth.flow, truth.flow_local, truth.bits, bits_l, bins, hist_code, hist,
                              (0.5, 0.95))
    # region totals: the sum of the patterns it belongs to
    member = (np.arange(n_codes)[None, :] >> np.arange(len(names))[:, None]) & 1  # (R, codes)
    rows: list[dict] = []
    for m, motion in enumerate(motions):
        by_code = stats[m]
        used = np.flatnonzero(by_code[:, _N])
        for j, r in enumerate(names):
            st = np.zeros(9)
            for c in used:
                if member[j, c]:
                    st += by_code[c]
            n = int(st[_N])
            rows += _error_rows_from_totals(n, float(st[_S_EPE]), float(st[_S_SQ]), float(st[_S_AE]),
                                            [int(st[_K1]), int(st[_K3]), int(st[_K5])], int(st[_KFL]),
                                            float(quant[m, j, 0]), float(quant[m, j, 1]), hist[m, j],
                                            region=r, motion=motion, frame=frame, tail=tails.get((m, j)))
            k = int(st[_KCOV])
            rows.append(_row("coverage", 100.0 * k / n if n else float("nan"), k, n, region=r, motion=motion,
                             frame=frame))
    return rows, 0


# columns of the pattern totals of harness._flow_kernels.pair_totals
_N, _S_EPE, _S_SQ, _S_AE, _K1, _K3, _K5, _KFL, _KCOV = range(9)


def score_flow(flow_est: np.ndarray, flow_true: np.ndarray, valid_true: np.ndarray, *,
               valid_est: np.ndarray | None = None, instances: np.ndarray | None = None,
               motion: str = "total", frame: int | None = None, regions: Iterable[str] = REGIONS,
               boundary_px: int = 3) -> list[dict]:
    """Flow rows of one field in every region, plus ``coverage``.

    Scored pixels: every pixel valid (and finite) in the truth, whatever the
    method's own ``valid_est`` says, so that a method cannot improve its errors
    by declining hard pixels (Middlebury and KITTI score dense fields the same
    way); ``valid_est`` only feeds ``coverage``. A non-finite estimate is an
    error, not a pixel to skip. Regions are built from the truth's validity and
    instances (:func:`region_masks`).

    All regions are counted in one pass over the pixels (sums, outlier counts,
    EPE histogram); the median and 95th percentile are exact, read among the
    samples of the histogram bin that holds them. The values equal
    :func:`flow_rows` on each region's mask (sums to rounding, ~1e-15 relative;
    counts, quantiles and histograms exactly).
    """
    t = np.ascontiguousarray(check_flow(flow_true, name="flow_true", allow_nan=True))
    e = np.ascontiguousarray(check_flow(flow_est, name="flow_est", shape=t.shape[:2]))
    vt = np.asarray(valid_true, bool)
    if vt.shape != t.shape[:2]:
        raise ValueError(f"valid_true: expected shape {t.shape[:2]}, got {vt.shape}")
    vt = vt & _finite_uv(t)
    ve = _valid_est(valid_est, vt.shape)
    regions = tuple(regions)
    masks = region_masks(vt, instances, boundary_px=boundary_px, regions=regions)
    bits = np.ascontiguousarray(_region_bits(masks)) if regions else np.zeros(vt.shape, np.uint8)
    t, e, bits, ve = _read_only(t), _read_only(e), _read_only(bits), _read_only(ve)
    truth = PreparedTruth(regions=regions, boundary_px=boundary_px, flow=t, flow_local=t, bits=bits, bits_local=bits)
    # one motion: the local one is left unscored (g = e only keeps the pass's finiteness test true)
    rows, _ = _score_motions(e, e, truth, ve, frame=frame, motions=(motion,))
    return rows


def _valid_est(valid, shape: tuple[int, int]) -> np.ndarray:
    """The method's valid mask as C-contiguous (H, W) bool (all True when None)."""
    if valid is None:
        return np.ones(shape, bool)
    ve = np.ascontiguousarray(valid, bool)
    if ve.shape != shape:
        raise ValueError(f"valid_est: expected shape {shape}, got {ve.shape}")
    return ve


def _finite_uv(flow: np.ndarray) -> np.ndarray:
    """(H, W) bool: both components finite (``np.isfinite(flow).all(-1)``, several times faster)."""
    return np.isfinite(flow[..., 0]) & np.isfinite(flow[..., 1])


def _region_bits(masks: Mapping[str, np.ndarray]) -> np.ndarray:
    """(H, W) uint8: bit j set where the pixel is in the j-th region of ``masks`` (at most 8)."""
    if len(masks) > 8:
        raise ValueError(f"regions: at most 8 in one pass, got {len(masks)}")
    bits = None
    for j, m in enumerate(masks.values()):
        b = m.view(np.uint8) << np.uint8(j) if m.dtype == bool else m.astype(np.uint8) << np.uint8(j)
        bits = b if bits is None else bits | b
    return bits


def score_pair(estimate, truth, *, frame: int, regions: Iterable[str] | None = None,
               boundary_px: int | None = None, timings: bool = True, prepared: PreparedTruth | None = None
               ) -> list[dict]:
    """All rows of one frame pair: flow metrics (total and local motion) and stage timings.

    Both motions and every region are scored in one pass over the pixels
    (:mod:`harness._flow_kernels`); the values equal :func:`flow_rows` on each region's
    mask (sums to rounding, ~1e-15 relative, the angular error's arccos being the pass's
    own, within 1 ulp of numpy's; counts, quantiles and histograms exactly). To score
    several estimates of one pair, prepare the truth once::

        prepared = prepare_pair_truth(truth)
        rows = [score_pair(est, truth, frame=f, prepared=prepared) for est in estimates]

    Parameters
    ----------
    estimate : PairEstimate
        Uses ``flow_total``, ``flow_global`` (H, W, 2), ``valid`` (H, W) and ``stage_ms``.
    truth : PairTruth or None
        ``flow``, ``flow_camera`` (H, W, 2), ``valid`` (H, W) bool, ``instances`` (H, W) uint16.
        With ``prepared`` it is only checked for its size (and may be None).
    frame : int
        Index of the first frame of the pair.
    regions : iterable of str, optional
        Regions to score (default :data:`REGIONS`); with ``prepared``, must be its regions if given.
    boundary_px : int, optional
        Margin of the ``interior`` region (default 3); with ``prepared``, must be its margin if given.
    prepared : PreparedTruth, optional
        :func:`prepare_pair_truth` of ``truth``, shared by several estimates of the pair: the
        rows are the same as without it.
    """
    if prepared is None:
        if truth is None:
            raise ValueError("score_pair: expected a PairTruth or prepared=prepare_pair_truth(truth), got neither")
        prepared = prepare_pair_truth(truth, regions=REGIONS if regions is None else regions,
                                      boundary_px=3 if boundary_px is None else boundary_px)
    else:
        if regions is not None and tuple(regions) != prepared.regions:
            raise ValueError(f"regions: expected those of prepared {prepared.regions}, got {tuple(regions)}")
        if boundary_px is not None and boundary_px != prepared.boundary_px:
            raise ValueError(f"boundary_px: expected that of prepared ({prepared.boundary_px}), got {boundary_px}")
        if truth is not None and np.shape(truth.flow)[:2] != prepared.shape:
            raise ValueError(f"truth: expected the size of prepared {prepared.shape}, got {np.shape(truth.flow)[:2]}")
    shape = prepared.shape
    # finiteness of the estimate (total and local) is tested in the pass itself
    e = np.ascontiguousarray(check_flow(estimate.flow_total, name="flow_est", shape=shape, allow_nan=True))
    g = np.asarray(estimate.flow_global, np.float32)
    if g.shape != e.shape:  # as numpy's e - g broadcasts it
        g = np.broadcast_to(g, e.shape)
    # read-only views: one compiled signature of the kernels whatever the caller's arrays
    e, g, ve = _read_only(e), _read_only(np.ascontiguousarray(g)), _read_only(_valid_est(estimate.valid, shape))
    rows, bad = _score_motions(e, g, prepared, ve, frame=frame)
    if bad:  # raise check_flow's message
        check_flow(e, name="flow_est")
        check_flow(e - g, name="flow_est")
    if timings and getattr(estimate, "stage_ms", None):
        rows += timing_rows(estimate.stage_ms, frame=frame)
    return rows
