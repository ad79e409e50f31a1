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
``mot_<tracker>.txt``    each tracker's tracks in MOTChallenge format (:data:`MOT_COLUMNS`), for
                         TrackEval or py-motmetrics; ``<tracker>`` is the tracks' ``source``
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
mot_table(tracks) / mot_truth_table(true_tracks) -> DataFrame   MOTChallenge rows
write_mot_tracks(cell_dir, tracks) -> [Path], write_mot(path, table), read_mot(path), read_mot_tracks(cell_dir)

MOTChallenge export: one line per frame x track, ``frame,id,bb_left,bb_top,bb_width,bb_height,conf,x,y,z``
(frames 1-based; boxes as :func:`scenes.formats.mot_box` writes them, ``bb_left = x0 + 1.5``, ``bb_width =
x1 - x0``: MOTChallenge's first pixel is 1 and its bb_left a box's edge, our pixel 0 is centred on 0; ``x, y,
z`` = -1, no world coordinates). A track with a box (``bbox_*_px``, e.g. the multi-target
tracker's) is written with it; a point track (the thesis point tracker, or any tracker without a box)
gets a fixed :data:`MOT_POINT_BOX_PX` x :data:`MOT_POINT_BOX_PX` px box centred on its filtered
position, a carrier only: :func:`read_mot_tracks` gives a box of exactly that size back as a point (the
box centre, no box), so that our metrics score it as a point; an IoU-based scorer would not match such
a box to a vehicle.
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
from harness.metrics.objects import low_visibility
from scenes.formats import atomic_write_bytes, box_of_mot, mot_box, read_flo, write_flo

__all__ = [
    "CELL_FORMAT", "CELL_FILE", "STABILISATION_FILE", "TRACKS_FILE", "ERROR_FILE", "CELL_INFO_KEYS",
    "STABILISATION_COLUMNS", "TRACK_COLUMNS", "CellArtifactError",
    "stabilisation_table", "tracks_table", "write_pair_flows", "write_stabilisation", "read_stabilisation",
    "write_tracks", "read_tracks", "write_error", "read_error", "write_cell_info", "read_cell_info",
    "picture_pairs", "read_flow",
    "MOT_COLUMNS", "MOT_POINT_BOX_PX", "mot_file", "mot_table", "mot_truth_table", "write_mot", "write_mot_tracks",
    "read_mot", "read_mot_tracks",
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
# and the box of a tracker that has one (NaN for the point tracker; absent from older cells: read as NaN)
TRACK_COLUMNS = ("frame", "track_id", "source", "seed_vehicle_id", "x_px", "y_px", "x_filt_px", "y_filt_px",
                 "x_pred_px", "y_pred_px", "true_x_px", "true_y_px", "true_visible",
                 "bbox_x0_px", "bbox_y0_px", "bbox_x1_px", "bbox_y1_px")

MOT_COLUMNS = ("frame", "id", "bb_left", "bb_top", "bb_width", "bb_height", "conf", "x", "y", "z")
MOT_POINT_BOX_PX = 4.0  # side of the carrier box a point track is exported with, px
_BOX = ("bbox_x0_px", "bbox_y0_px", "bbox_x1_px", "bbox_y1_px")


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
        seed_vehicle_id, and the box ``bbox_x0_px .. bbox_y1_px`` (NaN when absent).
    true_tracks : DataFrame or None
        The sequence's tracks.csv (frame, vehicle_id, x_px, y_px, visible); ``true_visible`` is 1 where
        the vehicle is in view as the metrics score it (visible, and not under half visible:
        :func:`harness.metrics.objects.low_visibility`).

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
        # in view as the metrics score it: a row under half visible (objects.low_visibility) is no object
        seen = (pd.to_numeric(true_tracks["visible"], errors="coerce").fillna(0).to_numpy() != 0) & ~low_visibility(
            true_tracks)
        t = true_tracks[["frame", "vehicle_id", "x_px", "y_px"]].assign(visible=seen.astype(np.int64)).rename(
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
    """Write ``tracks.csv`` (:data:`TRACK_COLUMNS`, from :func:`tracks_table`; box columns absent: NaN)."""
    path = Path(cell_dir) / TRACKS_FILE
    missing_box = [c for c in _BOX if c not in table.columns]
    if missing_box:
        table = table.assign(**{c: np.nan for c in missing_box})
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


def _read_table(path: Path, columns: tuple[str, ...], optional: tuple[str, ...] = ()) -> pd.DataFrame | None:
    if not path.is_file():
        return None
    df = pd.read_csv(path)
    for c in optional:
        if c not in df.columns:
            df[c] = np.nan
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
    df = _read_table(Path(cell_dir) / TRACKS_FILE, TRACK_COLUMNS, optional=_BOX)
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


# --------------------------------------------------------------------------- MOTChallenge export

def mot_file(tracker: str) -> str:
    """The file name of a tracker's MOTChallenge export: ``mot_<tracker>.txt``."""
    name = str(tracker)
    if not name or not all(c.isalnum() or c in "-_" for c in name):
        raise ValueError(f"tracker: expected a name of letters, digits, '-' or '_', got {name!r}")
    return f"mot_{name}.txt"


def _mot_rows(frame, ids, x0, y0, x1, y1, conf) -> pd.DataFrame:
    left, top, width, height = mot_box(x0, y0, x1, y1)
    return pd.DataFrame({"frame": np.asarray(frame, np.int64) + 1, "id": np.asarray(ids, np.int64),
                         "bb_left": left, "bb_top": top, "bb_width": width, "bb_height": height,
                         "conf": conf, "x": -1, "y": -1, "z": -1}, columns=list(MOT_COLUMNS))


def mot_table(tracks: pd.DataFrame, *, point_box_px: float = MOT_POINT_BOX_PX) -> pd.DataFrame:
    """One tracker's estimated tracks as MOTChallenge rows (:data:`MOT_COLUMNS`), sorted by frame and id.

    Parameters
    ----------
    tracks : DataFrame
        ``frame`` (0-based), ``track_id``, ``x_filt_px``, ``y_filt_px`` and optionally
        ``bbox_x0_px .. bbox_y1_px``; rows without a finite position are no prediction and
        left out. A row without a finite box gets a ``point_box_px`` square centred on its
        position.
    """
    x, y = (tracks[c].to_numpy(np.float64) for c in ("x_filt_px", "y_filt_px"))
    ok = np.isfinite(x) & np.isfinite(y)
    box = (np.stack([tracks[c].to_numpy(np.float64) for c in _BOX], 1) if all(c in tracks for c in _BOX)
           else np.full((len(tracks), 4), np.nan))
    has = np.isfinite(box).all(axis=1)
    h = point_box_px / 2
    point = np.stack([x - h, y - h, x + h, y + h], 1)
    box = np.where(has[:, None], box, point)[ok]
    out = _mot_rows(tracks["frame"].to_numpy()[ok], tracks["track_id"].to_numpy()[ok], *box.T, 1.0)
    return out.sort_values(["frame", "id"], kind="stable").reset_index(drop=True)


def mot_truth_table(true_tracks: pd.DataFrame) -> pd.DataFrame:
    """A sequence's visible, boxed vehicles (tracks.csv) as MOTChallenge ground-truth rows (``conf`` 1)."""
    vis = true_tracks["visible"].astype(bool).to_numpy()
    box = np.stack([true_tracks[c].to_numpy(np.float64) for c in _BOX], 1)
    ok = vis & np.isfinite(box).all(axis=1)
    out = _mot_rows(true_tracks["frame"].to_numpy()[ok], true_tracks["vehicle_id"].to_numpy()[ok], *box[ok].T, 1.0)
    return out.sort_values(["frame", "id"], kind="stable").reset_index(drop=True)


def write_mot(path: str | os.PathLike, table: pd.DataFrame) -> Path:
    """Write MOTChallenge rows (:data:`MOT_COLUMNS`) as a headerless comma-separated text file.

    Floats are written in their shortest round-trip form, so a reader gets the same numbers back.
    """
    path = Path(path)
    missing = [c for c in MOT_COLUMNS if c not in table.columns]
    if missing:
        raise ValueError(f"{path.name}: the table lacks the column(s) {missing}; expected {list(MOT_COLUMNS)}")
    atomic_write_bytes(path, table[list(MOT_COLUMNS)].to_csv(index=False, header=False).encode())
    return path


def write_mot_tracks(cell_dir: str | os.PathLike, tracks: pd.DataFrame | None) -> list[Path]:
    """Write ``mot_<source>.txt`` for each tracker (``source``) of the estimated tracks; the paths written."""
    if tracks is None or len(tracks) == 0:
        return []
    return [write_mot(Path(cell_dir) / mot_file(str(source)), mot_table(g))
            for source, g in tracks.groupby("source", sort=True)]


def read_mot(path: str | os.PathLike) -> pd.DataFrame:
    """A MOTChallenge text file as boxes: ``frame`` (0-based), ``id``, ``bbox_x0_px .. bbox_y1_px``, ``conf``.

    Comma- or whitespace-separated, 6 to 10 columns (the first six required). The boxes by
    :func:`scenes.formats.box_of_mot`: ``x0 = bb_left - 1.5``, ``x1 = x0 + bb_width`` (py-motmetrics'
    arithmetic up to the shift of origin, so both see the same overlaps).

    Raises
    ------
    CellArtifactError
        A line with fewer than 6 fields or a field that is not a number (the message names file and line).
    """
    path = Path(path)
    rows = []
    for n, line in enumerate(path.read_text().splitlines(), start=1):
        if not line.strip():
            continue
        fields = line.replace(",", " ").split()
        if len(fields) < 6:
            raise CellArtifactError(f"{path}:{n}: expected at least 6 fields (frame,id,bb_left,bb_top,bb_width,"
                                    f"bb_height), got {len(fields)}")
        try:
            vals = [float(v) for v in fields[:7]]
        except ValueError:
            raise CellArtifactError(f"{path}:{n}: expected numbers, got {line.strip()!r}") from None
        if vals[0] != int(vals[0]) or vals[0] < 1:
            raise CellArtifactError(f"{path}:{n}: expected a 1-based integer frame, got {fields[0]!r}")
        rows.append(vals + [1.0] * (7 - len(vals)))
    a = np.asarray(rows, np.float64).reshape(-1, 7)
    x0, y0, x1, y1 = box_of_mot(a[:, 2], a[:, 3], a[:, 4], a[:, 5])
    return pd.DataFrame({"frame": a[:, 0].astype(np.int64) - 1, "id": a[:, 1].astype(np.int64),
                         "bbox_x0_px": x0, "bbox_y0_px": y0, "bbox_x1_px": x1, "bbox_y1_px": y1,
                         "conf": a[:, 6]})


def read_mot_tracks(cell_dir: str | os.PathLike) -> pd.DataFrame | None:
    """Every ``mot_<tracker>.txt`` of a cell as estimated tracks for the metrics; None when there is none.

    Columns ``frame, track_id, source, x_filt_px, y_filt_px`` (the box centre) and
    ``bbox_x0_px .. bbox_y1_px``; a carrier box (:data:`MOT_POINT_BOX_PX` square) is dropped
    (NaN): a point track is scored as a point, as in the run.
    """
    out = []
    for path in sorted(Path(cell_dir).glob("mot_*.txt")):
        source = path.stem.removeprefix("mot_")
        df = read_mot(path).rename(columns={"id": "track_id"})
        df["x_filt_px"] = (df["bbox_x0_px"] + df["bbox_x1_px"]) / 2
        df["y_filt_px"] = (df["bbox_y0_px"] + df["bbox_y1_px"]) / 2
        carrier = (np.isclose(df["bbox_x1_px"] - df["bbox_x0_px"], MOT_POINT_BOX_PX, rtol=0, atol=1e-9)
                   & np.isclose(df["bbox_y1_px"] - df["bbox_y0_px"], MOT_POINT_BOX_PX, rtol=0, atol=1e-9))
        df.loc[carrier, list(_BOX)] = np.nan
        df["source"] = source
        out.append(df[["frame", "track_id", "source", "x_filt_px", "y_filt_px", *_BOX]])
    return pd.concat(out, ignore_index=True) if out else None
