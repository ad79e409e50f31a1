"""The report's numbers: headline, per-scene, region and sweep tables, baseline diffs, gate verdict.

All aggregates are pooled from the results table's totals by
:func:`reports.load.pooled` (never an average of averages). Tables come back
as plain Python structures that the HTML and Markdown writers both render.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from harness.results import summarize
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


def metric_table(data: RunData, rows: pd.DataFrame, columns: list[Column], *,
                 all_rows: pd.DataFrame | None = None) -> MetricTable:
    """Pool ``rows`` (a subset of ``data.ok``) per pipeline for ``columns``.

    ``all_rows`` (default the whole table) are the rows, failed cells included,
    of the same scenes: they give the "total" of the cell count.
    """
    agg = pooled(primary_rows(rows), ["pipeline"]) if len(rows) else None
    values, counts = {}, {}
    if agg is not None:
        for r in agg.itertuples(index=False):
            values[(r.pipeline, r.metric)] = float(r.value)
            counts[(r.pipeline, r.metric)] = float(r.count)
    pipes = [p for p in data.pipelines if any((p, c.metric) in values for c in columns)]
    best = {c.metric: best_pipelines(values, c, pipes) for c in columns}
    cells = {}
    all_cells = (data.table if all_rows is None else all_rows).groupby("pipeline")["cell_id"].nunique()
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
    rank_r = {r: i for i, r in enumerate(("all", "background", "vehicles", "interior"))}
    rank_m = {m: i for i, m in enumerate(("total", "local"))}

    def key(w: str):
        r, m = w.split(" / ", 1)
        return (rank_m.get(m, 9), m, rank_r.get(r, 9), r)

    return wide.loc[order, sorted(wide.columns, key=key)]


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

_KEYS = ("pipeline", "scene", "sweep_param", "sweep_value", "metric", "region", "motion")


def baseline_records(baseline) -> tuple[list[dict], str]:
    """Flatten a baseline (a loaded JSON dict, a list, or a path) to records.

    Returns ``(records, note)``; each record has ``pipeline, metric, value`` and,
    when the baseline has them, ``scene, sweep_param, sweep_value, region,
    motion`` (the summary keys of :func:`harness.results.summarize`, which
    harness.gate baselines use). Understood shapes: a list of records, a dict
    holding one under ``metrics`` / ``rows`` / ``summary`` / ``entries``, or
    nested ``{pipeline: {metric: value or {"value": v}}}``. Anything else gives
    no records and a note saying so.
    """
    if isinstance(baseline, (str, os.PathLike)):
        path = Path(baseline)
        try:
            baseline = json.loads(path.read_text())
        except (OSError, ValueError) as exc:
            return [], f"baseline {path}: unreadable ({exc})"
    if isinstance(baseline, Mapping):
        for key in ("metrics", "rows", "summary", "entries"):
            if isinstance(baseline.get(key), (list, Mapping)):
                baseline = baseline[key]
                break
    records = []
    if isinstance(baseline, list):
        for r in baseline:
            if isinstance(r, Mapping) and "pipeline" in r and "metric" in r:
                v = r.get("value")
                if isinstance(v, (int, float)) and not isinstance(v, bool):
                    records.append({k: str(r[k]) for k in _KEYS if k in r and r[k] is not None}
                                   | {"value": float(v)})
    elif isinstance(baseline, Mapping):
        for pipe, metrics in baseline.items():
            if not isinstance(metrics, Mapping):
                continue
            for m, v in metrics.items():
                if isinstance(v, Mapping):
                    v = v.get("value")
                if isinstance(v, (int, float)) and not isinstance(v, bool):
                    records.append({"pipeline": str(pipe), "metric": str(m), "value": float(v)})
    note = "" if records else "baseline given, but no (pipeline, metric, value) entries were found in it"
    return records, note


def _change(diff: float, higher_is_better: bool) -> str:
    if not np.isfinite(diff):
        return "gone"
    if diff == 0:
        return "same"
    return "better" if (diff > 0) == bool(higher_is_better) else "worse"


def baseline_diffs(data: RunData, baseline) -> tuple[pd.DataFrame, str]:
    """Current values against the baseline's, for the headline metrics.

    Baseline records with the full summary keys are matched to the current
    :func:`harness.results.summarize` rows on those keys; records with only
    ``pipeline, metric`` to the pooled headline value. Returns ``where,
    pipeline, metric, unit, current, baseline, diff, diff_pct, change``
    (change: worse / gone / better, in that order; unchanged entries are counted in the note, not
    listed) and a note (what was left out).
    """
    records, note = baseline_records(baseline)
    cols = ["where", "pipeline", "metric", "unit", "current", "baseline", "diff", "diff_pct", "change"]
    if not records:
        return pd.DataFrame(columns=cols), note
    shown = {c.metric for c in headline_columns(data)}
    prim = primary_rows(data.ok)
    primary_combo = {m: set(zip(g["region"], g["motion"]))
                     for m, g in data.ok.groupby("metric")} if len(data.ok) else {}
    # which (region, motion) each headline metric shows: region "all" rows of its primary motion
    motion_of = dict(zip(prim["metric"], prim["motion"]))
    full = summarize(data.table)
    full_idx = {tuple(str(r[k]) for k in _KEYS): r for r in full.to_dict("records")}
    overall = {(r["pipeline"], r["metric"]): r for r in pooled(prim, ["pipeline"]).to_dict("records")}
    out, hidden, hidden_worse = [], 0, 0
    for r in records:
        keyed = all(k in r for k in _KEYS)
        if keyed:
            cur = full_idx.get(tuple(r[k] for k in _KEYS))
            headline = (r["metric"] in shown and r["motion"] == motion_of.get(r["metric"])
                        and (r["region"] == "all" or "all" not in {x for x, _ in primary_combo.get(r["metric"], ())}))
            sweep = f" {r['sweep_param']}={r['sweep_value']}" if r.get("sweep_param") else ""
            where = f"{r['scene']}{sweep}" + ("" if r["region"] == "all" else f" [{r['region']}]")
        else:
            cur = overall.get((r["pipeline"], r["metric"]))
            headline, where = True, "all scenes"
        v = float(cur["value"]) if cur is not None else math.nan
        hib = bool(cur["higher_is_better"]) if cur is not None else False
        diff = v - r["value"]
        change = _change(diff, hib)
        if not headline:
            hidden += 1
            hidden_worse += change == "worse"
            continue
        pct = 100.0 * diff / abs(r["value"]) if r["value"] != 0 and np.isfinite(diff) else math.nan
        out.append({"where": where, "pipeline": r["pipeline"], "metric": r["metric"],
                    "unit": str(cur["unit"]) if cur is not None else "", "current": v, "baseline": r["value"],
                    "diff": diff, "diff_pct": pct, "change": change})
    order = {"worse": 0, "gone": 1, "better": 2}
    same = sum(r["change"] == "same" for r in out)
    out = sorted((r for r in out if r["change"] != "same"), key=lambda r: order.get(r["change"], 3))
    notes = []
    if same:
        notes.append(f"{same} headline entries equal the baseline and are not listed.")
    if hidden:
        notes.append(f"{hidden} further baseline entries (other metrics, regions and motions) were compared "
                     f"but are not listed; {hidden_worse} of them are worse than the baseline.")
    note = " ".join(notes)
    return pd.DataFrame(out, columns=cols), note


def _describe_item(item) -> str:
    if isinstance(item, Mapping):
        return ", ".join(f"{k}={item[k]}" for k in item)
    if isinstance(item, str):
        return item
    parts = []
    for attr in ("group", "name"):
        v = getattr(item, attr, None)
        if isinstance(v, str):
            parts.append(v)
    b, c = getattr(item, "baseline", None), getattr(item, "current", None)
    if isinstance(b, (int, float)) and isinstance(c, (int, float)):
        parts.append(f"baseline {b:.4g} \u2192 current {c:.4g}")
    reason = getattr(item, "reason", None)
    if reason:
        parts.append(str(reason))
    return ": ".join(parts[:2]) + (" " + ", ".join(parts[2:]) if len(parts) > 2 else "") if parts else str(item)


def gate_view(gate_result) -> dict | None:
    """A gate result (mapping or object, e.g. ``harness.gate.GateResult``) as ``{"passed": bool |
    None, "verdict": str, "messages": [str], "notes": [str]}``; None when none was given."""
    if gate_result is None:
        return None

    def get(key):
        if isinstance(gate_result, Mapping):
            return gate_result.get(key)
        try:
            return getattr(gate_result, key, None)
        except Exception:  # a property that cannot be computed is simply absent
            return None

    passed = None
    for key in ("passed", "ok", "success"):
        if isinstance(get(key), bool):
            passed = get(key)
            break
    verdict = ""
    for key in ("verdict", "status", "result"):
        if isinstance(get(key), str):
            verdict = get(key)
            break
    if passed is None and verdict:
        passed = verdict.strip().lower() in ("pass", "passed", "ok", "success")
    if not verdict:
        verdict = "passed" if passed else ("failed" if passed is False else "unknown")
    messages = []
    for key in ("failures", "regressions", "messages", "reasons", "details"):
        v = get(key)
        if isinstance(v, (list, tuple)):
            messages = [_describe_item(x) for x in v]
            break
    notes = [str(n) for n in (get("notes") or []) if isinstance(get("notes"), (list, tuple))]
    return {"passed": passed, "verdict": verdict, "messages": messages, "notes": notes}
