"""Matplotlib figures of the report, returned as inline SVG text (deterministic bytes).

Every function takes plain tables (pandas) and returns an ``<svg>`` string with
no XML prolog, DOCTYPE or namespace URLs, ready to sit inside HTML. Output is
byte-identical between runs: a fixed ``svg.hashsalt``, no date metadata.
"""

from __future__ import annotations

import hashlib
import io
import re

import matplotlib

matplotlib.use("Agg")  # headless, set before pyplot is imported

import matplotlib.pyplot as plt  # noqa: E402
from matplotlib import patheffects  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.ticker import MaxNLocator  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from algorithms.jitter import least_squares_line  # noqa: E402
from reports.pictures import webp_data_uri  # noqa: E402

__all__ = ["pipeline_colors", "fig_to_svg", "difficulty_curves", "stabilisation_figure",
           "jitter_figure", "tracking_figure", "tracking_error_figure", "TRACKER_STYLE",
           "track_polylines"]

_RC = {
    "svg.hashsalt": "aerobench-report",
    "svg.fonttype": "none",      # text stays text: small files, browser fonts
    "font.size": 9,
    "axes.titlesize": 9,
    "axes.labelsize": 9,
    "legend.fontsize": 8,
    "axes.grid": True,
    "grid.alpha": 0.3,
    "figure.dpi": 100,
}
# Colour-blind-safe palette (Okabe-Ito), one colour per pipeline in suite order.
_PALETTE = ["#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#000000", "#F0E442"]


def pipeline_colors(pipelines: list[str]) -> dict[str, str]:
    """A fixed colour per pipeline, the same in every figure of a report."""
    return {p: _PALETTE[i % len(_PALETTE)] for i, p in enumerate(pipelines)}


def fig_to_svg(fig) -> str:
    """Render ``fig`` to SVG text fit for inline HTML and close it."""
    buf = io.StringIO()
    with matplotlib.rc_context(_RC):
        fig.savefig(buf, format="svg", metadata={"Date": None, "Creator": None})
    plt.close(fig)
    svg = buf.getvalue()
    svg = svg[svg.index("<svg"):]
    # the RDF metadata block names schema URLs and says nothing a reader needs
    svg = re.sub(r"<metadata>.*?</metadata>\s*", "", svg, flags=re.S)
    # namespaces are implied for <svg> inside HTML; dropping them keeps URLs out of the file
    svg = re.sub(r'\s+xmlns(:xlink)?="[^"]*"', "", svg, count=2)
    # let CSS size the figure: keep the aspect ratio through viewBox
    svg = re.sub(r'<svg([^>]*?) width="([^"]*)" height="[^"]*"',
                 r'<svg\1 style="width:100%;height:auto;max-width:\2"', svg, count=1)
    return svg.strip()


def svg_document(svg: str) -> tuple[bytes, float, float]:
    """An inline SVG of :func:`fig_to_svg` as a standalone ``.svg`` file: ``(bytes, width, height)``,
    the size in CSS px (the figure's points x 4/3).

    The namespaces an SVG file needs are put back, and the size CSS gave it becomes its own
    ``width`` and ``height``. Everything it shows must be inside it (an image in an SVG shown by
    ``<img>`` cannot load another file): the trajectories figure's frame is a data URI.
    """
    m = re.match(r'<svg style="width:100%;height:auto;max-width:[^"]*" viewBox="0 0 ([0-9.]+) ([0-9.]+)"', svg)
    if m is None:
        raise ValueError("svg: expected the <svg> of fig_to_svg (style width 100% and a viewBox)")
    w_pt, h_pt = float(m.group(1)), float(m.group(2))
    head = (f'<?xml version="1.0" encoding="utf-8"?>\n<svg xmlns="http://www.w3.org/2000/svg" '
            f'xmlns:xlink="http://www.w3.org/1999/xlink" width="{w_pt:g}pt" height="{h_pt:g}pt" '
            f'viewBox="0 0 {m.group(1)} {m.group(2)}"')
    return (head + svg[m.end():] + "\n").encode("utf-8"), w_pt * 4.0 / 3.0, h_pt * 4.0 / 3.0


def _figure(nrows: int, ncols: int, *, width_in: float, height_in: float):
    with matplotlib.rc_context(_RC):
        fig, axes = plt.subplots(nrows, ncols, figsize=(width_in, height_in), squeeze=False,
                                 layout="constrained")
    return fig, axes


def difficulty_curves(curves: pd.DataFrame, *, param: str, metrics: list[tuple[str, str]],
                      colors: dict[str, str]) -> str:
    """One panel per metric: pooled value against the swept parameter, one line per pipeline.

    Parameters
    ----------
    curves : DataFrame
        Columns ``pipeline, sweep_value, metric, value`` (pooled sum / count).
    metrics : list of (metric name, axis label with unit and direction)
    """
    n = len(metrics)
    ncols = min(3, n)
    nrows = int(np.ceil(n / ncols))
    with matplotlib.rc_context(_RC):
        fig, axes = _figure(nrows, ncols, width_in=3.3 * ncols, height_in=2.5 * nrows + 0.5)
        handles = {}
        for k, (metric, label) in enumerate(metrics):
            ax = axes[k // ncols][k % ncols]
            sub = curves[curves["metric"] == metric]
            for pipe, color in colors.items():
                g = sub[sub["pipeline"] == pipe].sort_values("sweep_value")
                if g.empty:
                    continue
                (h,) = ax.plot(g["sweep_value"].to_numpy(float), g["value"].to_numpy(float), "o-",
                               color=color, label=pipe, lw=1.5, ms=4)
                handles[pipe] = h
            ax.set_title(label)
            ax.set_xlabel(param)
        for k in range(n, nrows * ncols):
            axes[k // ncols][k % ncols].set_visible(False)
        if handles:
            fig.legend(list(handles.values()), list(handles.keys()), loc="outside lower center",
                       ncols=min(len(handles), 5), frameon=False)
    return fig_to_svg(fig)


def stabilisation_figure(stab: pd.DataFrame, *, title: str) -> tuple[str, bool]:
    """The thesis's figs. 3.1 and 3.2 for one cell, for the x and y shift.

    Top row (fig. 3.1): estimated cumulative shift (blue), its least-squares
    flight line (orange) and the correction (green). Bottom row (fig. 3.2): the
    same after stabilisation: the true cumulative shift plus the applied
    correction, its refitted line and the remaining difference.

    Returns the SVG and whether the bottom row used ground truth (False: no
    true cumulative shift known, bottom row left out).
    """
    t = stab["frame"].to_numpy(float)
    have_truth = bool(np.isfinite(stab[["cum_true_x", "cum_true_y"]].to_numpy(float)).any())
    nrows = 2 if have_truth else 1
    with matplotlib.rc_context(_RC):
        fig, axes = _figure(nrows, 2, width_in=7.5, height_in=2.4 * nrows + 0.4)
        for j, a in enumerate("xy"):
            ax = axes[0][j]
            # one legend serves both rows: each colour names its quantity in the top and the bottom row
            ax.plot(t, stab[f"cum_{a}"], color="#0072B2", lw=1.5,
                    label="estimated cumulative shift" + (" | after: true cumulative + correction" if have_truth else ""))
            ax.plot(t, stab[f"line_{a}"], color="#D55E00", lw=1.5,
                    label="fitted flight line" + (" | after: its refitted line" if have_truth else ""))
            ax.plot(t, stab[f"corr_{a}"], color="#009E73", lw=1.5,
                    label="correction" + (" | after: refitted line \u2212 after" if have_truth else ""))
            ax.set_title(f"before (fig. 3.1), {a} [px]")
            ax.set_xlabel("frame")
            ax.xaxis.set_major_locator(MaxNLocator(integer=True))
            if have_truth:
                after = stab[f"cum_true_{a}"].to_numpy(float) + stab[f"corr_{a}"].to_numpy(float)
                line = least_squares_line(after, t)
                ax = axes[1][j]
                ax.plot(t, after, color="#0072B2", lw=1.5)
                ax.plot(t, line, color="#D55E00", lw=1.5)
                ax.plot(t, line - after, color="#009E73", lw=1.5)
                ax.set_title(f"after stabilisation (fig. 3.2), {a} [px]")
                ax.set_xlabel("frame")
                ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        h, lab = axes[0][0].get_legend_handles_labels()
        fig.legend(h, lab, loc="outside lower center", ncols=1 if have_truth else 3, frameon=False)
        fig.suptitle(title)
    return fig_to_svg(fig), have_truth


def jitter_figure(jitters: dict[str, pd.DataFrame], *, colors: dict[str, str], title: str) -> str:
    """Estimated jitter per pipeline against the true jitter, x and y panels (px)."""
    with matplotlib.rc_context(_RC):
        fig, axes = _figure(1, 2, width_in=7.5, height_in=2.8)
        truth_drawn = False
        for j, a in enumerate("xy"):
            ax = axes[0][j]
            for pipe, stab in jitters.items():
                t = stab["frame"].to_numpy(float)
                ax.plot(t, stab[f"jit_{a}"], "-", color=colors.get(pipe, "#555555"), lw=1.2, label=pipe)
            first = next(iter(jitters.values()))
            t = first["frame"].to_numpy(float)
            true = first[f"jit_true_{a}"].to_numpy(float)
            if np.isfinite(true).sum() >= 2:
                # the estimate is measured from a fitted line: measure the truth the same way
                ax.plot(t, true - least_squares_line(true, t), "k--", lw=1.8, label="true jitter (detrended)")
                truth_drawn = True
            ax.set_title(f"jitter {a} [px]")
            ax.set_xlabel("frame")
            ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        h, lab = axes[0][0].get_legend_handles_labels()
        fig.legend(h, lab, loc="outside lower center", ncols=min(len(lab), 6), frameon=False)
        fig.suptitle(title + ("" if truth_drawn else " (true jitter unknown)"))
    return fig_to_svg(fig)


# Trackers by colour, measurement by line style: raw dashed with hollow markers, Kalman solid and filled.
TRACKER_STYLE = {
    "point": {"color": "#0072B2", "name": "point tracker (thesis 4.1)"},
    "multi": {"color": "#D55E00", "name": "multi-target tracker"},
}
_OTHER_TRACKER = {"color": "#CC79A7", "name": "tracker"}
# labels on a white box rather than a stroked halo: stroked text is saved as paths, not text
_LABEL_BOX = {"boxstyle": "round,pad=0.1", "fc": "white", "ec": "none", "alpha": 0.8}


def _zoom_box(xy: list[np.ndarray], frame: np.ndarray | None, *, margin_px: float = 12.0,
              min_span_px: float = 40.0) -> tuple[float, float, float, float]:
    """The part of the frame the points ``xy`` (arrays of shape (n, 2), px) cover, with a margin:
    ``x0, x1, y0, y1`` (px), at least ``min_span_px`` each way, inside the frame.

    The box does not keep the frame's aspect: vehicles on one road give a wide, low
    strip, which the figure draws at its own aspect and so enlarges.
    """
    pts = np.concatenate([np.asarray(p, float).reshape(-1, 2) for p in xy] or [np.zeros((0, 2))])
    pts = pts[np.isfinite(pts).all(axis=1)]
    if frame is None and not len(pts):
        return 0.0, 1.0, 0.0, 1.0
    if frame is not None:
        h, w = frame.shape[:2]
        if not len(pts):
            return -0.5, w - 0.5, -0.5, h - 0.5
    else:
        w = h = np.inf

    def side(v: np.ndarray, size: float) -> tuple[float, float]:
        lo, hi = float(v.min()) - margin_px, float(v.max()) + margin_px
        if hi - lo < min_span_px:
            mid = (lo + hi) / 2
            lo, hi = mid - min_span_px / 2, mid + min_span_px / 2
        if np.isfinite(size):
            span = min(hi - lo, size)
            lo = float(np.clip(lo, -0.5, size - 0.5 - span))
            hi = lo + span
        return lo, hi

    x0, x1 = side(pts[:, 0], w)
    y0, y1 = side(pts[:, 1], h)
    return x0, x1, y0, y1


def _truth_by_vehicle(tracks: dict[str, pd.DataFrame], truth: pd.DataFrame | None) -> dict[int, pd.DataFrame]:
    """Vehicle id -> its true centre per frame (``frame, x, y``): the sequence's tracks.csv,
    else the truth columns the point tracks carry."""
    if truth is not None and len(truth):
        return {int(v): g[["frame", "x", "y"]] for v, g in truth.groupby("vehicle_id", sort=True)}
    out: dict[int, pd.DataFrame] = {}
    for tr in tracks.values():
        pts = tr[(tr["source"] == "point") & tr["seed_vehicle_id"].notna() & tr["x_true"].notna()]
        for v, g in pts.groupby("seed_vehicle_id", sort=True):
            out.setdefault(int(v), g[["frame", "x_true", "y_true"]].set_axis(["frame", "x", "y"], axis=1))
    return out


def track_polylines(tr: pd.DataFrame) -> dict[tuple[str, int], pd.DataFrame]:
    """One polyline per track, ``(source, track_id) -> rows sorted by frame``.

    ``track_id`` alone is not a track: the point tracker and the multi-target
    tracker number their tracks from 0 each, and joining them draws lines
    across the frame.
    """
    return {(str(src), int(tid)): g.sort_values("frame", kind="stable")
            for (src, tid), g in tr.groupby(["source", "track_id"], sort=True)}


def _start_labels(vehicles: dict[int, pd.DataFrame], *, near_px: float = 6.0) -> list[tuple[str, tuple[float, float]]]:
    """``v<id>`` labels at each vehicle's first position; vehicles starting within ``near_px`` of
    each other share one label (``v1,3``) instead of printing over each other."""
    groups: list[tuple[list[int], tuple[float, float]]] = []
    for vid, g in vehicles.items():
        x, y = float(g["x"].iloc[0]), float(g["y"].iloc[0])
        for ids, (gx, gy) in groups:
            if np.hypot(x - gx, y - gy) < near_px:
                ids.append(vid)
                break
        else:
            groups.append(([vid], (x, y)))
    return [("v" + ",".join(str(v) for v in ids), xy) for ids, xy in groups]


def _frame_crop(frame: np.ndarray, x0: float, x1: float, y0: float, y1: float
                ) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    """The whole pixels of ``frame`` (H, W, 3) that the view ``x0..x1, y0..y1`` (px, pixel centres at integers)
    touches, and their ``extent`` for ``imshow`` (left, right, bottom, top)."""
    h, w = frame.shape[:2]
    c0, c1 = max(0, int(np.floor(x0 + 0.5))), min(w, int(np.ceil(x1 + 0.5)))
    r0, r1 = max(0, int(np.floor(y0 + 0.5))), min(h, int(np.ceil(y1 + 0.5)))
    return frame[r0:r1, c0:c1], (c0 - 0.5, c1 - 0.5, r1 - 0.5, r0 - 0.5)


def tracking_figure(frame: np.ndarray | None, tracks: dict[str, pd.DataFrame], *, title: str,
                    truth: pd.DataFrame | None = None) -> str:
    """Trajectories over a frame, one panel per pipeline, each track drawn on its own.

    Parameters
    ----------
    frame : (H, W, 3) uint8 or None
        The picture under the trajectories.
    tracks : pipeline -> DataFrame
        :func:`reports.load.read_tracks` tables; a track is ``(source, track_id)``.
    truth : DataFrame, optional
        :func:`reports.load.read_true_tracks` (every vehicle's true centre, px).

    Ground truth is black on a white halo, labelled ``v<vehicle id>`` at its first
    frame; each tracker has a colour (:data:`TRACKER_STYLE`), the raw measurement a
    dashed line with hollow markers, the Kalman estimate a solid line with filled
    markers. Multi-target tracks are labelled ``m<track id>`` at their last frame.
    """
    n = len(tracks)
    ncols = min(3, n)
    nrows = int(np.ceil(n / ncols))
    vehicles = _truth_by_vehicle(tracks, truth)
    every = [g[["x", "y"]].to_numpy(float) for g in vehicles.values()]
    for tr in tracks.values():
        every += [tr[["x", "y"]].to_numpy(float), tr[["x_filt", "y_filt"]].to_numpy(float)]
    x0, x1, y0, y1 = _zoom_box(every, frame)
    aspect = (y1 - y0) / (x1 - x0)
    halo = [patheffects.withStroke(linewidth=2.5, foreground="white")]
    labels = _start_labels(vehicles)
    polylines = {pipe: track_polylines(tr) for pipe, tr in tracks.items()}
    legend = {"ground truth (true vehicle centre)": {"color": "#000000", "ls": "-", "lw": 1.2, "path_effects": halo}}
    for lines in polylines.values():
        for source, _ in lines:
            st = TRACKER_STYLE.get(source, _OTHER_TRACKER)
            legend.setdefault(f"{st['name']}: raw", {"color": st["color"], "ls": "--", "marker": "o", "lw": 1.0,
                                                     "ms": 3.5, "mfc": "none", "mew": 0.9})
            legend.setdefault(f"{st['name']}: Kalman", {"color": st["color"], "ls": "-", "marker": "s", "lw": 1.4,
                                                        "ms": 2.5})
    crop = _frame_crop(frame, x0, x1, y0, y1) if frame is not None else None
    with matplotlib.rc_context(_RC):
        # rows tall enough for the zoomed image at its aspect plus a title, so panels never overlap
        fig, axes = _figure(nrows, ncols, width_in=3.8 * ncols, height_in=(3.3 * aspect + 0.55) * nrows + 0.9)
        # Constrained layout measures every artist and costs a second full draw at savefig. It is run on a
        # skeleton instead (limits, aspect, titles, labels, legend): the lines and the image it would measure
        # are clipped to their axes and cannot move the layout. The layout is then frozen and drawn once.
        for k, (pipe, lines) in enumerate(polylines.items()):
            ax = axes[k // ncols][k % ncols]
            ax.grid(False)
            ax.set_xlim(x0, x1)
            ax.set_ylim(y1, y0)  # image rows grow downwards
            if frame is not None:
                ax.set_aspect("equal")  # the frame's pixels square
                ax.set_facecolor("none")  # the frame goes under the axes (see below)
            for text, (x, y) in labels:
                ax.annotate(text, (x, y), xytext=(-3, 3), textcoords="offset points", ha="right", fontsize=7,
                            bbox=_LABEL_BOX)
            for (source, tid), g in lines.items():
                if source != "point":
                    st = TRACKER_STYLE.get(source, _OTHER_TRACKER)
                    ax.annotate(f"m{tid}", (float(g["x_filt"].iloc[-1]), float(g["y_filt"].iloc[-1])),
                                xytext=(3, -3), textcoords="offset points", va="top", fontsize=7,
                                color=st["color"], bbox=_LABEL_BOX)
            ax.set_title(f"{pipe} ({' + '.join(dict.fromkeys(s for s, _ in lines))})")
        for k in range(n, nrows * ncols):
            axes[k // ncols][k % ncols].set_visible(False)
        handles = [Line2D([], [], **style) for style in legend.values()]
        fig.legend(handles, list(legend.keys()), loc="outside lower center", ncols=3, frameon=False)
        fig.suptitle(title)
        fig.get_layout_engine().execute(fig)
        fig.set_layout_engine(None)  # no engine: savefig draws once
        for k, (pipe, lines) in enumerate(polylines.items()):
            ax = axes[k // ncols][k % ncols]
            for g in vehicles.values():
                ax.plot(g["x"], g["y"], "-", color="#000000", lw=1.2, path_effects=halo)
                ax.plot(g["x"].iloc[:1], g["y"].iloc[:1], "o", color="#000000", ms=3, path_effects=halo)
            for (source, tid), g in lines.items():
                st = TRACKER_STYLE.get(source, _OTHER_TRACKER)
                ax.plot(g["x"], g["y"], "--o", color=st["color"], lw=1.0, ms=3.5, mfc="none", mew=0.9)
                ax.plot(g["x_filt"], g["y_filt"], "-s", color=st["color"], lw=1.4, ms=2.5)
    svg = _compact_markers(fig_to_svg(fig))
    if crop is None:
        return svg
    # The frame is not drawn by matplotlib: its SVG backend would resample it per panel and PNG-encode each
    # copy at zlib's slowest settings. Instead its pixels are encoded once at their own size, defined once,
    # and shown under each panel's (transparent) axes in a nested <svg> whose viewBox is the panel's data
    # range: image pixel (col, row) covers col - 0.5 .. col + 0.5, as imshow draws it; the <svg> clips.
    img, (left, right, bottom, top) = crop
    uri = webp_data_uri(np.ascontiguousarray(img))  # in a file of its own, shown at about its size
    # ids are global in an HTML page holding several figures: named by the picture's content, so one name is
    # one picture (a fixed name would show the first figure's frame in every figure)
    frame_id = "trackframe-" + hashlib.sha1(uri.encode("ascii")).hexdigest()[:12]
    width_pt, height_pt = fig.get_size_inches() * 72.0
    uses = []
    for k in range(n):
        pos = axes[k // ncols][k % ncols].get_position()  # after savefig: the box the aspect left
        uses.append(f'<svg x="{pos.x0 * width_pt:.6f}" y="{(1.0 - pos.y1) * height_pt:.6f}" '
                    f'width="{pos.width * width_pt:.6f}" height="{pos.height * height_pt:.6f}" '
                    f'viewBox="{x0:.6f} {y0:.6f} {x1 - x0:.6f} {y1 - y0:.6f}" preserveAspectRatio="none">'
                    f'<use xlink:href="#{frame_id}"/></svg>')
    image = (f'<defs><image id="{frame_id}" x="{left:g}" y="{top:g}" width="{right - left:g}" '
             f'height="{bottom - top:g}" style="image-rendering:crisp-edges;image-rendering:pixelated" '
             f'preserveAspectRatio="none" xlink:href="{uri}"/></defs>')
    # under everything of the figure but its white background patch (the figure's first group)
    start = svg.index('<g id="figure_1">')
    at = svg.index("</g>", start) + len("</g>")
    return svg[:at] + image + "".join(uses) + svg[at:]


_USE_GROUP = re.compile(r'(<g clip-path="url\(#[^)]+\)")>((?:\s*<use [^>]*/>)+)(\s*</g>)')
_USE_STYLE = re.compile(r' style="([^"]*)"(?=/>)')
_COORD_ATTR = re.compile(r' (d|x|y)="([^"]*)"')
_LONG_DECIMAL = re.compile(r"(-?\d+\.\d{2})\d+")


def _compact_markers(svg: str) -> str:
    """The same drawing in fewer bytes: a marker per point and frame (``<use>``, thousands in a
    trajectories figure) made the figure about 1 MB for 7 pipelines and 20 frames.

    Each group of markers that share one style carries it once, on the group (SVG inheritance
    gives every ``<use>`` in it the same look), and coordinates of paths and markers are
    rounded to 0.01 pt, far below a screen pixel. Text, ids and the frame picture are left as
    they are.
    """
    def group(m: re.Match) -> str:
        styles = set(_USE_STYLE.findall(m.group(2)))
        if len(styles) != 1:
            return m.group(0)
        return f'{m.group(1)} style="{styles.pop()}">{_USE_STYLE.sub("", m.group(2))}{m.group(3)}'

    def coords(m: re.Match) -> str:
        return f' {m.group(1)}="{_LONG_DECIMAL.sub(lambda n: f"{float(n.group(0)):.2f}", m.group(2))}"'

    return _COORD_ATTR.sub(coords, _USE_GROUP.sub(group, svg))


def tracking_error_figure(errors: dict[str, pd.DataFrame], *, colors: dict[str, str], title: str) -> str:
    """Per-frame position error [px]: raw flow track dashed, Kalman track solid, per pipeline.

    ``errors[pipeline]`` has columns ``frame, err_raw, err_kalman`` (px, mean over tracks).
    """
    with matplotlib.rc_context(_RC):
        fig, axes = _figure(1, 1, width_in=7.5, height_in=2.8)
        ax = axes[0][0]
        for pipe, e in errors.items():
            c = colors.get(pipe, "#555555")
            ax.plot(e["frame"], e["err_raw"], "--", color=c, lw=1.0)
            ax.plot(e["frame"], e["err_kalman"], "-", color=c, lw=1.6, label=pipe)
        ax.set_xlabel("frame")
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_ylabel("position error [px] \u2193")
        ax.set_title("solid: Kalman track, dashed: raw flow track")
        h, lab = ax.get_legend_handles_labels()
        fig.legend(h, lab, loc="outside lower center", ncols=min(len(errors), 5), frameon=False)
        fig.suptitle(title)
    return fig_to_svg(fig)
