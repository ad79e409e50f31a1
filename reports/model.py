"""The report's numbers, computed once; the HTML and Markdown writers only render them.

:func:`build_model` reads a run folder (through :mod:`reports.load`) and returns a
:class:`ReportModel`: provenance lines, the gate verdict and the baseline
comparison (both judged by :mod:`harness.gate`), the LK vs HS paired comparisons
(:mod:`reports.lkhs`), the headline, per-scene, region and all-metrics tables
and the sweep curves. Nothing here writes HTML or Markdown.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from reports import lkhs, real_footage, synthetic_vs_real
from reports.load import RunData, load_run, scene_base, scene_bases
from reports.tables import (Column, MetricTable, baseline_diffs, format_value, gate_view, headline_columns, metric_table,
                            per_scene_rows, region_table, sweep_curves)

__all__ = ["LOCAL_VS_TOTAL", "LKHS_FLOW", "LkHsPair", "ReportModel", "build_model", "summary_parts"]

# said once, in the LK vs HS section; the reason local EPE exceeds total EPE follows from
# harness.metrics: local scores (flow_total - flow_global) against (flow - flow_camera)
LOCAL_VS_TOTAL = (
    "Total motion scores the whole estimated flow (the global camera model plus the local flow) against the "
    "true flow. Local motion takes the global motion out of both sides: the estimate minus the pipeline's "
    "global-motion field against the true flow minus the true camera-induced flow, so what is left is the "
    "vehicles' own motion (zero on the ground). Local error is the larger because the global model (one shift "
    "per frame pair) never matches the true camera flow exactly (sub-pixel rest, rotation, parallax): the flow "
    "method recovers that rest, which keeps the total error small, but in the local comparison the rest counts "
    "as wrongly estimated vehicle motion. Pixel by pixel, the local error vector is the total error vector "
    "minus the global model's own error vector (their lengths do not subtract).")


# the regions and motions of the flow rows of LK vs HS; the first is the report's one-line verdict (all
# pixels, total motion: the endpoint error of the headline table)
LKHS_FLOW = (("all", "total"), ("background", "total"), ("vehicles", "total"), ("background", "local"),
             ("vehicles", "local"))


@dataclass
class LkHsPair:
    """One LK / HS twin and its paired comparisons."""

    lk: str
    hs: str
    comparisons: list[lkhs.Comparison]     # flow (epe_mean), per LKHS_FLOW entry with paired frames
    by_scene_seed: pd.DataFrame            # scene, seed, then LK - HS per "region / motion"
    tracking: list[lkhs.Comparison] = field(default_factory=list)  # per tracker and metric, paired by sequence


@dataclass
class ReportModel:
    """Everything the report states, as numbers and short texts."""

    data: RunData
    title: str
    provenance: list[tuple[str, str]]
    gate: dict | None                      # reports.tables.gate_view of the verdict, or None
    baseline: pd.DataFrame | None          # reports.tables.baseline_diffs, or None without a baseline
    baseline_note: str
    lkhs: list[LkHsPair]
    lkhs_note: str                         # why there is no comparison, when there is none
    columns: list[Column]                  # headline metrics
    headline: MetricTable
    per_scene: dict[str, MetricTable]
    regions: dict[str, pd.DataFrame]       # metric -> pipeline x "region / motion" pooled values
    all_metrics: MetricTable
    curves: dict[str, pd.DataFrame]
    notes: list[str] = field(default_factory=list)
    summary: list[str] = field(default_factory=list)  # the one-line verdict, in parts (see summary_parts)
    real_scenes: list[str] = field(default_factory=list)   # scene labels that are real footage
    real_tables: dict[str, MetricTable] = field(default_factory=dict)  # per real scene: its metrics
    synthetic_vs_real: synthetic_vs_real.SyntheticVsReal | None = None  # None without a real scene


def _provenance_rows(data: RunData) -> list[tuple[str, str]]:
    run, prov = data.run, data.folder.provenance
    versions = prov.get("versions") or {}
    if isinstance(versions, Mapping):
        versions = ", ".join(f"{k} {v}" for k, v in sorted(versions.items()))
    sweeps = sorted(set(pd.unique(data.table["sweep_param"].astype(str)).tolist()) - {""})  # not a loop over rows
    n_cells = data.table["cell_id"].nunique()
    commit, dirty = prov.get("git_commit"), prov.get("git_dirty")
    return [
        ("Suite", data.folder.suite or "(run.json has no suite name)"),
        ("Scenes", ", ".join(dict.fromkeys(scene_base(s) for s in data.scenes)) + f" ({len(data.scenes)} variants)"),
        ("Swept parameters", ", ".join(sweeps) or "none"),
        ("Pipelines", ", ".join(data.pipelines)),
        ("Seeds", ", ".join(str(s) for s in data.seeds)),
        ("Cells", f"{n_cells} ({n_cells - len(data.failed)} ok, {len(data.failed)} failed)"),
        ("Git commit", f"{commit}{' (dirty tree)' if dirty else ''}" if commit else "unknown"),
        ("Config hash", str(run.get("config_hash") or "unknown")),
        ("Versions", str(versions or "not recorded")),
        ("Renderer", str(prov.get("renderer") or "unknown")),
        ("Machine", str(prov.get("machine") or "unknown")),
        ("Date", f"started {run.get('started') or '?'}, finished {run.get('finished') or '?'}"),
        ("Run status", str(run.get("status") or "unknown")),
        ("Aggregation", "Every figure and table pools the results table's totals (sum and count) over "
                        "frames, tracks, seeds and cells, then reduces them by each metric's rule "
                        "(mean = sum / count, rms = sqrt(sum / count), rate = 100 sum / count); never an "
                        "average of averages. Flow metrics: region 'all', motion 'total' unless a table "
                        "says otherwise; track metrics pool both trackers. Failed cells are left out."),
    ]


def _lkhs(data: RunData) -> tuple[list[LkHsPair], str]:
    specs = {p: s for p, s in data.folder.pipelines.items() if p in data.pipelines}
    twins = lkhs.pair_pipelines(specs)
    if not twins:
        if not specs:
            return [], ("run.json names no resolved pipelines (a run folder written before they were "
                        "recorded): the LK and HS pipelines cannot be identified; re-run the suite.")
        return [], ("No pair of pipelines that differ only in the flow method (lucas_kanade vs horn_schunck) "
                    "was run.")
    ok_ids = pd.unique(data.ok["cell_id"])  # distinct ids: isin of arrow strings loops over them
    # the comparisons read epe_mean and track rows only: select them before the cell filter, not after it
    track = data.table[data.table["motion"] == "track"]
    track = track[track["cell_id"].isin(ok_ids)]
    if "epe_mean" not in data.metrics and track.empty:
        return [], "The run has no epe_mean or tracking rows: nothing to compare."
    epe = data.table[data.table["metric"] == "epe_mean"]
    ok = epe[epe["cell_id"].isin(ok_ids)]
    pairs = []
    for lk, hs in twins:
        flow = [c for region, motion in LKHS_FLOW
                for c in lkhs.compare_pair(ok, lk, hs, regions=(region,), motions=(motion,))]
        pairs.append(LkHsPair(lk, hs, flow, lkhs.by_scene_seed(ok, lk, hs),
                              lkhs.compare_tracking(track, lk, hs) if len(track) else []))
    return pairs, ""


def summary_parts(pairs: list[LkHsPair], headline: MetricTable, columns: list[Column], gate: dict | None,
                  baseline: pd.DataFrame | None) -> list[str]:
    """The report's one-line verdict, in parts: LK vs HS (the first twin, all pixels, total motion),
    the best pipeline by the headline's first metric, the gate and the baseline comparison."""
    parts = []
    first = next((c for c in pairs[0].comparisons if (c.region, c.motion) == LKHS_FLOW[0]), None) if pairs else None
    if first is None:
        parts.append("LK vs HS: no LK / HS twin" if not pairs else "LK vs HS: no frame pair scored by both")
    else:
        ci = f"95 % CI {first.lo:+.3f} to {first.hi:+.3f}; {first.lk} vs {first.hs}, all pixels"
        if first.better is None:
            parts.append(f"LK vs HS: no clear difference ({first.diff:+.3f} px EPE, {ci})")
        else:
            parts.append(f"LK vs HS: {first.better} better by {abs(first.diff):.3f} px EPE ({ci})")
    if columns and headline.pipelines:
        c = columns[0]
        best = [p for p in headline.pipelines if p in headline.best.get(c.metric, set())]  # one, or none: a tie
        if best:
            value = format_value(headline.values.get((best[0], c.metric), float("nan")))
            unit = f" {c.unit}" if c.unit else ""
            name = "EPE" if c.metric == "epe_mean" else c.metric
            parts.append(f"best: {best[0]} ({name} {value}{unit})")
    if gate is None:
        parts.append("gate: not run")
    else:
        n = gate["counts"]
        parts.append("gate: passed" if gate["passed"] else f"gate: FAILED ({n['failed']} of {n['checked']} checks)")
    if baseline is not None:
        worse = int((baseline["change"] == "worse").sum()) if len(baseline) else 0
        better = int((baseline["change"] == "better").sum()) if len(baseline) else 0
        parts.append(f"baseline: {worse} worse, {better} better")
    return parts


def build_model(run_dir: str | os.PathLike, *, baseline: str | os.PathLike | None = None,
                gate_verdict: str | os.PathLike | Mapping | None = None,
                rules: str | os.PathLike | None = None, data: RunData | None = None) -> ReportModel:
    """Read ``run_dir`` and compute every number of its report.

    Parameters
    ----------
    run_dir : path
        A run folder.
    baseline : path, optional
        A baseline file of ``aerobench baseline``; compared by the gate's rules.
    gate_verdict : path or dict, optional
        A verdict of ``aerobench gate --json``.
    rules : path, optional
        Gate rules for the baseline comparison; default the gate's ``gate_rules.yaml``.
    data : RunData, optional
        ``load_run(run_dir)``, when the caller has read it already.
    """
    if data is None:
        data = load_run(run_dir)
    cols = headline_columns(data)
    diffs, note = (baseline_diffs(data, baseline, rules=rules) if baseline is not None else (None, ""))
    bases = scene_bases(data.table["scene"])
    # all_rows only gives the cells per pipeline: filter those two columns, not the whole table
    cell_rows = data.table[["pipeline", "cell_id"]]
    per_scene = {s: metric_table(data, rows, cols, all_rows=cell_rows[bases == s])
                 for s, rows in per_scene_rows(data).items()}
    regions = {}
    for c in cols[:2]:
        wide = region_table(data, c.metric)
        if wide.shape[1] > 1:
            regions[c.metric] = wide
    pairs, lkhs_note = _lkhs(data)
    gate = gate_view(gate_verdict) if gate_verdict is not None else None
    headline = metric_table(data, data.ok, cols)
    real = real_footage.real_scenes(data)
    return ReportModel(
        data=data, title=f"aerobench report: {data.folder.suite or Path(run_dir).name}",
        provenance=_provenance_rows(data), gate=gate,
        baseline=diffs, baseline_note=note, lkhs=pairs, lkhs_note=lkhs_note, columns=cols,
        headline=headline, per_scene=per_scene, regions=regions,
        all_metrics=metric_table(data, data.ok, headline_columns(data, include_others=True)),
        curves=sweep_curves(data), summary=summary_parts(pairs, headline, cols, gate, diffs),
        real_scenes=real, real_tables={s: real_footage.real_metric_table(data, s) for s in real},
        synthetic_vs_real=synthetic_vs_real.compare(data.ok, real, pipelines=data.pipelines) if real else None)
