"""Aggregation from totals: summed ``sum`` / ``count`` (and histograms) reduced by each metric's rule."""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np
import pandas as pd

from harness.metrics.histogram import (
    HIST_NBINS, add_hist, decode_alpha_totals, encode_alpha_totals, encode_hist, hist_quantile, merge_tails,
)
from harness.metrics.mot import alpha_mean_value
from harness.metrics.registry import METRICS, metric_def

def reduce_totals(metric: str, total: float, count: float, hist: np.ndarray | None = None, *,
                  tail: tuple[np.ndarray, np.ndarray] | None = None,
                  alphas: tuple[np.ndarray, np.ndarray] | None = None) -> float:
    """The value of ``metric`` from summed totals (and a summed histogram and its tail for quantiles, the
    summed per-alpha totals for HOTA's metrics)."""
    d = metric_def(metric) if metric in METRICS else None
    rule = d.reduce if d else "mean"
    if rule == "alpha_mean":
        return alpha_mean_value(metric, *alphas) if alphas is not None else float("nan")
    if rule == "total":
        return float(total)
    if count == 0 or not np.isfinite(count):
        return float("nan")
    if rule == "mean":
        return float(total / count)
    if rule == "rms":
        return float(math.sqrt(total / count))
    if rule == "rate":
        return float(100.0 * total / count)
    if rule == "complement":
        return float(1.0 - total / count)
    if hist is None:
        return float("nan")
    return hist_quantile(hist, d.q, tail=tail)


def aggregate(rows: pd.DataFrame, by: Iterable[str] = ()) -> pd.DataFrame:
    """Aggregate rows over everything not in ``by`` (+ metric, region, motion), from totals.

    ``sum`` and ``count`` are summed and reduced by each metric's rule; quantile
    metrics sum their ``hist`` and its overflow tail. Rows whose ``status`` (if present) is not "ok" are
    left out. Returns one row per group with ``by, metric, region, motion, kind,
    value, sum, count, unit, higher_is_better, n_rows`` (and ``hist`` for quantiles).
    """
    keys = list(dict.fromkeys([*by, "metric", "region", "motion"]))
    df = rows
    if "status" in df.columns:
        df = df[df["status"] == "ok"]
    cols = [*keys, "kind", "value", "sum", "count", "unit", "higher_is_better", "n_rows", "hist"]
    if df.empty:
        return pd.DataFrame(columns=cols)
    # the groups of df.groupby(keys, sort=True, dropna=False), walked as slices of one stable sort
    # (a pandas group iteration costs ~2 ms a group: minutes on a suite's results)
    gid = df.groupby(keys, sort=True, dropna=False).ngroup().to_numpy()
    order = np.argsort(gid, kind="stable")  # rows of a group keep their order: the first row is the group's
    bounds = np.flatnonzero(np.diff(gid[order])) + 1
    starts = np.concatenate([[0], bounds])
    ends = np.concatenate([bounds, [len(order)]])
    first = order[starts]
    key_cols = {k: df[k].to_numpy(object)[first] for k in keys}
    sums_all = df["sum"].to_numpy(np.float64)[order]
    counts_all = df["count"].to_numpy(np.float64)[order]
    kind = df["kind"].to_numpy(object)[first]
    unit = df["unit"].to_numpy(object)[first]
    hib = df["higher_is_better"].to_numpy()[first]
    metrics = key_cols["metric"]
    hist_col = df["hist"].to_numpy(object) if "hist" in df.columns else None
    out = []
    for g, (a, b) in enumerate(zip(starts, ends)):
        rec = {k: key_cols[k][g] for k in keys}
        metric = metrics[g]
        sums = sums_all[a:b]
        counts = counts_all[a:b]
        # math.fsum is exactly rounded, so the aggregate does not depend on the order of the rows
        # (which cell finished first); a row with items but no total (NaN) makes the total NaN
        # instead of silently dropping its sum while keeping its count
        total = math.fsum(sums[counts != 0])
        count = math.fsum(counts)
        hist = tail = alphas = None
        packed = b""
        d = METRICS.get(metric)
        if d is not None and d.reduce == "quantile":
            hist, tails = np.zeros(HIST_NBINS, np.int64), []
            for h in ([] if hist_col is None else hist_col[order[a:b]]):
                if isinstance(h, (bytes, bytearray)):
                    add_hist(hist, h, tails=tails)
            tail = merge_tails(tails)
            if int(tail[1].sum()) != int(hist[-1]):  # a row written before tails were kept: the floor
                tail = None
            total = float("nan")
            packed = encode_hist(hist, tail=tail)
        elif d is not None and d.reduce == "alpha_mean":
            parts = [decode_alpha_totals(h) for h in ([] if hist_col is None else hist_col[order[a:b]])
                     if isinstance(h, (bytes, bytearray)) and len(h)]
            if parts:
                # exactly rounded sums per alpha, as the totals above: independent of the rows' order
                alphas = tuple(np.array([math.fsum(v) for v in np.stack([p[k] for p in parts], 1)]) for k in (0, 1))
                packed = encode_alpha_totals(*alphas)
            total = float("nan")
        rec.update(kind=kind[g], value=reduce_totals(metric, total, count, hist, tail=tail, alphas=alphas),
                   sum=total, count=count, unit=unit[g], higher_is_better=bool(hib[g]), n_rows=int(b - a),
                   hist=packed)
        out.append(rec)
    return pd.DataFrame(out, columns=cols)
