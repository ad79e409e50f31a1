"""Read a run folder for the report: run.json, the results table, cell artifacts, sequences.

Everything the report shows comes from here, and only from the files the run
folder contract of ``docs/architecture.md`` names. Aggregates are recomputed
from the ``sum`` and ``count`` columns (pooled), never as an average of
per-frame or per-cell averages.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from harness.results import aggregate, read_results
from scenes.formats import read_flo, read_png
from scenes.sequence import read_pair_flow

__all__ = [
    "RESULT_COLUMNS",
    "RunData",
    "load_run",
    "read_results_table",
    "pooled",
    "primary_rows",
    "scene_base",
    "find_sequence_dir",
    "read_stabilisation",
    "read_tracks",
    "read_true_tracks",
    "picture_frames",
    "read_frame_truth",
    "read_camera_flow",
    "read_cell_flow",
]

# The results-table columns of docs/architecture.md (harness.results adds kind, hist, schema_version).
RESULT_COLUMNS = (
    "cell_id", "scene", "scene_hash", "seed", "pipeline", "pipeline_hash", "sweep_param",
    "sweep_value", "frame", "track_id", "metric", "region", "motion", "value", "sum", "count",
    "unit", "higher_is_better", "status", "error", "config_hash", "git_commit", "git_dirty",
    "renderer", "machine",
)


def read_results_table(run_dir: str | os.PathLike) -> pd.DataFrame:
    """``RUN/results.parquet`` through :func:`harness.results.read_results` (schema checked)."""
    df = read_results(run_dir)
    missing = [c for c in RESULT_COLUMNS if c not in df.columns]
    if missing:
        raise ValueError(f"{run_dir}: results table lacks the columns {missing} of docs/architecture.md")
    return df


def pooled(df: pd.DataFrame, by: list[str]) -> pd.DataFrame:
    """Aggregate rows over everything not in ``by`` (+ metric, region, motion) from summed totals.

    Delegates to :func:`harness.results.aggregate`, which reduces each metric by
    its own rule (mean = sum / count, rms, rate in percent, total, quantiles from
    summed histograms): never an average of averages.
    """
    return aggregate(df, by=by)


def primary_rows(df: pd.DataFrame) -> pd.DataFrame:
    """For each metric, the rows of its headline view, relabelled ``region="all"``.

    Flow metrics: region ``all``, motion ``total``. Metrics without a ``total``
    motion (timing ``cost``, ``jitter``, ``global``): region ``all`` and their
    first motion. Metrics without region ``all`` (track metrics per tracker
    ``point`` / ``multi``): every region pooled.
    """
    parts = []
    for metric, g in df.groupby("metric", sort=False):
        r = g[g["region"] == "all"] if (g["region"] == "all").any() else g
        if (r["motion"] == "total").any():
            r = r[r["motion"] == "total"]
        else:
            r = r[r["motion"] == sorted(r["motion"].unique())[0]]
        parts.append(r.assign(region="all"))
    return pd.concat(parts, ignore_index=True) if parts else df.iloc[:0]


def scene_base(label: str) -> str:
    """The scene of a variant label: ``"urban[jitter_px=2]"`` -> ``"urban"``."""
    return str(label).split("[", 1)[0]


@dataclass
class RunData:
    """What a report needs from a run folder."""

    run_dir: Path
    run: dict
    table: pd.DataFrame          # every row of results.parquet
    ok: pd.DataFrame             # rows of cells that completed, with a metric
    failed: pd.DataFrame         # one row per failed cell: cell_id, scene, seed, pipeline, error
    pipelines: list[str]
    scenes: list[str]
    seeds: list
    metrics: list[str]
    cache_dir: Path | None
    notes: list[str] = field(default_factory=list)


def _clean_str(x) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return ""
    return str(x)


def _failed_cells(run_dir: Path, table: pd.DataFrame, run: dict) -> pd.DataFrame:
    """One row per failed cell: the error from the table, the traceback from ``error.txt``."""
    rows: dict[str, dict] = {}
    bad = table[table["status"].astype(str).str.lower() != "ok"]
    for cell_id, g in bad.groupby("cell_id", sort=True):
        first = g.iloc[0]
        errors = [e for e in g["error"].map(_clean_str).unique() if e]
        rows[str(cell_id)] = dict(cell_id=str(cell_id), scene=_clean_str(first["scene"]),
                                  seed=_clean_str(first["seed"]), pipeline=_clean_str(first["pipeline"]),
                                  status=_clean_str(first["status"]), error="; ".join(errors), traceback="")
    cells_dir = run_dir / "cells"
    if cells_dir.is_dir():
        for err in sorted(cells_dir.glob("*/error.txt")):
            cid = err.parent.name
            if cid.startswith("."):
                continue
            entry = rows.setdefault(cid, dict(cell_id=cid, scene="", seed="", pipeline="", status="failed",
                                              error="", traceback=""))
            entry["traceback"] = err.read_text(errors="replace").strip()
            if not entry["error"] and entry["traceback"]:
                entry["error"] = entry["traceback"].splitlines()[-1]
    return pd.DataFrame(list(rows.values()),
                        columns=["cell_id", "scene", "seed", "pipeline", "status", "error", "traceback"])


def _ordered_unique(values) -> list:
    seen = []
    for v in values:
        if v is None or (isinstance(v, float) and math.isnan(v)) or v in seen:
            continue
        seen.append(v)
    return seen


def load_run(run_dir: str | os.PathLike) -> RunData:
    """Read ``RUN/run.json`` and ``RUN/results.parquet``; see :class:`RunData`."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise FileNotFoundError(f"{run_dir}: not a run folder")
    run_json = run_dir / "run.json"
    run: dict = {}
    if run_json.is_file():
        try:
            run = json.loads(run_json.read_text())
        except json.JSONDecodeError as exc:
            raise ValueError(f"{run_json}: not valid JSON ({exc})") from exc
        if not isinstance(run, dict):
            raise ValueError(f"{run_json}: expected a JSON object, got {type(run).__name__}")
    table = read_results_table(run_dir)
    ok = table[(table["status"] == "ok") & ~table["metric"].isin(["", "cell_failed"])].copy()
    failed = _failed_cells(run_dir, table, run)
    ok = ok[~ok["cell_id"].astype(str).isin(set(failed["cell_id"]))]
    # order of first appearance in the suite (run.json), then the table
    suite = run.get("resolved_suite") or {}
    suite_pipes = []
    if isinstance(suite, dict):
        p = suite.get("pipelines")
        suite_pipes = list(p.keys()) if isinstance(p, dict) else [x.get("name") if isinstance(x, dict) else x
                                                                  for x in (p or [])]
    pipelines = _ordered_unique([*(str(x) for x in suite_pipes if x), *table["pipeline"].dropna().astype(str)])
    pipelines = [p for p in pipelines if p in set(table["pipeline"].astype(str))]
    scenes = _ordered_unique(table["scene"].dropna().astype(str))
    seeds = sorted(_ordered_unique(table["seed"].dropna().tolist()))
    metrics = _ordered_unique(ok["metric"].astype(str))
    cache = run.get("cache_dir")
    cache_dir = None
    if cache:
        cache_dir = Path(cache)
        if not cache_dir.is_absolute():
            cache_dir = run_dir / cache_dir
    return RunData(run_dir=run_dir, run=run, table=table, ok=ok, failed=failed, pipelines=pipelines,
                   scenes=scenes, seeds=seeds, metrics=metrics, cache_dir=cache_dir)


# ---------------------------------------------------------------- cell artifacts and sequences

def find_sequence_dir(data: RunData, *, scene: str, scene_hash: str | None) -> Path | None:
    """The sequence folder of a scene: ``run.json`` cell entry, else ``cache_dir/<scene_hash>``.

    A folder counts only when it holds ``meta.json`` or ``frames/``.
    """
    candidates: list[Path] = []
    for cell in data.run.get("cells", []) or []:
        if isinstance(cell, dict) and str(cell.get("scene")) == scene:
            for key in ("sequence_dir", "sequence"):
                if cell.get(key):
                    p = Path(str(cell[key]))
                    candidates.append(p if p.is_absolute() else (data.cache_dir or data.run_dir) / p)
    if data.cache_dir is not None and scene_hash:
        candidates.append(data.cache_dir / str(scene_hash))
        if data.cache_dir.is_dir():
            candidates += sorted(p for p in data.cache_dir.glob(f"*{scene_hash}*") if p.is_dir())
    for p in candidates:
        if (p / "meta.json").is_file() or (p / "frames").is_dir():
            return p
    if data.cache_dir is not None and scene_hash and data.cache_dir.is_dir():
        # folders named otherwise: match the hash recorded in meta.json
        for meta in sorted(data.cache_dir.glob("*/meta.json")):
            try:
                m = json.loads(meta.read_text())
            except (OSError, ValueError):
                continue
            if isinstance(m, dict) and scene_hash in (m.get("scene_hash"), m.get("spec_hash")):
                return meta.parent
    return None


def _read_csv(path: Path) -> pd.DataFrame | None:
    if not path.is_file():
        return None
    df = pd.read_csv(path)
    return df if not df.empty else None


def _first_col(df: pd.DataFrame, *names: str) -> str | None:
    for n in names:
        if n in df.columns:
            return n
    return None


def read_stabilisation(cell_dir: Path, seq_dir: Path | None) -> pd.DataFrame | None:
    """``cells/<id>/stabilisation.csv`` in a fixed shape, truth filled in from ``camera.csv``.

    Returns columns ``frame`` and, for ``a`` in ``x, y``: ``cum_a`` (estimated
    cumulative shift), ``line_a`` (fitted flight line), ``corr_a``
    (correction), ``jit_a`` (estimated jitter), ``cum_true_a``, ``jit_true_a``
    (NaN when unknown), all in px.
    """
    df = _read_csv(cell_dir / "stabilisation.csv")
    if df is None or "frame" not in df.columns:
        return None
    out = pd.DataFrame({"frame": df["frame"].astype(int)})
    cam = _read_csv(seq_dir / "camera.csv") if seq_dir is not None else None
    for a in ("x", "y"):
        cum = _first_col(df, f"cumulative_{a}_px")
        line = _first_col(df, f"line_{a}_px", f"flight_line_{a}_px")
        corr = _first_col(df, f"correction_{a}_px")
        jit = _first_col(df, f"jitter_{a}_px")
        if cum is None or line is None:
            return None
        out[f"cum_{a}"] = df[cum].to_numpy(float)
        out[f"line_{a}"] = df[line].to_numpy(float)
        out[f"jit_{a}"] = df[jit].to_numpy(float) if jit else out[f"cum_{a}"] - out[f"line_{a}"]
        out[f"corr_{a}"] = df[corr].to_numpy(float) if corr else -out[f"jit_{a}"]
        cum_t = _first_col(df, f"true_cumulative_{a}_px")
        jit_t = _first_col(df, f"true_jitter_{a}_px")
        out[f"cum_true_{a}"] = df[cum_t].to_numpy(float) if cum_t else np.nan
        out[f"jit_true_{a}"] = df[jit_t].to_numpy(float) if jit_t else np.nan
        if cam is not None and "frame" in cam.columns:
            cam_i = cam.set_index("frame")
            if cum_t is None and f"global_d{a}_px" in cam.columns:
                # cumulative true shift of frame i = sum of pair shifts 0..i-1 (eq. of thesis 3.2)
                d = cam_i[f"global_d{a}_px"].astype(float).fillna(0.0)
                cum_true = pd.Series(np.concatenate([[0.0], np.cumsum(d.to_numpy())[:-1]]), index=d.index)
                out[f"cum_true_{a}"] = out["frame"].map(cum_true).to_numpy(float)
            if jit_t is None and f"jitter_{a}_px" in cam.columns:
                out[f"jit_true_{a}"] = out["frame"].map(cam_i[f"jitter_{a}_px"].astype(float)).to_numpy(float)
    return out


def read_tracks(cell_dir: Path) -> pd.DataFrame | None:
    """``cells/<id>/tracks.csv`` in a fixed shape, one row per frame x estimated track.

    The runner's columns ``source, seed_vehicle_id, x_px, y_px, x_filt_px, y_filt_px,
    true_x_px, true_y_px`` are renamed to ``source, seed_vehicle_id, x, y, x_filt, y_filt,
    x_true, y_true`` (px; NaN where the file has no such column or value). ``track_id``
    is unique only within a ``source`` (the point tracker's and the multi-target
    tracker's ids both start at 0): a track is the pair ``(source, track_id)``.
    Files without ``source`` are taken as the point tracker's. The truth columns are
    filled for point tracks only (the vehicle the track was seeded on).
    """
    df = _read_csv(cell_dir / "tracks.csv")
    if df is None or "frame" not in df.columns:
        return None
    names = {
        "x": ("x_px",), "y": ("y_px",), "x_filt": ("x_filt_px",), "y_filt": ("y_filt_px",),
        "x_true": ("true_x_px",), "y_true": ("true_y_px",),
    }
    out = pd.DataFrame({
        "frame": df["frame"].astype(int),
        "source": df["source"].fillna("point").astype(str) if "source" in df.columns else "point",
        "track_id": df["track_id"] if "track_id" in df.columns else 0,
        "seed_vehicle_id": (pd.to_numeric(df["seed_vehicle_id"], errors="coerce")
                            if "seed_vehicle_id" in df.columns else np.nan),
    })
    for k, cands in names.items():
        c = _first_col(df, *cands)
        out[k] = pd.to_numeric(df[c], errors="coerce").to_numpy(float) if c else np.nan
    if out[["x", "y"]].isna().all().all():
        return None
    return out.sort_values(["source", "track_id", "frame"], kind="stable").reset_index(drop=True)


def read_true_tracks(seq_dir: Path | None) -> pd.DataFrame | None:
    """The sequence's ``tracks.csv`` (every vehicle's projected centre) as ``frame, vehicle_id,
    x, y, parked`` for the frames where the vehicle is visible; None when absent."""
    if seq_dir is None:
        return None
    df = _read_csv(seq_dir / "tracks.csv")
    if df is None or not {"frame", "vehicle_id", "x_px", "y_px"} <= set(df.columns):
        return None
    if "visible" in df.columns:
        df = df[df["visible"].astype(float) > 0]
    return pd.DataFrame({"frame": df["frame"].astype(int), "vehicle_id": df["vehicle_id"].astype(int),
                         "x": df["x_px"].astype(float), "y": df["y_px"].astype(float),
                         "parked": df["parked"].astype(int) if "parked" in df.columns else 0}
                        ).sort_values(["vehicle_id", "frame"], kind="stable").reset_index(drop=True)


def picture_frames(cell_dir: Path) -> list[int]:
    """Frames for which the cell saved its estimated flow (``flow_NNNNNN.flo``)."""
    frames = []
    for p in cell_dir.glob("flow_*.flo"):
        tail = p.stem.split("_", 1)[1]
        if tail.isdigit():
            frames.append(int(tail))
    return sorted(frames)


def read_cell_flow(cell_dir: Path, frame: int, *, local: bool = False) -> np.ndarray | None:
    """The flow a cell saved for pair ``frame``: ``flow_NNNNNN.flo`` (total) or, with ``local``,
    ``local_flow_NNNNNN.flo`` (total minus the global model); None when the cell has no such file
    (run folders written before local flow was saved have none)."""
    p = cell_dir / f"{'local_' if local else ''}flow_{frame:06d}.flo"
    return read_flo(p) if p.is_file() else None


def read_camera_flow(seq_dir: Path, frame: int) -> np.ndarray | None:
    """The camera-induced part of the true flow of pair ``frame`` (either flow format), or None."""
    return read_pair_flow(seq_dir, frame)[1]


def read_frame_truth(seq_dir: Path, frame: int) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray | None]:
    """Frame ``frame`` (uint8 RGB), its ground-truth flow and valid mask, each None if absent."""
    name = f"{frame:06d}"
    img = read_png(seq_dir / "frames" / f"{name}.png") if (seq_dir / "frames" / f"{name}.png").is_file() else None
    if img is not None and img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    flow = read_pair_flow(seq_dir, frame)[0]
    valid = None
    if (seq_dir / "valid" / f"{name}.png").is_file():
        valid = read_png(seq_dir / "valid" / f"{name}.png") > 0
    return img, flow, valid
