"""The report's numbers: headline, per-scene, region and sweep tables, baseline diffs, gate verdict.

All aggregates are pooled from the results table's totals by
:func:`reports.load.pooled` (never an average of averages). Tables come back
as plain Python structures that the HTML and Markdown writers both render.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from reports.load import RunData, pooled, primary_rows, scene_base

__all__ = ["HEADLINE", "Column", "MetricTable", "headline_columns", "metric_table", "format_value",
           "best_pipelines", "sweep_curves", "region_table", "baseline_records", "baseline_diffs",
           "gate_view"]

# (label in the report, metric names in order of preference: the first present is shown)
HEADLINE: list[tuple[str, tuple[str, ...]]] = [
    ("Endpoint error", ("epe_mean",)),
    ("Angular error", ("ae_mean",)),
    ("Outlier rate", ("outlier_3px", "fl_all", "outlier_1px", "outlier_5px")),
    ("Stabilisation residual", ("jitter_residual_rms",)),
    ("Trajectory error", ("track_error", "track_ate_rmse")),
    ("Time per frame", ("time_total_ms",)),
]


@dataclass(frozen=True)
class Column:
    """A metric column: its label, metric name, unit and direction (from the table)."""

    label: str
    metric: str
    unit: str
    higher_is_better: bool

    @property
    def direction(self) -> str:
        return "higher is better" if self.higher_is_better else "lower is better"

    @property
    def arrow(self) -> str:
        return "\u2191" if self.higher_is_better else "\u2193"


def format_value(v: float) -> str:
    """How every number of the report is printed: 4 decimals below 1, 3 below 100, else 1."""
    if v is None or not np.isfinite(v):
        return "\u2013"
    a = abs(v)
    if a >= 100:
        return f"{v:.1f}"
    if a >= 1:
        return f"{v:.3f}"
    return f"{v:.4f}"


def _column(df: pd.DataFrame, metric: str, label: str) -> Column:
    g = df[df["metric"] == metric]
    unit = str(g["unit"].iloc[0]) if len(g) else ""
    hib = bool(g["higher_is_better"].iloc[0]) if len(g) else False
    return Column(label, metric, unit, hib)


def headline_columns(data: RunData, *, include_others: bool = False) -> list[Column]:
    """The headline metrics present in the run (first preferred name of each), then, with
    ``include_others``, every other metric in the table's order."""
    cols = []
    used = set()
    for label, names in HEADLINE:
        for n in names:
            if n in data.metrics:
                cols.append(_column(data.ok, n, label))
                used.add(n)
                break
    if include_others:
        for m in data.metrics:
            if m not in used:
                cols.append(_column(data.ok, m, m))
    return cols


@dataclass
class MetricTable:
    """Pipelines (rows) x metric columns of pooled values, with the best marked per column."""

    columns: list[Column]
    pipelines: list[str]
    values: dict[tuple[str, str], float]      # (pipeline, metric) -> pooled value
    counts: dict[tuple[str, str], float]      # (pipeline, metric) -> pooled count
    best: dict[str, set[str]]                 # metric -> pipelines holding the best value
    cells: dict[str, str]                     # pipeline -> "ok / total" cells


def best_pipelines(values: dict[tuple[str, str], float], col: Column, pipelines: list[str]) -> set[str]:
    """The pipelines with the best finite value of ``col`` (ties all marked); empty if none."""
    vals = {p: values.get((p, col.metric), math.nan) for p in pipelines}
    finite = {p: v for p, v in vals.items() if np.isfinite(v)}
    if len(finite) < 2:
        return set()
    target = max(finite.values()) if col.higher_is_better else min(finite.values())
    return {p for p, v in finite.items() if v == target}


def metric_table(data: RunData, rows: pd.DataFrame, columns: list[Column]) -> MetricTable:
    """Pool ``rows`` (a subset of ``data.ok``) per pipeline for ``columns``."""
    agg = pooled(primary_rows(rows), ["pipeline"]) if len(rows) else None
    values, counts = {}, {}
    if agg is not None:
        for r in agg.itertuples(index=False):
            values[(r.pipeline, r.metric)] = float(r.value)
            counts[(r.pipeline, r.metric)] = float(r.count)
    pipes = [p for p in data.pipelines if any((p, c.metric) in values for c in columns)]
    best = {c.metric: best_pipelines(values, c, pipes) for c in columns}
    cells = {}
    all_cells = data.table.groupby("pipeline")["cell_id"].nunique()
    ok_cells = rows.groupby("pipeline")["cell_id"].nunique() if len(rows) else pd.Series(dtype=int)
    for p in pipes:
        cells[p] = f"{int(ok_cells.get(p, 0))} / {int(all_cells.get(p, 0))}"
    return MetricTable(columns, pipes, values, counts, best, cells)


def region_table(data: RunData, metric: str) -> pd.DataFrame:
    """``metric`` pooled per pipeline x region x motion (wide: one column per region/motion)."""
    rows = data.ok[data.ok["metric"] == metric]
    if rows.empty:
        return pd.DataFrame()
    agg = pooled(rows, ["pipeline"])
    agg["where"] = agg["region"].astype(str) + " / " + agg["motion"].astype(str)
    wide = agg.pivot(index="pipeline", columns="where", values="value")
    order = [p for p in data.pipelines if p in wide.index]
    return wide.loc[order]


def sweep_curves(data: RunData) -> dict[str, pd.DataFrame]:
    """Swept parameter -> pooled ``pipeline, sweep_value (float), metric, value`` over scenes and seeds."""
    out = {}
    ok = data.ok[data.ok["sweep_param"].astype(str) != ""]
    for param, g in ok.groupby("sweep_param", sort=True):
        agg = pooled(primary_rows(g), ["pipeline", "sweep_value"])
        agg["sweep_value"] = pd.to_numeric(agg["sweep_value"], errors="coerce")
        out[str(param)] = agg
    return out


def per_scene_rows(data: RunData) -> dict[str, pd.DataFrame]:
    """Scene (variant labels without their sweep suffix) -> its ok rows."""
    bases = data.ok["scene"].map(scene_base)
    return {s: data.ok[bases == s] for s in dict.fromkeys(bases)}


# ------------------------------------------------------------------------------ baseline and gate

def baseline_records(baseline) -> tuple[list[dict], str]:
    """Flatten a baseline (a loaded JSON dict, a list, or a path) to records.

    Returns ``(records, note)``; each record has ``pipeline, metric, value`` and
    optional ``scene, region, motion``. Understood shapes: a list of such
    records, a dict holding one under ``rows`` / ``summary`` / ``metrics`` /
    ``entries`` / ``values``, or nested ``{pipeline: {metric: value or
    {"value": v}}}``. Anything else gives no records and a note saying so.
    """
    if isinstance(baseline, (str, os.PathLike)):
        path = Path(baseline)
        try:
            baseline = json.loads(path.read_text())
        except (OSError, ValueError) as exc:
            return [], f"baseline {path}: unreadable ({exc})"
    if isinstance(baseline, Mapping):
        for key in ("rows", "summary", "metrics", "entries", "values"):
            if isinstance(baseline.get(key), list):
                baseline = baseline[key]
                break
            if isinstance(baseline.get(key), Mapping):
                baseline = baseline[key]
                break
    records = []
    if isinstance(baseline, list):
        for r in baseline:
            if isinstance(r, Mapping) and "pipeline" in r and "metric" in r:
                v = r.get("value", r.get("mean"))
                if isinstance(v, (int, float)):
                    records.append({"pipeline": str(r["pipeline"]), "metric": str(r["metric"]),
                                    "value": float(v), "scene": str(r.get("scene") or ""),
                                    "region": str(r.get("region") or "all"),
                                    "motion": str(r.get("motion") or "")})
    elif isinstance(baseline, Mapping):
        for pipe, metrics in baseline.items():
            if not isinstance(metrics, Mapping):
                continue
            for m, v in metrics.items():
                if isinstance(v, Mapping):
                    v = v.get("value", v.get("mean"))
                if isinstance(v, (int, float)) and not isinstance(v, bool):
                    records.append({"pipeline": str(pipe), "metric": str(m), "value": float(v),
                                    "scene": "", "region": "all", "motion": ""})
    note = "" if records else "baseline given, but no (pipeline, metric, value) entries were found in it"
    return records, note


def baseline_diffs(data: RunData, baseline) -> tuple[pd.DataFrame, str]:
    """Current pooled values against the baseline's: ``pipeline, scene, metric, unit, current,
    baseline, diff, diff_pct, change`` (change: better / worse / same / new / gone)."""
    records, note = baseline_records(baseline)
    cols = ["pipeline", "scene", "metric", "unit", "current", "baseline", "diff", "diff_pct", "change"]
    if not records:
        return pd.DataFrame(columns=cols), note
    prim = primary_rows(data.ok)
    overall = pooled(prim, ["pipeline"])
    by_scene = pooled(prim.assign(scene=prim["scene"].map(scene_base)), ["pipeline", "scene"])
    by_scene_full = pooled(prim, ["pipeline", "scene"])
    out = []
    for r in records:
        if r["scene"]:
            src = by_scene if r["scene"] in set(by_scene["scene"]) else by_scene_full
            cur = src[(src["pipeline"] == r["pipeline"]) & (src["metric"] == r["metric"])
                      & (src["scene"] == r["scene"])]
        else:
            cur = overall[(overall["pipeline"] == r["pipeline"]) & (overall["metric"] == r["metric"])]
        if cur.empty:
            out.append({**{k: r[k] for k in ("pipeline", "scene", "metric")}, "unit": "", "current": math.nan,
                        "baseline": r["value"], "diff": math.nan, "diff_pct": math.nan, "change": "gone"})
            continue
        c = cur.iloc[0]
        v, b = float(c["value"]), r["value"]
        diff = v - b
        pct = 100.0 * diff / abs(b) if b != 0 else math.nan
        if diff == 0:
            change = "same"
        else:
            change = "better" if (diff > 0) == bool(c["higher_is_better"]) else "worse"
        out.append({"pipeline": r["pipeline"], "scene": r["scene"], "metric": r["metric"], "unit": str(c["unit"]),
                    "current": v, "baseline": b, "diff": diff, "diff_pct": pct, "change": change})
    return pd.DataFrame(out, columns=cols), note


def gate_view(gate_result) -> dict | None:
    """A gate result (mapping, dataclass or object) as ``{"passed": bool | None, "verdict": str,
    "messages": [str]}``; None when no gate result was given."""
    if gate_result is None:
        return None
    if isinstance(gate_result, Mapping):
        d = dict(gate_result)
    elif hasattr(gate_result, "to_dict") and callable(gate_result.to_dict):
        d = dict(gate_result.to_dict())
    elif dataclasses.is_dataclass(gate_result) and not isinstance(gate_result, type):
        d = dataclasses.asdict(gate_result)
    else:
        d = {k: getattr(gate_result, k) for k in dir(gate_result)
             if not k.startswith("_") and not callable(getattr(gate_result, k, None))}
    passed = None
    for key in ("passed", "ok", "success"):
        if isinstance(d.get(key), bool):
            passed = d[key]
            break
    verdict = ""
    for key in ("verdict", "status", "result"):
        if isinstance(d.get(key), str):
            verdict = d[key]
            break
    if passed is None and verdict:
        passed = verdict.strip().lower() in ("pass", "passed", "ok", "success")
    if not verdict:
        verdict = "passed" if passed else ("failed" if passed is False else "unknown")
    messages = []
    for key in ("failures", "regressions", "messages", "reasons", "details", "checks"):
        v = d.get(key)
        if isinstance(v, (list, tuple)):
            for item in v:
                if isinstance(item, Mapping):
                    messages.append(", ".join(f"{k}={item[k]}" for k in item))
                elif dataclasses.is_dataclass(item):
                    messages.append(", ".join(f"{k}={v2}" for k, v2 in dataclasses.asdict(item).items()))
                else:
                    messages.append(str(item))
            break
    return {"passed": passed, "verdict": verdict, "messages": messages}
