"""The files of one cell folder (``RUN/cells/<cell_id>/``): one schema, written and read here.

The runner writes a cell's artifacts through this module and the reports read
them back through it, so the file names, the columns and the version live in one
place. Schema :data:`CELL_FORMAT` is stamped into ``cell.json`` (written last);
:func:`read_cell_info` refuses another version with a message naming it.

=======================  =====================================================================
file                     content
=======================  =====================================================================
``rows.parquet``         the cell's result rows (:mod:`harness.results` owns that schema)
``flow_NNNNNN.flo``      estimated total flow of picture pair NNNNNN, (H, W, 2) float32 px
``local_flow_NNNNNN.flo`` the same pair's local flow: ``flow_total - flow_global`` (px)
``stabilisation.csv``    :data:`STABILISATION_COLUMNS`, one row per frame, px
``tracks.csv``           :data:`TRACK_COLUMNS`, one row per frame x estimated track, px
``error.txt``            the traceback, only when the cell failed
``cell.json``            :data:`CELL_INFO_KEYS` + ``format``; written last
=======================  =====================================================================

Public functions
----------------
stabilisation_table(seq_estimate, camera) -> DataFrame     what stabilisation.csv holds
tracks_table(seq_estimate, true_tracks) -> DataFrame        what tracks.csv holds
write_pair_flows(cell_dir, index, flow_total, flow_global)
write_stabilisation / read_stabilisation, write_tracks / read_tracks
write_error / read_error, write_cell_info / read_cell_info
picture_pairs(cell_dir) -> [int], read_flow(cell_dir, index, *, local=False)
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from algorithms.jitter import cumulative_path
from scenes.formats import atomic_write_bytes, read_flo, write_flo

__all__ = [
    "CELL_FORMAT", "CELL_FILE", "STABILISATION_FILE", "TRACKS_FILE", "ERROR_FILE", "CELL_INFO_KEYS",
    "STABILISATION_COLUMNS", "TRACK_COLUMNS", "CellArtifactError",
    "stabilisation_table", "tracks_table", "write_pair_flows", "write_stabilisation", "read_stabilisation",
    "write_tracks", "read_tracks", "write_error", "read_error", "write_cell_info", "read_cell_info",
    "picture_pairs", "read_flow",
]

CELL_FORMAT = "aerobench-cell/1"
CELL_FILE = "cell.json"
STABILISATION_FILE = "stabilisation.csv"
TRACKS_FILE = "tracks.csv"
ERROR_FILE = "error.txt"
CELL_INFO_KEYS = ("cell_id", "config_hash", "status", "error", "rows", "elapsed_s", "scene", "seed", "pipeline")

# estimate beside truth per frame; the truth of the cumulative shift is the sum of the true pair
# shifts before the frame (thesis 3.2), the true jitter is camera.csv's
STABILISATION_COLUMNS = ("frame",
                         "cumulative_x_px", "cumulative_y_px", "flight_line_x_px", "flight_line_y_px",
                         "correction_x_px", "correction_y_px", "jitter_x_px", "jitter_y_px",
                         "true_cumulative_x_px", "true_cumulative_y_px", "true_jitter_x_px", "true_jitter_y_px")
# the pipeline's track columns (algorithms.pipeline SequenceEstimate.tracks) and, for point tracks,
# the seeded vehicle's true centre in the same frame (NaN for multi-target tracks)
TRACK_COLUMNS = ("frame", "track_id", "source", "seed_vehicle_id", "x_px", "y_px", "x_filt_px", "y_filt_px",
                 "x_pred_px", "y_pred_px", "true_x_px", "true_y_px", "true_visible")


class CellArtifactError(ValueError):
    """A cell file has another schema than this aerobench writes (the message names file and version)."""


def _flo_name(index: int, *, local: bool) -> str:
    return f"{'local_' if local else ''}flow_{int(index):06d}.flo"


# --------------------------------------------------------------------------- tables from estimates

def stabilisation_table(seq_estimate: Any, camera: pd.DataFrame | None) -> pd.DataFrame:
    """Per frame: the estimated cumulative shift, flight line, correction and jitter beside the truth.

    Parameters
    ----------
    seq_estimate : SequenceEstimate
        ``cumulative_px``, ``flight_line_px``, ``correction_px``, ``jitter_px``: (N, 2) float px;
        an array of another shape is written as NaN.
    camera : DataFrame or None
        The sequence's camera.csv (``global_dx_px, global_dy_px, jitter_x_px, jitter_y_px``), N rows;
        None for real footage: the truth columns are NaN and N is the estimate's length.

    Returns
    -------
    DataFrame
        :data:`STABILISATION_COLUMNS`, N rows, float px (``frame`` int).
    """
    truthless = camera is None
    if truthless:
        cum = getattr(seq_estimate, "cumulative_px", None)
        n = len(cum) if cum is not None else 0
        camera = pd.DataFrame({c: np.full(n, np.nan) for c in ("global_dx_px", "global_dy_px", "jitter_x_px",
                                                                 "jitter_y_px")})
    n = len(camera)
    out = pd.DataFrame({"frame": np.arange(n)})
    for name in ("cumulative_px", "flight_line_px", "correction_px", "jitter_px"):
        a = getattr(seq_estimate, name, None)
        a = np.asarray(a, dtype=float) if a is not None else np.full((n, 2), np.nan)
        if a.shape != (n, 2):
            a = np.full((n, 2), np.nan)
        stem = name.removesuffix("_px")
        out[f"{stem}_x_px"], out[f"{stem}_y_px"] = a[:, 0], a[:, 1]
    # cumulative truth of frame i: sum of the pair shifts before it (frame 0 at the origin)
    true_shifts = np.column_stack([pd.to_numeric(camera[f"global_d{a}_px"], errors="coerce").to_numpy(float)
                                   for a in ("x", "y")])
    true_cumulative = (np.full((n, 2), np.nan) if truthless
                       else cumulative_path(np.nan_to_num(true_shifts[:-1])))
    out["true_cumulative_x_px"], out["true_cumulative_y_px"] = true_cumulative[:, 0], true_cumulative[:, 1]
    out["true_jitter_x_px"] = camera["jitter_x_px"].to_numpy(float)
    out["true_jitter_y_px"] = camera["jitter_y_px"].to_numpy(float)
    return out[list(STABILISATION_COLUMNS)]


def tracks_table(seq_estimate: Any, true_tracks: pd.DataFrame | None) -> pd.DataFrame:
    """The estimated tracks, with the true centre of the seeded vehicle beside each point-track row.

    Parameters
    ----------
    seq_estimate : SequenceEstimate
        ``tracks``: frame, track_id, x_px, y_px, x_filt_px, y_filt_px, x_pred_px, y_pred_px, source,
        seed_vehicle_id.
    true_tracks : DataFrame or None
        The sequence's tracks.csv (frame, vehicle_id, x_px, y_px, visible).

    Returns
    -------
    DataFrame
        :data:`TRACK_COLUMNS` sorted by source, track_id, frame; empty when there is no track.
    """
    tracks = getattr(seq_estimate, "tracks", None)
    if tracks is None or len(tracks) == 0:
        return pd.DataFrame(columns=list(TRACK_COLUMNS))
    tracks = tracks.copy()
    for c in TRACK_COLUMNS:
        if c not in tracks.columns and not c.startswith("true_"):
            tracks[c] = np.nan
    tracks["seed_vehicle_id"] = pd.to_numeric(tracks["seed_vehicle_id"], errors="coerce").astype("Int64")
    if true_tracks is not None and len(true_tracks):
        t = true_tracks[["frame", "vehicle_id", "x_px", "y_px", "visible"]].rename(
            columns={"vehicle_id": "seed_vehicle_id", "x_px": "true_x_px", "y_px": "true_y_px",
                     "visible": "true_visible"})
        t["seed_vehicle_id"] = t["seed_vehicle_id"].astype("Int64")
        tracks = tracks.merge(t, on=["frame", "seed_vehicle_id"], how="left")
    for c in ("true_x_px", "true_y_px", "true_visible"):
        if c not in tracks.columns:
            tracks[c] = np.nan
    return tracks[list(TRACK_COLUMNS)].sort_values(["source", "track_id", "frame"], kind="stable").reset_index(drop=True)


# --------------------------------------------------------------------------- writers

def write_pair_flows(cell_dir: str | os.PathLike, index: int, flow_total: np.ndarray, flow_global: np.ndarray) -> None:
    """Save pair ``index``'s total flow and its local part ``flow_total - flow_global`` (both (H, W, 2) px).

    The total flow is dominated by the camera's motion; the local part shows the vehicles.
    """
    cell_dir = Path(cell_dir)
    total = np.asarray(flow_total, np.float32)
    write_flo(cell_dir / _flo_name(index, local=False), total)
    write_flo(cell_dir / _flo_name(index, local=True), total - np.asarray(flow_global, np.float32))


def _write_table(path: Path, table: pd.DataFrame, columns: tuple[str, ...]) -> None:
    missing = [c for c in columns if c not in table.columns]
    if missing:
        raise ValueError(f"{path.name}: the table lacks the column(s) {missing}; expected {list(columns)}")
    atomic_write_bytes(path, table[list(columns)].to_csv(index=False).encode())


def write_stabilisation(cell_dir: str | os.PathLike, table: pd.DataFrame) -> Path:
    """Write ``stabilisation.csv`` (:data:`STABILISATION_COLUMNS`, from :func:`stabilisation_table`)."""
    path = Path(cell_dir) / STABILISATION_FILE
    _write_table(path, table, STABILISATION_COLUMNS)
    return path


def write_tracks(cell_dir: str | os.PathLike, table: pd.DataFrame) -> Path:
    """Write ``tracks.csv`` (:data:`TRACK_COLUMNS`, from :func:`tracks_table`)."""
    path = Path(cell_dir) / TRACKS_FILE
    _write_table(path, table, TRACK_COLUMNS)
    return path


def write_error(cell_dir: str | os.PathLike, text: str) -> Path:
    """Write ``error.txt`` (the traceback of a failed cell)."""
    path = Path(cell_dir) / ERROR_FILE
    atomic_write_bytes(path, str(text).encode())
    return path


def write_cell_info(cell_dir: str | os.PathLike, info: Mapping) -> Path:
    """Write ``cell.json`` (last, it marks the folder complete): :data:`CELL_INFO_KEYS` and ``format``."""
    missing = [k for k in CELL_INFO_KEYS if k not in info]
    if missing:
        raise ValueError(f"cell.json: missing key(s) {missing}; expected {list(CELL_INFO_KEYS)}")
    path = Path(cell_dir) / CELL_FILE
    data = {**{k: info[k] for k in CELL_INFO_KEYS}, "format": CELL_FORMAT}
    atomic_write_bytes(path, (json.dumps(data, indent=2, sort_keys=True, default=str) + "\n").encode())
    return path


# --------------------------------------------------------------------------- readers

def read_cell_info(cell_dir: str | os.PathLike) -> dict | None:
    """``cell.json`` of a complete cell folder; None when it is absent or unreadable (a partial cell).

    Raises
    ------
    CellArtifactError
        The file is of another cell format than :data:`CELL_FORMAT`.
    """
    path = Path(cell_dir) / CELL_FILE
    try:
        info = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(info, dict):
        return None
    if info.get("format") != CELL_FORMAT:
        raise CellArtifactError(f"{path}: cell format {info.get('format')!r}, this aerobench reads "
                                f"{CELL_FORMAT!r}; re-run the suite into a new run folder")
    return info


def _read_table(path: Path, columns: tuple[str, ...]) -> pd.DataFrame | None:
    if not path.is_file():
        return None
    df = pd.read_csv(path)
    missing = [c for c in columns if c not in df.columns]
    if missing:
        raise CellArtifactError(f"{path}: lacks the column(s) {missing} of {CELL_FORMAT}; expected {list(columns)}")
    return df[list(columns)]


def read_stabilisation(cell_dir: str | os.PathLike) -> pd.DataFrame | None:
    """``stabilisation.csv`` (:data:`STABILISATION_COLUMNS`, float px); None when the cell has none."""
    df = _read_table(Path(cell_dir) / STABILISATION_FILE, STABILISATION_COLUMNS)
    if df is None:
        return None
    return df.astype({c: float for c in STABILISATION_COLUMNS if c != "frame"}).astype({"frame": int})


def read_tracks(cell_dir: str | os.PathLike) -> pd.DataFrame | None:
    """``tracks.csv`` (:data:`TRACK_COLUMNS`); None when the cell has none or it holds no track.

    ``track_id`` is unique only within a ``source`` ("point" or "multi"): a track is the
    pair ``(source, track_id)``. Positions float px; ``seed_vehicle_id`` NaN for multi tracks.
    """
    df = _read_table(Path(cell_dir) / TRACKS_FILE, TRACK_COLUMNS)
    if df is None or df.empty:
        return None
    df = df.copy()
    df["frame"] = df["frame"].astype(int)
    df["source"] = df["source"].astype(str)
    for c in TRACK_COLUMNS[3:]:
        df[c] = pd.to_numeric(df[c], errors="coerce").astype(float)
    return df.sort_values(["source", "track_id", "frame"], kind="stable").reset_index(drop=True)


def read_error(cell_dir: str | os.PathLike) -> str:
    """The traceback in ``error.txt``, "" when there is none."""
    path = Path(cell_dir) / ERROR_FILE
    return path.read_text(errors="replace").strip() if path.is_file() else ""


def picture_pairs(cell_dir: str | os.PathLike) -> list[int]:
    """Pair indices for which the cell saved its estimated total flow."""
    out = []
    for p in Path(cell_dir).glob("flow_*.flo"):
        tail = p.stem.removeprefix("flow_")
        if tail.isdigit():
            out.append(int(tail))
    return sorted(out)


def read_flow(cell_dir: str | os.PathLike, index: int, *, local: bool = False) -> np.ndarray | None:
    """The total (or, with ``local``, the local) flow the cell saved for pair ``index``; None if absent."""
    path = Path(cell_dir) / _flo_name(index, local=local)
    return read_flo(path) if path.is_file() else None
