"""``write_report``: one self-contained ``report.html`` and a ``report.md`` from a run folder.

The report reads only the run folder (run.json, results.parquet, the cell
artifacts) and the sequence folders in the cache dir named in run.json. The
HTML has no external resource: CSS inline, figures as inline SVG, pictures as
base64 PNG. The output is deterministic: the same run folder gives the same
bytes (the date shown is the run's, from run.json).
"""

from __future__ import annotations

import html
import math
import os
from pathlib import Path

import numpy as np
import pandas as pd

from reports import pictures, plots
from reports.load import (RunData, find_sequence_dir, load_run, picture_frames, read_camera_flow, read_cell_flow,
                          read_frame_truth, read_stabilisation, read_tracks, read_true_tracks,
                          scene_base)
from reports.tables import (Column, MetricTable, baseline_diffs, format_value, gate_view, headline_columns,
                            metric_table, per_scene_rows, region_table, sweep_curves)
from scenes.formats import atomic_write_bytes

__all__ = ["write_report", "build_report"]

_MAX_PICTURE_FRAMES = 2
_PICTURE_MIN_WIDTH_PX = 320  # tiny suites render 160 x 120: enlarge pictures to at least this width
_LOCAL_FLOOR_PX = 1.0  # colour scale floor of the local-motion row (a scene may have no moving vehicle)

_CSS = """
:root { --fg:#1b1f24; --muted:#57606a; --line:#d0d7de; --bg-alt:#f6f8fa; --best:#dafbe1; --bad:#ffebe9; }
* { box-sizing: border-box; }
body { margin:0; font: 15px/1.45 system-ui, -apple-system, "Segoe UI", Roboto, "DejaVu Sans", sans-serif;
       color: var(--fg); background:#fff; }
main { max-width: 1180px; margin: 0 auto; padding: 16px; }
h1 { font-size: 1.6em; margin: 0.2em 0 0.4em; }
h2 { font-size: 1.3em; border-bottom: 1px solid var(--line); padding-bottom: 4px; margin-top: 1.8em; }
h3 { font-size: 1.05em; margin: 1.2em 0 0.4em; }
p.note, .note { color: var(--muted); font-size: 0.9em; }
nav ul { display:flex; flex-wrap:wrap; gap: 4px 14px; padding:0; list-style:none; margin: 0.5em 0; }
nav a { color:#0969da; text-decoration:none; }
.scroll { overflow-x: auto; -webkit-overflow-scrolling: touch; margin: 0.4em 0 0.8em; }
table { border-collapse: collapse; font-size: 0.9em; }
th, td { border: 1px solid var(--line); padding: 4px 8px; vertical-align: top; }
th { background: var(--bg-alt); text-align: left; font-weight: 600; }
th small { font-weight: 400; color: var(--muted); display:block; }
td.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
td.best { background: var(--best); font-weight: 700; }
td.worse { background: var(--bad); }
table.meta th { width: 12em; }
table.meta td { word-break: break-word; }
.verdict { padding: 10px 14px; border-radius: 6px; font-weight: 700; margin: 0.6em 0; }
.verdict.pass { background: var(--best); border: 1px solid #4ac26b; }
.verdict.fail { background: var(--bad); border: 1px solid #ff8182; }
.verdict.unknown { background: var(--bg-alt); border: 1px solid var(--line); }
figure { margin: 0.6em 0 1.2em; }
figcaption { color: var(--muted); font-size: 0.88em; margin-top: 4px; }
.plot { overflow-x: auto; }
.plot svg { display:block; }
.gallery { display: grid; grid-template-columns: repeat(auto-fill, minmax(170px, 1fr)); gap: 10px; }
.gallery figure { margin: 0; }
.gallery img { width: 100%; height: auto; display: block; border: 1px solid var(--line); }
.gallery.flow { grid-template-columns: repeat(auto-fill, minmax(260px, 1fr)); margin-bottom: 10px; }
.gallery figure.empty { border: 1px dashed var(--line); display: flex; align-items: center; justify-content: center;
                        min-height: 80px; padding: 6px; }
h4 { font-size: 0.95em; margin: 0.9em 0 0.2em; }
img.pix { image-rendering: pixelated; }
img.legend { max-width: 120px; border: none !important; }
img.bar { width: 100%; height: 14px; }
pre { white-space: pre-wrap; word-break: break-word; background: var(--bg-alt); padding: 8px;
      font-size: 0.82em; max-height: 18em; overflow: auto; }
.missing { color: var(--muted); font-style: italic; }
@media (max-width: 600px) {
  body { font-size: 14px; }
  main { padding: 10px; }
  .gallery { grid-template-columns: repeat(2, 1fr); }
  .plot svg { min-width: 520px; }  /* scroll sideways rather than shrink text below legibility */
}
@media print {
  nav { display: none; }
  main { max-width: none; padding: 0; }
  .scroll { overflow: visible; }
  pre { max-height: none; overflow: visible; }
  details > *:not(summary) { display: block; }
  figure, table, .gallery { break-inside: avoid; page-break-inside: avoid; }
  h2 { break-after: avoid; page-break-after: avoid; }
  td.best, td.worse { -webkit-print-color-adjust: exact; print-color-adjust: exact; }
  body { font-size: 10pt; }
  table { font-size: 7.5pt; }
  th, td { padding: 2px 4px; }
  th small { display: none; }
}
"""

_SECTIONS = [
    ("provenance", "What was run"),
    ("verdict", "Gate and baseline"),
    ("headline", "Headline"),
    ("per-scene", "Per scene"),
    ("regions", "By region and motion"),
    ("all-metrics", "All metrics"),
    ("difficulty", "Difficulty curves"),
    ("pictures", "Pictures"),
    ("stabilisation", "Stabilisation"),
    ("tracking", "Tracking"),
    ("failed", "Failed cells"),
]


def _e(x) -> str:
    """Escape any text that comes from data."""
    return html.escape("" if x is None else str(x), quote=True)


def _missing(text: str) -> str:
    return f'<p class="missing">{_e(text)}</p>'


# ------------------------------------------------------------------------------ sections

def _provenance_rows(data: RunData) -> list[tuple[str, str]]:
    run, prov = data.run, data.run.get("provenance") or {}
    t = data.table

    def first(col):
        v = t[col].astype(str)
        v = v[v != ""]
        return v.iloc[0] if len(v) else ""

    commit = prov.get("git_commit") or first("git_commit")
    dirty = prov.get("git_dirty")
    if dirty is None and len(t):
        dirty = bool(t["git_dirty"].any())
    versions = prov.get("versions") or {}
    if isinstance(versions, dict):
        versions = ", ".join(f"{k} {v}" for k, v in sorted(versions.items()))
    sweeps = sorted(set(data.table["sweep_param"].astype(str)) - {""})
    n_cells = data.table["cell_id"].nunique()
    return [
        ("Suite", str(run.get("suite") or "(run.json has no suite name)")),
        ("Scenes", ", ".join(dict.fromkeys(scene_base(s) for s in data.scenes))
         + f" ({len(data.scenes)} variants)"),
        ("Swept parameters", ", ".join(sweeps) or "none"),
        ("Pipelines", ", ".join(data.pipelines)),
        ("Seeds", ", ".join(str(s) for s in data.seeds)),
        ("Cells", f"{n_cells} ({n_cells - len(data.failed)} ok, {len(data.failed)} failed)"),
        ("Git commit", f"{commit}{' (dirty tree)' if dirty else ''}" if commit else "unknown"),
        ("Config hash", str(run.get("config_hash") or first("config_hash") or "unknown")),
        ("Versions", str(versions or "not recorded")),
        ("Renderer", str(prov.get("renderer") or first("renderer") or "unknown")),
        ("Machine", str(prov.get("machine") or first("machine") or "unknown")),
        ("Date", f"started {run.get('started') or '?'}, finished {run.get('finished') or '?'}"),
        ("Run status", str(run.get("status") or "unknown")),
        ("Aggregation", "Every figure and table pools the results table's totals (sum and count) over "
                        "frames, tracks, seeds and cells, then reduces them by each metric's rule "
                        "(mean = sum / count, rms = sqrt(sum / count), rate = 100 sum / count); never an "
                        "average of averages. Flow metrics: region 'all', motion 'total' unless a table "
                        "says otherwise; track metrics pool both trackers. Failed cells are left out."),
    ]


def _col_header(c: Column) -> str:
    unit = f" [{_e(c.unit)}]" if c.unit else ""
    return (f'<th scope="col" title="{_e(c.direction)}">{_e(c.label)}{unit} {c.arrow}'
            f"<small>{_e(c.metric)}, {_e(c.direction)}</small></th>")


def _metric_table_html(t: MetricTable, *, caption: str = "") -> str:
    if not t.pipelines:
        return _missing("No results for these metrics.")
    head = "".join(_col_header(c) for c in t.columns)
    body = []
    for p in t.pipelines:
        cells = []
        for c in t.columns:
            v = t.values.get((p, c.metric), math.nan)
            if p in t.best.get(c.metric, set()):
                cells.append(f'<td class="num best" title="best">{format_value(v)} \u2605</td>')
            else:
                cells.append(f'<td class="num">{format_value(v)}</td>')
        body.append(f'<tr><th scope="row">{_e(p)}</th>{"".join(cells)}<td class="num">{_e(t.cells[p])}</td></tr>')
    cap = f"<caption class=\"note\">{_e(caption)}</caption>" if caption else ""
    return (f'<div class="scroll"><table class="metrics">{cap}<thead><tr><th scope="col">Pipeline</th>{head}'
            f'<th scope="col">Cells<small>ok / total</small></th></tr></thead><tbody>{"".join(body)}'
            "</tbody></table></div>")


def _metric_table_md(t: MetricTable) -> str:
    if not t.pipelines:
        return "_No results for these metrics._\n"
    head = ["Pipeline"] + [f"{c.label} [{c.unit}] {c.arrow}" if c.unit else f"{c.label} {c.arrow}"
                           for c in t.columns] + ["Cells ok/total"]
    lines = ["| " + " | ".join(_md(h) for h in head) + " |", "|" + "---|" * len(head)]
    for p in t.pipelines:
        vals = []
        for c in t.columns:
            s = format_value(t.values.get((p, c.metric), math.nan))
            vals.append(f"**{s}**" if p in t.best.get(c.metric, set()) else s)
        lines.append("| " + " | ".join([_md(p), *vals, t.cells[p]]) + " |")
    return "\n".join(lines) + "\n"


def _md(x) -> str:
    return str(x).replace("|", "\\|").replace("\n", " ")


def _verdict_html(gate: dict | None, diffs: pd.DataFrame | None, note: str) -> str:
    out = []
    if gate is not None:
        cls = {True: "pass", False: "fail"}.get(gate["passed"], "unknown")
        word = {True: "PASSED", False: "FAILED"}.get(gate["passed"], "UNKNOWN")
        extra = "" if gate["verdict"].strip().upper() in (word, word[:-2]) else f' ({_e(gate["verdict"])})'
        out.append(f'<div class="verdict {cls}">Gate: {word}{extra}</div>')
        msgs = [f"<li>{_e(m)}</li>" for m in gate["messages"]]
        if msgs:
            out.append("<ul>" + "".join(msgs[:8]) + "</ul>")
        if len(msgs) > 8:
            out.append(f"<details><summary>{len(msgs) - 8} more</summary><ul>{''.join(msgs[8:])}</ul></details>")
        out += [f'<p class="note">{_e(n)}</p>' for n in gate["notes"]]
    else:
        out.append(_missing("No gate result was given."))
    if diffs is None:
        out.append(_missing("No baseline was given: no diff column."))
    elif note:
        out.append(_missing(note))
    if diffs is not None and len(diffs):
        rows = []
        for r in diffs.itertuples(index=False):
            cls = " worse" if r.change == "worse" else (" best" if r.change == "better" else "")
            pct = "" if not np.isfinite(r.diff_pct) else f" ({r.diff_pct:+.1f} %)"
            diff = "\u2013" if not np.isfinite(r.diff) else f"{r.diff:+.4g}{pct}"
            rows.append(f'<tr><td>{_e(r.where)}</td><th scope="row">{_e(r.pipeline)}</th>'
                        f"<td>{_e(r.metric)}</td><td>{_e(r.unit)}</td>"
                        f'<td class="num">{format_value(r.current)}</td><td class="num">{format_value(r.baseline)}</td>'
                        f'<td class="num{cls}">{_e(diff)}</td><td>{_e(r.change)}</td></tr>')
        out.append('<div class="scroll"><table><thead><tr><th>Where</th><th>Pipeline</th><th>Metric</th>'
                   "<th>Unit</th><th>Current</th><th>Baseline</th><th>Diff (current \u2212 baseline)</th>"
                   f"<th>Change</th></tr></thead><tbody>{''.join(rows)}</tbody></table></div>")
    return "".join(out)


def _difficulty_html(data: RunData, curves: dict[str, pd.DataFrame], cols: list[Column],
                     colors: dict[str, str]) -> str:
    if not curves:
        return _missing("No parameter was swept in this run: no difficulty curves.")
    out = ['<p class="note">Each point pools every scene and seed run at that value of the parameter. '
           "A line that climbs steeply marks where a method breaks.</p>"]
    for param, agg in curves.items():
        present = [c for c in cols if c.metric in set(agg["metric"])]
        if agg["sweep_value"].isna().all() or not present:
            out.append(_missing(f"{param}: sweep values are not numeric; no curve drawn."))
            continue
        metrics = [(c.metric, f"{c.label} [{c.unit}] {c.arrow}" if c.unit else f"{c.label} {c.arrow}")
                   for c in present]
        svg = plots.difficulty_curves(agg, param=param, metrics=metrics, colors=colors)
        out.append(f'<h3>Against {_e(param)}</h3><figure class="plot">{svg}<figcaption>'
                   f"Pooled value per pipeline at each {_e(param)}; arrows give the better direction."
                   "</figcaption></figure>")
    return "".join(out)


def _cell_index(data: RunData) -> pd.DataFrame:
    """One row per ok cell: cell_id, scene, scene_hash, seed, pipeline, sweep."""
    cols = ["cell_id", "scene", "scene_hash", "seed", "pipeline", "sweep_param", "sweep_value"]
    return data.ok[cols].drop_duplicates("cell_id").reset_index(drop=True)


def _variant_for(data: RunData, cells: pd.DataFrame, base: str, want) -> tuple[pd.DataFrame, Path | None]:
    """The first variant (scene label, seed) of scene ``base`` whose cells satisfy ``want(cell_dir)``."""
    sub = cells[cells["scene"].map(scene_base) == base]
    # the easiest setting first (lowest sweep value, then lowest seed): the base case the thesis shows
    sub = sub.assign(_x=pd.to_numeric(sub["sweep_value"], errors="coerce")).sort_values(
        ["_x", "sweep_value", "seed", "cell_id"], kind="stable").drop(columns="_x")
    for (label, seed), g in sub.groupby(["scene", "seed"], sort=False):
        dirs = [data.run_dir / "cells" / c for c in g["cell_id"]]
        if any(want(d) for d in dirs):
            seq = find_sequence_dir(data, scene=label, scene_hash=str(g["scene_hash"].iloc[0]))
            return g, seq
    return sub.iloc[:0], None


def _img(uri: str, *, cls: str = "", alt: str) -> str:
    return f'<img class="{cls}" src="{uri}" alt="{_e(alt)}">'


def _tile(rgb: np.ndarray, *, scale: int, alt: str, caption: str) -> str:
    """A picture tile: ``rgb`` enlarged ``scale`` x by nearest neighbour, with its caption."""
    uri = pictures.png_data_uri(pictures.upscale_nearest(rgb, scale))
    return f"<figure>{_img(uri, cls='pix' if scale > 1 else '', alt=alt)}<figcaption>{_e(caption)}</figcaption></figure>"


def _empty_tile(text: str) -> str:
    """A placeholder that keeps the columns of the flow row and the error row aligned."""
    return f'<figure class="empty"><p class="missing">{_e(text)}</p></figure>'


def _flow_rows(truth: np.ndarray | None, ests: dict[str, np.ndarray | None], valid: np.ndarray | None, *,
               scale: int, first_error_tile: str, what: str, floor_px: float) -> str:
    """Two aligned galleries: [truth, each method's flow, colour wheel] and
    [``first_error_tile``, each method's endpoint-error map, colour bar].

    Colours saturate at one magnitude for the whole row (the largest true
    magnitude, at least ``floor_px``); the error maps share one scale (the
    largest 99th percentile of the methods' errors).
    """
    present = [f for f in ests.values() if f is not None]
    max_mag = pictures.row_max_magnitude(truth, present, valid, floor_px=floor_px)
    tiles = [_tile(pictures.flow_row(truth, max_magnitude=max_mag, valid=valid), scale=scale,
                   alt=f"true {what} flow", caption=f"true {what} flow")
             if truth is not None else _empty_tile(f"no true {what} flow")]
    for pipe, flow in ests.items():
        tiles.append(_tile(pictures.flow_row(flow, max_magnitude=max_mag), scale=scale, alt=f"{pipe} {what} flow",
                           caption=pipe) if flow is not None else _empty_tile(f"{pipe}: no {what} flow saved"))
    tiles.append(f"<figure>{_img(pictures.png_data_uri(pictures.wheel_legend()), cls='legend', alt='colour wheel')}"
                 f"<figcaption>hue = direction (+x right, +y down), full saturation = {max_mag:.2f} px"
                 "</figcaption></figure>")
    out = [f"<div class=\"gallery flow\">{''.join(tiles)}</div>"]
    if truth is None or not present:
        return "".join(out)
    errs = []
    for flow in present:
        d = np.hypot(*(flow.astype(np.float64) - truth.astype(np.float64)).transpose(2, 0, 1))
        known = np.isfinite(d) & (valid if valid is not None else True)
        if known.any():
            errs.append(float(np.percentile(d[known], 99)))
    err_max = max(errs + [1e-3])
    etiles = [first_error_tile]
    for pipe, flow in ests.items():
        if flow is None:
            etiles.append(_empty_tile(f"{pipe}: no {what} flow saved"))
            continue
        rgb, mean = pictures.epe_map(flow, truth, max_epe_px=err_max, valid=valid)
        etiles.append(_tile(rgb, scale=scale, alt=f"{pipe} {what} endpoint error",
                            caption=f"{pipe}: mean EPE {format_value(mean)} px"))
    bar = _img(pictures.png_data_uri(pictures.epe_colorbar()), cls="bar", alt="EPE colour scale")
    etiles.append(f"<figure>{bar}<figcaption>endpoint error 0 \u2192 {err_max:.2f} px (largest 99th percentile "
                  "of the row; brighter is worse; black = no ground truth)</figcaption></figure>")
    out.append(f"<div class=\"gallery flow\">{''.join(etiles)}</div>")
    return "".join(out)


def _pictures_html(data: RunData, cells: pd.DataFrame) -> str:
    out = []
    for base in dict.fromkeys(cells["scene"].map(scene_base)):
        g, seq = _variant_for(data, cells, base, lambda d: bool(picture_frames(d)))
        if g.empty:
            out.append(f"<h3>{_e(base)}</h3>" + _missing("No cell saved estimated flow for pictures."))
            continue
        label = str(g["scene"].iloc[0])
        order = {p: i for i, p in enumerate(data.pipelines)}
        g = g.sort_values("pipeline", key=lambda s: s.map(order))
        cell_dirs = {r.pipeline: data.run_dir / "cells" / r.cell_id for r in g.itertuples(index=False)}
        frames = sorted(set().union(*(picture_frames(d) for d in cell_dirs.values())))
        for f in frames[:_MAX_PICTURE_FRAMES]:
            img, truth, valid = read_frame_truth(seq, f) if seq is not None else (None, None, None)
            camera = read_camera_flow(seq, f) if seq is not None else None
            totals = {p: read_cell_flow(d, f) for p, d in cell_dirs.items()}
            totals = {p: v for p, v in totals.items() if v is not None}
            locals_ = {p: read_cell_flow(d, f, local=True) for p, d in cell_dirs.items() if p in totals}
            if truth is not None and valid is not None and valid.shape != truth.shape[:2]:
                valid = None
            width = img.shape[1] if img is not None else next(iter(totals.values())).shape[1]
            scale = pictures.display_scale(width, min_width_px=_PICTURE_MIN_WIDTH_PX)
            where = f"{label}, seed {g['seed'].iloc[0]}, pair {f} \u2192 {f + 1}"
            out.append(f"<h3>{_e(where)}</h3>")
            if seq is None:
                out.append(_missing("Sequence folder not found in the cache dir: no frame or ground truth."))
            frame_tile = (_tile(img, scale=scale, alt="frame", caption=f"frame {f}") if img is not None
                          else _empty_tile("frame not found"))
            out.append("<h4>Total motion (camera and vehicles)</h4>"
                       '<p class="note">What the pipeline estimates before the global motion is taken out. The '
                       "camera's motion dominates it, so the field is nearly one colour; moving vehicles show "
                       "as small deviations.</p>")
            out.append(_flow_rows(truth, totals, valid, scale=scale, first_error_tile=frame_tile, what="total",
                                  floor_px=1e-6))
            true_local = truth - camera if truth is not None and camera is not None else None
            out.append("<h4>Local motion (global motion taken out)</h4>"
                       '<p class="note">Estimated: total flow minus the pipeline\'s global-motion field '
                       "(local_flow files of the cells). True: ground-truth flow minus the camera-induced flow "
                       "(flow/ minus flow_camera/), zero on the static world. A uniform tint on the background "
                       "is the global model's error; colour saturates at the largest true local motion, at "
                       f"least {_LOCAL_FLOOR_PX:g} px.</p>")
            if not any(v is not None for v in locals_.values()):
                out.append(_missing(f"The cells saved no local flow (local_flow_{f:06d}.flo; run folders written "
                                    "before it existed have none): only the true local motion is shown."))
                locals_ = {}
            if true_local is None and seq is not None:
                out.append(_missing("The sequence has no flow_camera/ file for this pair: no true local motion."))
            if true_local is not None or locals_:
                valid_tile = (_tile(pictures.mask_image(valid), scale=scale, alt="valid mask",
                                    caption="ground truth known (white)") if valid is not None
                              else _empty_tile("no valid mask"))
                out.append(_flow_rows(true_local, locals_, valid, scale=scale, first_error_tile=valid_tile,
                                      what="local", floor_px=_LOCAL_FLOOR_PX))
        out.append('<p class="note">Flow in the Middlebury colour coding, one maximum magnitude per row (the '
                   "largest true magnitude); estimates beyond it saturate. Small frames are enlarged by "
                   "pixel repetition, never interpolated.</p>")
    return "".join(out) or _missing("No pictures.")


def _per_pipeline(data: RunData, cells: pd.DataFrame, read) -> dict:
    """``read(cell_dir)`` of each pipeline's first cell in ``cells``, in the run's pipeline order; None left out."""
    out = {}
    for pipe in data.pipelines:
        r = cells[cells["pipeline"] == pipe]
        if len(r):
            value = read(data.run_dir / "cells" / r["cell_id"].iloc[0])
            if value is not None:
                out[pipe] = value
    return out


def _stabilisation_html(data: RunData, cells: pd.DataFrame, colors: dict[str, str]) -> str:
    out = []
    for base in dict.fromkeys(cells["scene"].map(scene_base)):
        g, seq = _variant_for(data, cells, base, lambda d: (d / "stabilisation.csv").is_file())
        if g.empty:
            out.append(f"<h3>{_e(base)}</h3>" + _missing("No stabilisation data (no stabilisation.csv)."))
            continue
        label, seed = str(g["scene"].iloc[0]), g["seed"].iloc[0]
        stabs = _per_pipeline(data, g, lambda cell_dir: read_stabilisation(cell_dir, seq))
        if not stabs:
            out.append(f"<h3>{_e(base)}</h3>" + _missing("stabilisation.csv lacks the cumulative / line columns."))
            continue
        thesis = next((p for p in stabs if "thesis" in p), next(iter(stabs)))
        svg, after = plots.stabilisation_figure(stabs[thesis], title=f"{label}, seed {seed}: {thesis}")
        cap = ("Top (thesis fig. 3.1): estimated cumulative shift, the sum of the pair-wise global shifts "
               "(blue), its least-squares flight line (orange) and the correction that moves each frame onto "
               "the line (green). ")
        cap += ("Bottom (fig. 3.2): after stabilisation, i.e. the true cumulative shift plus the applied "
                "correction (blue; a straight line when the jitter is removed exactly), its refitted line "
                "(orange) and the jitter left (green)." if after else
                "No true cumulative shift known: the after-stabilisation row is left out.")
        out.append(f"<h3>{_e(label)}, seed {_e(seed)}</h3><figure class=\"plot\">{svg}"
                   f"<figcaption>{_e(cap)}</figcaption></figure>")
        # pipelines that share a global-motion stage estimate the same jitter: draw it once
        groups: dict[str, pd.DataFrame] = {}
        for pipe, st in stabs.items():
            same = next((k for k, v in groups.items()
                         if np.allclose(v[["jit_x", "jit_y"]].to_numpy(float), st[["jit_x", "jit_y"]].to_numpy(float),
                                        equal_nan=True) and len(v) == len(st)), None)
            if same is None:
                groups[pipe] = st
            else:
                groups[f"{same} = {pipe}"] = groups.pop(same)
        group_colors = {k: colors[k.split(" = ")[0]] for k in groups}
        jsvg = plots.jitter_figure(groups, colors=group_colors, title=f"{label}: estimated vs true jitter")
        out.append(f"<figure class=\"plot\">{jsvg}<figcaption>Estimated jitter (cumulative shift minus "
                   "fitted line) per pipeline against the true jitter, detrended by its own least-squares line "
                   "so both are measured from a straight flight line.</figcaption></figure>")
    return "".join(out) or _missing("No stabilisation data.")


def _table41_html(tr: pd.DataFrame, *, pipe: str, vehicle: int) -> str:
    """Table 4.1 of the thesis for one point track: motion per frame in x and y, raw flow vs Kalman vs
    truth, and the position errors of both."""
    tr = tr.sort_values("frame")
    cols = [tr["x"].diff(), tr["x_filt"].diff(), tr["x_true"].diff(),
            tr["y"].diff(), tr["y_filt"].diff(), tr["y_true"].diff(),
            np.hypot(tr["x"] - tr["x_true"], tr["y"] - tr["y_true"]),
            np.hypot(tr["x_filt"] - tr["x_true"], tr["y_filt"] - tr["y_true"])]
    rows = []
    for i in range(len(tr)):
        rows.append(f'<tr><th scope="row">Frame {int(tr["frame"].iloc[i])}</th>'
                    + "".join(f'<td class="num">{format_value(float(c.iloc[i]))}</td>' for c in cols) + "</tr>")
    first = int(tr["frame"].iloc[0])
    caption = (f"In the style of thesis Table 4.1: {pipe}, point tracker seeded on vehicle {vehicle} "
               f"(track {tr['track_id'].iloc[0]}). \u0394x, \u0394y: image displacement since the previous "
               "frame [px] (camera and vehicle motion) of the raw optical-flow track, the Kalman track and the "
               "vehicle's true centre. Position error: distance [px] from the track to the vehicle's true "
               f"projected centre in the same frame (lower is better); frame {first} is the seed, taken from "
               "the truth, so its error is 0 by construction.")
    head = ("<tr><th rowspan=\"2\">Frame</th><th colspan=\"3\">\u0394x [px]</th><th colspan=\"3\">\u0394y [px]</th>"
            "<th colspan=\"2\">Position error [px] \u2193</th></tr><tr>"
            + "".join(f"<th>{h}</th>" for h in ("Optical flow", "Kalman filter", "True") * 2)
            + "<th>Optical flow</th><th>Kalman filter</th></tr>")
    return (f'<div class="scroll"><table class="t41"><caption class="note">{_e(caption)}</caption>'
            f"<thead>{head}</thead><tbody>{''.join(rows)}</tbody></table></div>")


def _table41_track(tracks: dict[str, pd.DataFrame], truth: pd.DataFrame | None
                   ) -> tuple[str, int, pd.DataFrame] | None:
    """The track Table 4.1 shows: the thesis pipeline's point track of the first seed vehicle that
    moves (not parked in the sequence's tracks.csv), else of the first seed vehicle."""
    pipe = next((p for p in tracks if "thesis" in p), next(iter(tracks)))
    t = tracks[pipe]
    pts = t[(t["source"] == "point") & t["seed_vehicle_id"].notna() & t[["x_true", "y_true"]].notna().all(axis=1)]
    if pts.empty:
        return None
    seeds = sorted(int(v) for v in pts["seed_vehicle_id"].unique())
    parked = set()
    if truth is not None and len(truth):
        parked = {int(v) for v, g in truth.groupby("vehicle_id") if (g["parked"] > 0).all()}
    vehicle = next((v for v in seeds if v not in parked), seeds[0])
    g = pts[pts["seed_vehicle_id"] == vehicle]
    return pipe, vehicle, g[g["track_id"] == g["track_id"].iloc[0]]


def _tracking_html(data: RunData, cells: pd.DataFrame, colors: dict[str, str]) -> str:
    out = []
    for base in dict.fromkeys(cells["scene"].map(scene_base)):
        g, seq = _variant_for(data, cells, base, lambda d: read_tracks(d) is not None)
        if g.empty:
            out.append(f"<h3>{_e(base)}</h3>" + _missing("No tracks in this scene's cells."))
            continue
        label, seed = str(g["scene"].iloc[0]), g["seed"].iloc[0]
        tracks = _per_pipeline(data, g, read_tracks)
        first = int(min(t["frame"].min() for t in tracks.values()))
        frame = read_frame_truth(seq, first)[0] if seq is not None else None
        truth = read_true_tracks(seq)
        out.append(f"<h3>{_e(label)}, seed {_e(seed)}</h3>")
        svg = plots.tracking_figure(frame, tracks, truth=truth, title=f"trajectories over frame {first}")
        multi = any((t["source"] != "point").any() for t in tracks.values())
        out.append(f'<figure class="plot">{svg}<figcaption>Ground truth: every vehicle\'s true centre (black on '
                   "white, v&lt;id&gt; at its first frame). Point tracker (blue; thesis 4.1): one track per seed "
                   "vehicle, started at its true centre in the first frame. "
                   + ("Multi-target tracker (orange-red, m&lt;id&gt; at the last frame): tracks born from "
                      "detections, not tied to a vehicle. " if multi else "")
                   + "Dashed, hollow: raw measurement (flow-followed point or detection centroid); solid, "
                   "filled: Kalman estimate. Positions are in each frame's own image coordinates (the camera "
                   f"moves), drawn over frame {first} for orientation."
                   + ("" if frame is not None else " Sequence frame not found: drawn without the image.")
                   + ("" if truth is not None else " Sequence tracks.csv not found: truth only for seed vehicles.")
                   + "</figcaption></figure>")
        have_truth = all(t[["x_true", "y_true"]].notna().all(axis=1).any() for t in tracks.values())
        if have_truth:
            errs = {}
            for pipe, t in tracks.items():
                t = t[(t["source"] == "point") & t[["x_true", "y_true"]].notna().all(axis=1)]
                e = pd.DataFrame({"frame": t["frame"],
                                  "err_raw": np.hypot(t["x"] - t["x_true"], t["y"] - t["y_true"]),
                                  "err_kalman": np.hypot(t["x_filt"] - t["x_true"], t["y_filt"] - t["y_true"])})
                errs[pipe] = e.groupby("frame", as_index=False).mean()
            esvg = plots.tracking_error_figure(errs, colors=colors, title="per-frame position error, point tracker")
            out.append(f'<figure class="plot">{esvg}<figcaption>Distance from the point tracker\'s position to '
                       "its seed vehicle's true centre per frame [px], mean over the seed vehicles. The "
                       "multi-target tracker is scored in the track metrics (region 'multi').</figcaption></figure>")
            chosen = _table41_track(tracks, truth)
            if chosen is not None:
                pipe, vehicle, t = chosen
                out.append(_table41_html(t, pipe=pipe, vehicle=vehicle))
        else:
            out.append(_missing("tracks.csv has no ground-truth columns: no position errors."))
    return "".join(out) or _missing("No tracks.")


def _failed_html(data: RunData) -> str:
    if data.failed.empty:
        return "<p>No cell failed.</p>"
    rows = []
    for r in data.failed.itertuples(index=False):
        tb = f"<details><summary>traceback</summary><pre>{_e(r.traceback)}</pre></details>" if r.traceback else ""
        rows.append(f'<tr><th scope="row">{_e(r.cell_id)}</th><td>{_e(r.scene)}</td><td>{_e(r.seed)}</td>'
                    f"<td>{_e(r.pipeline)}</td><td>{_e(r.status)}</td><td>{_e(r.error)}{tb}</td></tr>")
    return (f"<p>{len(data.failed)} cell(s) failed; their rows are left out of every aggregate.</p>"
            '<div class="scroll"><table class="failed"><thead><tr><th>Cell</th><th>Scene</th><th>Seed</th>'
            f"<th>Pipeline</th><th>Status</th><th>Error</th></tr></thead><tbody>{''.join(rows)}</tbody>"
            "</table></div>")


# ------------------------------------------------------------------------------ assembly

def build_report(run_dir: str | os.PathLike, *, baseline=None, gate_result=None) -> tuple[str, str]:
    """The HTML and Markdown text of the report of ``run_dir`` (see :func:`write_report`)."""
    data = load_run(run_dir)
    colors = plots.pipeline_colors(data.pipelines)
    cols = headline_columns(data)
    all_cols = headline_columns(data, include_others=True)
    cells = _cell_index(data)
    gate = gate_view(gate_result)
    diffs, note = (baseline_diffs(data, baseline) if baseline is not None else (None, ""))
    head_t = metric_table(data, data.ok, cols)
    bases = data.table["scene"].map(scene_base)
    scene_ts = {s: metric_table(data, rows, cols, all_rows=data.table[bases == s])
                for s, rows in per_scene_rows(data).items()}
    curves = sweep_curves(data)
    title = f"aerobench report: {data.run.get('suite') or Path(run_dir).name}"

    sec: dict[str, str] = {}
    sec["provenance"] = ('<div class="scroll"><table class="meta"><tbody>'
                         + "".join(f'<tr><th scope="row">{_e(k)}</th><td>{_e(v)}</td></tr>'
                                   for k, v in _provenance_rows(data))
                         + "</tbody></table></div>")
    sec["verdict"] = _verdict_html(gate, diffs, note)
    sec["headline"] = (
        '<p class="note">Pipelines side by side, pooled over every scene, sweep value and seed. '
        "\u2193 lower is better, \u2191 higher is better; the best value per column is shaded and starred "
        "(\u2605).</p>" + (_metric_table_html(head_t) if cols else _missing("None of the headline metrics is in "
                                                                          "the results table.")))
    sec["per-scene"] = "".join(f"<h3>{_e(s)}</h3>{_metric_table_html(t)}" for s, t in scene_ts.items()) \
        or _missing("No scenes.")
    region_parts = []
    for c in cols[:2]:
        wide = region_table(data, c.metric)
        if wide.shape[1] > 1:
            head = "".join(f"<th>{_e(w)}</th>" for w in wide.columns)
            body = "".join(f'<tr><th scope="row">{_e(p)}</th>'
                           + "".join(f'<td class="num">{format_value(float(v))}</td>' for v in row)
                           + "</tr>" for p, row in wide.iterrows())
            region_parts.append(f"<h3>{_e(c.label)} [{_e(c.unit)}] {c.arrow} by region / motion</h3>"
                                f'<div class="scroll"><table><thead><tr><th>Pipeline</th>{head}</tr></thead>'
                                f"<tbody>{body}</tbody></table></div>")
    sec["regions"] = ("".join(region_parts) + '<p class="note">Regions: all valid pixels, background, '
                      "vehicles, interior (away from boundaries). Motion total scores the whole flow; local "
                      "scores the flow left after the global motion.</p>") if region_parts else \
        _missing("The table has no region or motion breakdown.")
    sec["all-metrics"] = _metric_table_html(metric_table(data, data.ok, all_cols))
    sec["difficulty"] = _difficulty_html(data, curves, cols, colors)
    sec["pictures"] = _pictures_html(data, cells) if len(cells) else _missing("No completed cells.")
    sec["stabilisation"] = _stabilisation_html(data, cells, colors) if len(cells) else _missing("No completed cells.")
    sec["tracking"] = _tracking_html(data, cells, colors) if len(cells) else _missing("No completed cells.")
    sec["failed"] = _failed_html(data)

    nav = "".join(f'<li><a href="#{k}">{_e(v)}</a></li>' for k, v in _SECTIONS)
    body = "".join(f'<section id="{k}"><h2>{_e(v)}</h2>{sec[k]}</section>' for k, v in _SECTIONS)
    html_text = ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
                 '<meta name="viewport" content="width=device-width, initial-scale=1">'
                 f"<title>{_e(title)}</title><style>{_CSS}</style></head><body><main>"
                 f"<h1>{_e(title)}</h1><nav><ul>{nav}</ul></nav>{body}</main></body></html>\n")

    md = [f"# {_md(title)}", ""]
    md += [f"- **{_md(k)}**: {_md(v)}" for k, v in _provenance_rows(data)] + [""]
    if gate is not None:
        word = {True: "PASSED", False: "FAILED"}.get(gate["passed"], "UNKNOWN")
        extra = "" if gate["verdict"].strip().upper() in (word, word[:-2]) else f" ({_md(gate['verdict'])})"
        md += [f"## Gate: {word}{extra}", ""] + [f"- {_md(m)}" for m in gate["messages"]]
        md += [f"_{_md(n)}_" for n in gate["notes"]] + [""]
    if diffs is not None:
        md += ["## Against the baseline", ""]
        if note:
            md += [f"_{_md(note)}_", ""]
        if len(diffs):
            md += ["| Where | Pipeline | Metric | Current | Baseline | Diff | Change |", "|---|---|---|---|---|---|---|"]
            for r in diffs.itertuples(index=False):
                d = "\u2013" if not np.isfinite(r.diff) else f"{r.diff:+.4g}" + (
                    f" ({r.diff_pct:+.1f} %)" if np.isfinite(r.diff_pct) else "")
                md.append(f"| {_md(r.where)} | {_md(r.pipeline)} | {_md(r.metric)} | "
                          f"{format_value(r.current)} | {format_value(r.baseline)} | {d} | {r.change} |")
            md.append("")
    md += ["## Headline", "", "Pooled over every scene, sweep value and seed; best value in bold; "
           "\u2193 lower is better, \u2191 higher is better.", "", _metric_table_md(head_t)]
    md += ["## Per scene", ""]
    for s, t in scene_ts.items():
        md += [f"### {_md(s)}", "", _metric_table_md(t)]
    if curves and cols:
        md += ["## Difficulty", ""]
        c = cols[0]
        for param, agg in curves.items():
            sub = agg[agg["metric"] == c.metric]
            if sub.empty:
                continue
            xs = sorted(sub["sweep_value"].dropna().unique())
            md += [f"{c.label} [{c.unit}] {c.arrow} against {_md(param)}:", "",
                   "| Pipeline | " + " | ".join(f"{x:g}" for x in xs) + " |", "|---|" + "---|" * len(xs)]
            for p in data.pipelines:
                vals = {float(r.sweep_value): r.value for r in sub[sub["pipeline"] == p].itertuples()}
                if vals:
                    md.append(f"| {_md(p)} | " + " | ".join(format_value(vals.get(x, math.nan)) for x in xs) + " |")
            md.append("")
    else:
        md += ["## Difficulty", "", "_No parameter was swept in this run._", ""]
    md += ["## Failed cells", ""]
    if data.failed.empty:
        md += ["No cell failed.", ""]
    else:
        md += [f"- `{_md(r.cell_id)}` ({_md(r.pipeline)}): {_md(r.error)}" for r in data.failed.itertuples()] + [""]
    md += ["Figures (difficulty curves, flow pictures, stabilisation, tracking): see report.html.", ""]
    return html_text, "\n".join(md)


def write_report(run_dir: str | os.PathLike, *, baseline=None, gate_result=None,
                 out_dir: str | os.PathLike | None = None) -> dict[str, Path]:
    """Write ``report.html`` and ``report.md`` for the run folder ``run_dir``.

    Parameters
    ----------
    run_dir : path
        A run folder (run.json, results.parquet, cells/).
    baseline : dict, list or path, optional
        A loaded baseline JSON (or its path); diffs against the current pooled
        values are computed here (see :func:`reports.tables.baseline_records`).
    gate_result : mapping or object, optional
        A gate result (``passed`` / ``verdict`` / ``failures``); shown, not recomputed.
    out_dir : path, optional
        Where to write; default ``run_dir``.

    Returns
    -------
    dict
        ``{"html": Path, "md": Path}``.
    """
    html_text, md_text = build_report(run_dir, baseline=baseline, gate_result=gate_result)
    out = Path(out_dir) if out_dir is not None else Path(run_dir)
    paths = {"html": out / "report.html", "md": out / "report.md"}
    atomic_write_bytes(paths["html"], html_text.encode("utf-8"))
    atomic_write_bytes(paths["md"], md_text.encode("utf-8"))
    return paths
