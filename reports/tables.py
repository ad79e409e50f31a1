"""The report's numbers: headline, per-scene, region and sweep tables, baseline diffs, gate verdict.

All aggregates are pooled from the results table's totals by
:func:`reports.load.pooled` (never an average of averages). Tables come back
as plain Python structures that the HTML and Markdown writers both render.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import pandas as pd

from reports.load import RunData, pooled, primary_rows, scene_bases

__all__ = ["HEADLINE", "Column", "MetricTable", "headline_columns", "metric_table", "format_value",
           "best_pipelines", "sweep_curves", "region_table", "baseline_diffs", "gate_view", "BASELINE_COLUMNS"]

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
    """How every number of the report is printed: 4 decimals below 1, 3 below 100, else 1; "n/a"
    where there is no value (a metric whose ground truth is absent has no rows: never a 0)."""
    if v is None or not np.isfinite(v):
        return "n/a"
    a = abs(v)
    if a >= 100:
        return f"{v:.1f}"
    if a >= 1:
        return f"{v:.3f}"
    return f"{v:.4f}"


def _column(df: pd.DataFrame, metric: str, label: str) -> Column:
    # the first row of the metric, found without copying every column of its rows
    at = np.flatnonzero((df["metric"] == metric).to_numpy(bool))
    unit = str(df["unit"].iloc[at[0]]) if len(at) else ""
    hib = bool(df["higher_is_better"].iloc[at[0]]) if len(at) else False
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
    """The one pipeline with the best finite value of ``col``; empty when none, or when two or more
    share it (pipelines with a common stage, e.g. one global-motion method, give identical values for
    that stage's metrics: no single pipeline earns them)."""
    vals = {p: values.get((p, col.metric), math.nan) for p in pipelines}
    finite = {p: v for p, v in vals.items() if np.isfinite(v)}
    if len(finite) < 2:
        return set()
    target = max(finite.values()) if col.higher_is_better else min(finite.values())
    best = {p for p, v in finite.items() if math.isclose(v, target, rel_tol=1e-9, abs_tol=1e-12)}
    return best if len(best) == 1 else set()


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


# the columns metric_table reads (its pooling and cell counts): a scene's rows are cut to these before
# they are filtered (a bool filter takes every column of ~10^6 rows, most of them arrow strings)
_POOLED_COLUMNS = ["pipeline", "cell_id", "metric", "region", "motion", "kind", "value", "sum", "count", "unit",
                   "higher_is_better", "hist", "status"]


def per_scene_rows(data: RunData) -> dict[str, pd.DataFrame]:
    """Scene (variant labels without their sweep suffix) -> its ok rows (the columns :func:`metric_table`
    reads)."""
    bases = scene_bases(data.ok["scene"])
    rows = data.ok[[c for c in _POOLED_COLUMNS if c in data.ok.columns]]
    return {s: rows[bases == s] for s in dict.fromkeys(bases)}


# ------------------------------------------------------------------------------ baseline and gate

BASELINE_COLUMNS = ["where", "pipeline", "metric", "region", "motion", "unit", "current", "baseline", "diff",
                    "diff_pct", "change", "rule"]


def baseline_diffs(data: RunData, baseline: str | os.PathLike, *, rules: str | os.PathLike | None = None
                   ) -> tuple[pd.DataFrame, str]:
    """The run against a baseline file, judged by the gate's own rules.

    The baseline is read by :func:`harness.gate.read_baseline` and compared by
    :func:`harness.gate.compare` with the rules of ``rules`` (default: the gate's
    ``gate_rules.yaml``), so "worse" here is exactly what fails the gate and
    "better" an improvement beyond the same tolerance. Returns the changed entries
    (``where, pipeline, metric, region, motion, unit, current, baseline, diff,
    diff_pct, change, rule``; worse first) and a note: the entries within tolerance
    or skipped, or why nothing could be compared.
    """
    from harness import gate

    try:
        base = gate.read_baseline(baseline)
        rule_set = gate.load_rules(rules if rules is not None else
                                   (gate.DEFAULT_RULES if gate.DEFAULT_RULES.is_file() else None))
        result = gate.compare(data.table, base, rule_set, suite=data.folder.suite or None)
    except gate.GateError as exc:
        return pd.DataFrame(columns=BASELINE_COLUMNS), f"The baseline cannot be compared with this run: {exc}"
    out, counts = [], {"within tolerance": 0, "skipped": 0}
    for c in result.checks:
        if c.key["metric"] == "cell_failed":
            continue
        change = gate.change(c)
        if change in counts:
            counts[change] += 1
            continue
        k = c.key
        sweep = f" {k['sweep_param']}={k['sweep_value']}" if k.get("sweep_param") else ""
        pct = 100.0 * c.delta / abs(c.baseline) if c.baseline and np.isfinite(c.delta) else math.nan
        out.append({"where": f"{k['scene']}{sweep}", "pipeline": k["pipeline"], "metric": k["metric"],
                    "region": k["region"], "motion": k["motion"], "unit": c.unit, "current": c.current,
                    "baseline": c.baseline, "diff": c.delta, "diff_pct": pct, "change": change, "rule": str(c.rule)})
    out.sort(key=lambda r: 0 if r["change"] == "worse" else 1)
    note = (f"Compared by the gate's rules: {counts['within tolerance']} entries within tolerance and "
            f"{counts['skipped']} skipped (rule off, or timings from another machine) are not listed.")
    if result.notes:
        note += " " + " ".join(f"{n[0].upper()}{n[1:]}." for n in result.notes)
    return pd.DataFrame(out, columns=BASELINE_COLUMNS), note


def gate_view(verdict: str | os.PathLike | Mapping) -> dict:
    """A verdict of ``aerobench gate --json`` (a path, read by :func:`harness.gate.read_verdict`, or its
    dict) as ``{"passed", "suite", "counts", "failures": [str], "notes": [str]}``."""
    from harness import gate

    v = verdict if isinstance(verdict, Mapping) else gate.read_verdict(verdict)
    failures = []
    for c in v["checks"]:
        if c["status"] != "fail":
            continue
        sweep = f" {c['sweep_param']}={c['sweep_value']}" if c.get("sweep_param") else ""
        failures.append(f"{c['scene']}{sweep} / {c['pipeline']}: {c['metric']} [{c['region']}, {c['motion']}]: "
                        f"{c['reason']}")
    return {"passed": bool(v["passed"]), "suite": str(v.get("suite", "")), "counts": dict(v["counts"]),
            "failures": failures, "notes": [str(n) for n in v.get("notes", [])]}
