"""report.html: one self-contained page rendered from a :class:`reports.model.ReportModel`.

No external resource: the stylesheet (``reports/report.css``, package data) is
inlined, figures are inline SVG, pictures base64 PNG. The output is
deterministic: the same run folder gives the same bytes (the date shown is the
run's, from run.json). Figures (pictures, stabilisation, tracking) read the
cell artifacts and sequences through :mod:`reports.load`.
"""

from __future__ import annotations

import functools
import html
import math
import re
from importlib import resources

import numpy as np
import pandas as pd

from harness.metrics import endpoint_error, position_error_px
from reports import pictures, plots
from reports.lkhs import LEVEL, N_BOOT
from reports.load import (RunData, open_scene_sequence, picture_frames, read_cell_flow, read_stabilisation,
                          read_tracks, read_true_tracks, scene_base)
from reports.model import LOCAL_VS_TOTAL, ReportModel
from reports.tables import Column, MetricTable, format_value

__all__ = ["SCENE_SECTIONS", "cell_index", "render_html", "render_html_bytes", "scene_block", "scene_blocks",
           "stylesheet"]

_MAX_PICTURE_FRAMES = 2
_PICTURE_MIN_WIDTH_PX = 320  # tiny suites render 160 x 120: enlarge pictures to at least this width
_LOCAL_FLOOR_PX = 1.0  # colour scale floor of the local-motion row (a scene may have no moving vehicle)



def stylesheet() -> str:
    """The report's CSS (``reports/report.css``, shipped as package data)."""
    return resources.files("reports").joinpath("report.css").read_text(encoding="utf-8")


_SECTIONS = [
    ("verdict", "Gate and baseline"),
    ("lk-vs-hs", "LK vs HS"),
    ("provenance", "What was run"),
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


_CELL = re.compile(r"<(td|th)\b([^>]*)>")


def _header_text(cell_html: str) -> str:
    """The visible label of a header cell: its text before any ``<small>`` note, tags dropped."""
    return re.sub(r"<[^>]+>", "", cell_html.split("<small>", 1)[0]).strip()


def _cards(table_html: str, labels: list[str] | None = None) -> str:
    """Mark a table for the narrow layout: each body cell gets ``data-label`` (its column's header, or
    ``labels`` in column order) so that under 600 px every row becomes a card of label: value lines
    (report.css) instead of a table wider than the screen."""
    head, sep, body = table_html.partition("</thead>")
    if not sep or "data-cards" in head or 'class="meta"' in head:
        return table_html
    if labels is None:
        last_row = head.rsplit("<tr>", 1)[-1]
        labels = [_header_text(c) for c in re.findall(r"<th\b[^>]*>(.*?)</th>", last_row, flags=re.S)]

    def row(m: re.Match) -> str:
        i = -1

        def cell(c: re.Match) -> str:
            nonlocal i
            i += 1
            if c.group(1) == "th" or i >= len(labels) or "data-label" in c.group(2):
                return c.group(0)
            return f'<{c.group(1)}{c.group(2)} data-label="{_e(labels[i])}">'

        return _CELL.sub(cell, m.group(0))

    body = re.sub(r"<tr>.*?</tr>", row, body, flags=re.S)
    tag_end = head.index(">", head.index("<table"))
    return head[:tag_end] + ' data-cards="1"' + head[tag_end:] + sep + body


def _missing(text: str) -> str:
    return f'<p class="missing">{_e(text)}</p>'


# ------------------------------------------------------------------------------ sections

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


def _gate_html(gate: dict) -> str:
    word, cls = ("PASSED", "pass") if gate["passed"] else ("FAILED", "fail")
    n = gate["counts"]
    out = [f'<div class="verdict {cls}">Gate: {word} ({n["checked"]} checked, {n["passed"]} passed, '
           f'{n["failed"]} failed, {n["skipped"]} skipped)</div>']
    msgs = [f"<li>{_e(m)}</li>" for m in gate["failures"]]
    if msgs:
        out.append("<ul>" + "".join(msgs[:8]) + "</ul>")
    if len(msgs) > 8:
        out.append(f"<details><summary>{len(msgs) - 8} more</summary><ul>{''.join(msgs[8:])}</ul></details>")
    out += [f'<p class="note">{_e(n)}</p>' for n in gate["notes"]]
    return "".join(out)


def _verdict_html(gate: dict | None, diffs: pd.DataFrame | None, note: str) -> str:
    out = [_gate_html(gate) if gate is not None else
           _missing("No gate verdict was given (aerobench gate RUN --baseline B --json V, then "
                    "aerobench report RUN --gate V).")]
    if diffs is None:
        out.append(_missing("No baseline was given: no comparison."))
    elif note:
        out.append(f'<p class="note">{_e(note)}</p>')
    if diffs is not None and len(diffs):
        rows = []
        for r in diffs.itertuples(index=False):
            cls = " worse" if r.change == "worse" else (" best" if r.change == "better" else "")
            pct = "" if not np.isfinite(r.diff_pct) else f" ({r.diff_pct:+.1f} %)"
            diff = "\u2013" if not np.isfinite(r.diff) else f"{r.diff:+.4g}{pct}"
            rows.append(f'<tr><td>{_e(r.where)}</td><th scope="row">{_e(r.pipeline)}</th>'
                        f"<td>{_e(r.metric)} [{_e(r.region)}, {_e(r.motion)}]</td><td>{_e(r.unit)}</td>"
                        f'<td class="num">{format_value(r.current)}</td><td class="num">{format_value(r.baseline)}</td>'
                        f'<td class="num{cls}">{_e(diff)}</td><td>{_e(r.change)}</td><td>{_e(r.rule)}</td></tr>')
        out.append('<div class="scroll"><table><thead><tr><th>Where</th><th>Pipeline</th><th>Metric</th>'
                   "<th>Unit</th><th>Current</th><th>Baseline</th><th>Diff (current \u2212 baseline)</th>"
                   f"<th>Change</th><th>Gate rule</th></tr></thead><tbody>{''.join(rows)}</tbody></table></div>")
    return "".join(out)


def _lkhs_html(model: ReportModel) -> str:
    if not model.lkhs:
        return _missing(model.lkhs_note)
    out = [f'<p class="note">{_e(LOCAL_VS_TOTAL)}</p>',
           f'<p class="note">Each row pairs the two pipelines frame pair by frame pair (same scene, seed and '
           f"frame) and gives the difference LK \u2212 HS of the pooled endpoint error (epe_mean, per pixel) "
           f"with a {LEVEL:.0%} percentile-bootstrap interval over the frame pairs ({N_BOOT} resamples, "
           f"seeded: the same results give the same interval). Negative: LK has the lower error. An interval "
           f"that contains 0 is no clear difference.</p>"]
    for pair in model.lkhs:
        out.append(f"<h3>{_e(pair.lk)} vs {_e(pair.hs)}</h3>")
        out.append("<ul class=\"verdicts\">" + "".join(f"<li>{_e(c.sentence)}</li>" for c in pair.comparisons)
                   + "</ul>")
        rows = []
        for c in pair.comparisons:
            cls = " best" if c.hi < 0 or c.lo > 0 else ""
            rows.append(f'<tr><th scope="row">{_e(c.region)}</th><td>{_e(c.motion)}</td>'
                        f'<td class="num">{format_value(c.lk_value)}</td><td class="num">{format_value(c.hs_value)}</td>'
                        f'<td class="num{cls}">{c.diff:+.3f}</td><td class="num">{c.lo:+.3f} to {c.hi:+.3f}</td>'
                        f'<td class="num">{c.n_lk_lower} / {c.n_units}</td></tr>')
        unit = _e(pair.comparisons[0].unit) if pair.comparisons else "px"
        out.append('<div class="scroll"><table class="lkhs"><thead><tr><th>Region</th><th>Motion</th>'
                   f"<th>LK [{unit}]</th><th>HS [{unit}]</th><th>LK \u2212 HS [{unit}]</th>"
                   f"<th>{LEVEL:.0%} CI</th><th>LK lower / pairs</th></tr></thead><tbody>{''.join(rows)}"
                   "</tbody></table></div>")
        per = pair.by_scene_seed
        if len(per):
            cols = [c for c in per.columns if c not in ("scene", "seed")]
            body = "".join(f'<tr><th scope="row">{_e(r["scene"])}, seed {_e(r["seed"])}</th>'
                           + "".join(f'<td class="num">{r[c]:+.3f}</td>' if np.isfinite(r[c]) else
                                     '<td class="num">\u2013</td>' for c in cols) + "</tr>"
                           for r in per.to_dict("records"))
            out.append(f"<details><summary>LK \u2212 HS [{unit}] per scene and seed</summary>"
                       '<div class="scroll"><table class="lkhs-scene"><thead><tr><th>Scene, seed</th>'
                       + "".join(f"<th>{_e(c)}</th>" for c in cols)
                       + f"</tr></thead><tbody>{body}</tbody></table></div></details>")
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


def _variant_for(data: RunData, cells: pd.DataFrame, base: str, want):
    """The first variant (scene label, seed) of scene ``base`` whose cells satisfy ``want(cell_dir)``."""
    sub = cells[cells["scene"].map(scene_base) == base]
    # the easiest setting first (lowest sweep value, then lowest seed): the base case the thesis shows
    sub = sub.assign(_x=pd.to_numeric(sub["sweep_value"], errors="coerce")).sort_values(
        ["_x", "sweep_value", "seed", "cell_id"], kind="stable").drop(columns="_x")
    for (label, seed), g in sub.groupby(["scene", "seed"], sort=False):
        dirs = [data.run_dir / "cells" / c for c in g["cell_id"]]
        if any(want(d) for d in dirs):
            return g, open_scene_sequence(data, scene=label, seed=seed)
    return sub.iloc[:0], None


def _img(uri: str, *, cls: str = "", alt: str) -> str:
    return f'<img class="{cls}" src="{uri}" alt="{_e(alt)}">'


# the legends are the same picture in every row: encoded once per process
@functools.cache
def _wheel_uri() -> str:
    return pictures.png_data_uri(pictures.wheel_legend())


@functools.cache
def _colorbar_uri() -> str:
    return pictures.png_data_uri(pictures.epe_colorbar())


@functools.cache
def _no_truth_uri() -> str:
    return pictures.png_data_uri(pictures.swatch(pictures.NO_TRUTH_RGB))


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
    tiles.append(f"<figure>{_img(_wheel_uri(), cls='legend', alt='colour wheel')}"
                 f"<figcaption>hue = direction (+x right, +y down), full saturation = {max_mag:.2f} px"
                 "</figcaption></figure>")
    out = [f"<div class=\"gallery flow\">{''.join(tiles)}</div>"]
    if truth is None or not present:
        return "".join(out)
    errs = []
    for flow in present:
        d = endpoint_error(flow, truth)
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
    bar = _img(_colorbar_uri(), cls="bar", alt="EPE colour scale")
    etiles.append(f"<figure>{bar}<figcaption>endpoint error 0 \u2192 {err_max:.2f} px (largest 99th percentile "
                  "of the row; brighter is worse; black = zero error)</figcaption></figure>")
    no_truth = _img(_no_truth_uri(), cls="swatch", alt="teal swatch")
    etiles.append(f"<figure>{no_truth}<figcaption>teal = no ground truth (occluded or leaving the view)"
                  "</figcaption></figure>")
    out.append(f"<div class=\"gallery flow\">{''.join(etiles)}</div>")
    return "".join(out)


def _scene_pictures(data: RunData, cells: pd.DataFrame, base: str, colors: dict[str, str]) -> str:
    """Scene ``base``'s pictures: frame, true and estimated flow, error maps of its first variant."""
    out = []
    g, seq = _variant_for(data, cells, base, lambda d: bool(picture_frames(d)))
    if g.empty:
        return f"<h3>{_e(base)}</h3>" + _missing("No cell saved estimated flow for pictures.")
    label = str(g["scene"].iloc[0])
    order = {p: i for i, p in enumerate(data.pipelines)}
    g = g.sort_values("pipeline", key=lambda s: s.map(order))
    cell_dirs = {r.pipeline: data.run_dir / "cells" / r.cell_id for r in g.itertuples(index=False)}
    frames = sorted(set().union(*(picture_frames(d) for d in cell_dirs.values())))
    for f in frames[:_MAX_PICTURE_FRAMES]:
        img, truth, valid, camera = None, None, None, None
        if seq is not None:
            img, pair = seq.frame(f), seq.pair_truth(f)  # None: real footage without flow truth for the pair
            if pair is not None:
                truth, valid, camera = pair.flow, pair.valid, pair.flow_camera
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
    return "".join(out)


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


def _scene_stabilisation(data: RunData, cells: pd.DataFrame, base: str, colors: dict[str, str]) -> str:
    """Scene ``base``'s stabilisation figures (thesis figs. 3.1, 3.2) and estimated vs true jitter."""
    out = []
    g, seq = _variant_for(data, cells, base, lambda d: (d / "stabilisation.csv").is_file())
    if g.empty:
        return f"<h3>{_e(base)}</h3>" + _missing("No stabilisation data (no stabilisation.csv).")
    label, seed = str(g["scene"].iloc[0]), g["seed"].iloc[0]
    stabs = _per_pipeline(data, g, read_stabilisation)
    if not stabs:
        return f"<h3>{_e(base)}</h3>" + _missing("stabilisation.csv lacks the cumulative / line columns.")
    # the thesis figure shows the pipeline with the thesis' straight flight line, if one ran
    thesis = next((p for p in stabs if (data.folder.pipelines.get(p, {}).get("jitter") or {}).get("model")
                   == "line"), next(iter(stabs)))
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
    return "".join(out)


def _table41_html(tr: pd.DataFrame, *, pipe: str, vehicle: int) -> str:
    """Table 4.1 of the thesis for one point track: motion per frame in x and y, raw flow vs Kalman vs
    truth, and the position errors of both."""
    tr = tr.sort_values("frame")
    cols = [tr["x"].diff(), tr["x_filt"].diff(), tr["x_true"].diff(),
            tr["y"].diff(), tr["y_filt"].diff(), tr["y_true"].diff(),
            pd.Series(position_error_px(tr["x"], tr["y"], tr["x_true"], tr["y_true"]), index=tr.index),
            pd.Series(position_error_px(tr["x_filt"], tr["y_filt"], tr["x_true"], tr["y_true"]), index=tr.index)]
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
    labels = ["Frame"] + [f"{d} {w}" for d in ("\u0394x", "\u0394y") for w in ("optical flow", "Kalman", "true")] \
        + ["error optical flow", "error Kalman"]
    return ('<div class="scroll">' + _cards(f'<table class="t41"><caption class="note">{_e(caption)}</caption>'
                                            f"<thead>{head}</thead><tbody>{''.join(rows)}</tbody></table>", labels)
            + "</div>")


def _table41_track(tracks: dict[str, pd.DataFrame], truth: pd.DataFrame | None, specs: dict[str, dict]
                   ) -> tuple[str, int, pd.DataFrame] | None:
    """The track Table 4.1 shows: the point track of the first seed vehicle that moves (not parked in
    the sequence's tracks.csv), else of the first seed vehicle, from the first pipeline whose point
    tracker follows the filtered flow as the thesis does (``tracking.point: true``), else the first."""
    pipe = next((p for p in tracks if (specs.get(p, {}).get("tracking") or {}).get("point") is True),
                next(iter(tracks)))
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


def _scene_tracking(data: RunData, cells: pd.DataFrame, base: str, colors: dict[str, str]) -> str:
    """Scene ``base``'s trajectories over its first frame, position errors and thesis Table 4.1."""
    out = []
    g, seq = _variant_for(data, cells, base, lambda d: read_tracks(d) is not None)
    if g.empty:
        return f"<h3>{_e(base)}</h3>" + _missing("No tracks in this scene's cells.")
    label, seed = str(g["scene"].iloc[0]), g["seed"].iloc[0]
    tracks = _per_pipeline(data, g, read_tracks)
    first = int(min(t["frame"].min() for t in tracks.values()))
    frame = seq.frame(first) if seq is not None else None
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
                              "err_raw": position_error_px(t["x"], t["y"], t["x_true"], t["y_true"]),
                              "err_kalman": position_error_px(t["x_filt"], t["y_filt"],
                                                              t["x_true"], t["y_true"])})
            errs[pipe] = e.groupby("frame", as_index=False).mean()
        esvg = plots.tracking_error_figure(errs, colors=colors, title="per-frame position error, point tracker")
        out.append(f'<figure class="plot">{esvg}<figcaption>Distance from the point tracker\'s position to '
                   "its seed vehicle's true centre per frame [px], mean over the seed vehicles. The "
                   "multi-target tracker is scored in the track metrics (region 'multi').</figcaption></figure>")
        chosen = _table41_track(tracks, truth, data.folder.pipelines)
        if chosen is not None:
            pipe, vehicle, t = chosen
            out.append(_table41_html(t, pipe=pipe, vehicle=vehicle))
    else:
        out.append(_missing("tracks.csv has no ground-truth columns: no position errors."))
    return "".join(out)


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



def _regions_html(model: ReportModel) -> str:
    parts = []
    for c in model.columns:
        wide = model.regions.get(c.metric)
        if wide is None:
            continue
        head = "".join(f"<th>{_e(w)}</th>" for w in wide.columns)
        body = "".join(f'<tr><th scope="row">{_e(p)}</th>'
                       + "".join(f'<td class="num">{format_value(float(v))}</td>' for v in row)
                       + "</tr>" for p, row in wide.iterrows())
        parts.append(f"<h3>{_e(c.label)} [{_e(c.unit)}] {c.arrow} by region / motion</h3>"
                     f'<div class="scroll"><table><thead><tr><th>Pipeline</th>{head}</tr></thead>'
                     f"<tbody>{body}</tbody></table></div>")
    if not parts:
        return _missing("The table has no region or motion breakdown.")
    return "".join(parts) + ('<p class="note">Regions: all valid pixels, background, vehicles, interior (away '
                             "from boundaries). Motion total and local: see LK vs HS.</p>")


# the sections drawn scene by scene, the report's pictures and figures: nearly all of its time.
# Each (section, scene) block depends only on the run folder, so blocks can be drawn apart, in
# any order, by other processes (reports.report), and joined here in the scenes' order.
_SCENE_SECTIONS = {"tracking": _scene_tracking, "pictures": _scene_pictures,
                   "stabilisation": _scene_stabilisation}  # the costliest first
_NO_SCENE_BLOCK = {"pictures": "No pictures.", "stabilisation": "No stabilisation data.", "tracking": "No tracks."}
SCENE_SECTIONS = tuple(_SCENE_SECTIONS)


def cell_index(data: RunData) -> pd.DataFrame:
    """One row per ok cell: cell_id, scene, scene_hash, seed, pipeline, sweep."""
    cols = ["cell_id", "scene", "scene_hash", "seed", "pipeline", "sweep_param", "sweep_value"]
    return data.ok[cols].drop_duplicates("cell_id").reset_index(drop=True)


def scene_blocks(cells: pd.DataFrame) -> list[tuple[str, str]]:
    """Every (section, scene base) block of :data:`SCENE_SECTIONS` that ``cells`` calls for, costliest
    section first."""
    bases = list(dict.fromkeys(cells["scene"].map(scene_base)))
    return [(section, base) for section in SCENE_SECTIONS for base in bases]


def scene_block(data: RunData, cells: pd.DataFrame, section: str, base: str) -> str:
    """The HTML of ``section`` (one of :data:`SCENE_SECTIONS`) for scene ``base``.

    Reads only the run folder and the sequences (``data.folder``, ``data.run_dir``,
    ``data.pipelines``), never the results table: ``data`` may come without its rows.
    """
    if section not in _SCENE_SECTIONS:
        raise ValueError(f"section: expected one of {', '.join(SCENE_SECTIONS)}, got {section!r}")
    return _SCENE_SECTIONS[section](data, cells, base, plots.pipeline_colors(data.pipelines))


def render_html(model: ReportModel, blocks: dict[tuple[str, str], str] | None = None) -> str:
    """The report page of ``model``.

    ``blocks``: the :func:`scene_block` of every (section, scene) of :func:`scene_blocks`, drawn
    beforehand (by other processes); None draws them here, one after the other.
    """
    return "".join(_page_parts(model, blocks))


def render_html_bytes(model: ReportModel, blocks: dict[tuple[str, str], str] | None = None) -> bytes:
    """:func:`render_html` encoded as UTF-8, the same bytes.

    Encoded part by part: the scene blocks (all but a few kB of a page that may reach 150 MB) are
    ASCII, and joined into one ``str`` with the few non-ASCII sections they would be copied into
    a string of 2 bytes a character, then encoded again, at the end of every report.
    """
    return b"".join(part.encode("utf-8") for part in _page_parts(model, blocks))


_TABLE = re.compile(r"<table\b.*?</table>", flags=re.S)


def _card_tables(text: str) -> str | None:
    """``text`` with each table marked by :func:`_cards`; None when a table may run on past its end
    (a ``<table`` after the last complete table, or ``text`` ending in the start of one)."""
    out, end = [], 0
    for m in _TABLE.finditer(text):
        out += [text[end:m.start()], _cards(m.group(0))]
        end = m.end()
    rest = text[end:]
    if "<table" in rest or any(rest.endswith("<table"[:k]) for k in range(1, 6)):
        return None
    return "".join([*out, rest]) if out else text


def _page_parts(model: ReportModel, blocks: dict[tuple[str, str], str] | None) -> list[str]:
    """The page of :func:`render_html` in pieces whose concatenation is the page (blocks not copied)."""
    data = model.data
    colors = plots.pipeline_colors(data.pipelines)
    cells = cell_index(data)
    keys = scene_blocks(cells)
    if blocks is None:
        blocks = {key: scene_block(data, cells, *key) for key in keys}
    by_section = {section: [blocks[key] for key in keys if key[0] == section]
                  or [_missing(_NO_SCENE_BLOCK[section])] for section in SCENE_SECTIONS}
    sec: dict[str, list[str]] = {}
    sec["verdict"] = [_verdict_html(model.gate, model.baseline, model.baseline_note)]
    sec["lk-vs-hs"] = [_lkhs_html(model)]
    sec["provenance"] = ['<div class="scroll"><table class="meta"><tbody>'
                         + "".join(f'<tr><th scope="row">{_e(k)}</th><td>{_e(v)}</td></tr>'
                                   for k, v in model.provenance)
                         + "</tbody></table></div>"]
    sec["headline"] = [
        '<p class="note">Pipelines side by side, pooled over every scene, sweep value and seed. '
        "\u2193 lower is better, \u2191 higher is better; the best value per column is shaded and starred "
        "(\u2605) when one pipeline alone holds it (pipelines that share a stage tie on its metrics: no star). "
        "Flow errors here are over all pixels, which the background dominates; LK vs HS above splits them.</p>"
        + (_metric_table_html(model.headline) if model.columns else
           _missing("None of the headline metrics is in the results table."))]
    sec["per-scene"] = ["".join(f"<h3>{_e(s)}</h3>{_metric_table_html(t)}" for s, t in model.per_scene.items())
                        or _missing("No scenes.")]
    sec["regions"] = [_regions_html(model)]
    sec["all-metrics"] = [_metric_table_html(model.all_metrics)
                          + '<p class="note">Every metric in the results table, tracking and stabilisation '
                          "metrics included (aerobench list explains each).</p>"]
    sec["difficulty"] = [_difficulty_html(data, model.curves, model.columns, colors)]
    for section in SCENE_SECTIONS:
        sec[section] = by_section[section] if len(cells) else [_missing("No completed cells.")]
    sec["failed"] = [_failed_html(data)]
    nav = "".join(f'<li><a href="#{k}">{_e(v)}</a></li>' for k, v in _SECTIONS)
    body = []
    for k, v in _SECTIONS:
        body += [f'<section id="{k}"><h2>{_e(v)}</h2>', *sec[k], "</section>"]
    # every table of the body becomes cards; part by part when no table runs on into the next part
    # (as it cannot: each part is whole elements), else over the joined body as one string
    carded = [_card_tables(part) for part in body]
    if any(part is None for part in carded):
        carded = [_TABLE.sub(lambda m: _cards(m.group(0)), "".join(body))]
    return ["<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            '<meta name="viewport" content="width=device-width, initial-scale=1">'
            f"<title>{_e(model.title)}</title><style>{stylesheet()}</style></head><body><main>"
            f"<h1>{_e(model.title)}</h1><nav><ul>{nav}</ul></nav>", *carded, "</main></body></html>\n"]
