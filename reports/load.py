"""Read a run folder for the report, only through the harness readers that own each file.

run.json through :mod:`harness.run_folder`, the results table through
:mod:`harness.results`, cell artifacts through :mod:`harness.cell_artifacts`,
sequence folders through :mod:`scenes.sequence`. This module only reshapes
what they return for the report. Aggregates are recomputed from the ``sum``
and ``count`` columns (pooled), never as an average of per-frame or per-cell
averages.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from harness import cell_artifacts as artifacts
from harness.metrics import position_error_px
from harness.results import aggregate
from harness.run_folder import RunFolder, read_run
from scenes.sequence import Sequence, open_sequence

__all__ = [
    "RunData",
    "load_run",
    "load_cells",
    "pooled",
    "primary_rows",
    "scene_base",
    "scene_bases",
    "open_scene_sequence",
    "read_stabilisation",
    "read_tracks",
    "point_errors_by_frame",
    "read_true_tracks",
    "picture_frames",
    "read_cell_flow",
]


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

    Rows come back grouped by metric (in the order metrics first appear), each
    metric's rows in their order in ``df``.
    """
    if df.empty:
        return df.iloc[:0]
    # one pass over whole columns instead of a filter per metric (a results table has ~10^6 rows)
    code, _ = pd.factorize(df["metric"], sort=False)   # codes in order of first appearance
    n_metrics = int(code.max()) + 1
    is_all = (df["region"] == "all").to_numpy(bool)
    has_all = np.bincount(code, weights=is_all, minlength=n_metrics) > 0
    keep = is_all | ~has_all[code]
    motion = df["motion"].to_numpy(object)
    is_total = (motion == "total") & keep
    has_total = np.bincount(code, weights=is_total, minlength=n_metrics) > 0
    # metrics without a total motion: their first motion (sorted) among the kept rows
    first_motion = {}
    for m in np.flatnonzero(~has_total):
        first_motion[m] = sorted(set(motion[keep & (code == m)]))[0]
    want = np.array([first_motion.get(m, "total") for m in range(n_metrics)], dtype=object)
    keep &= motion == want[code]
    idx = np.flatnonzero(keep)
    order = idx[np.argsort(code[idx], kind="stable")]
    return df.iloc[order].assign(region="all").reset_index(drop=True)


def scene_bases(labels: pd.Series) -> pd.Series:
    """:func:`scene_base` of every label of ``labels`` (computed once per distinct label)."""
    code, uniques = pd.factorize(labels, sort=False)
    bases = np.array([scene_base(u) for u in uniques], dtype=object)
    return pd.Series(bases[code] if len(code) else np.array([], dtype=object), index=labels.index, dtype=object,
                     name=labels.name)


def scene_base(label: str) -> str:
    """The scene of a variant label: ``"urban[jitter_px=2]"`` -> ``"urban"``."""
    return str(label).split("[", 1)[0]


@dataclass
class RunData:
    """What a report needs from a run folder."""

    run_dir: Path
    folder: RunFolder            # run.json, read by harness.run_folder
    table: pd.DataFrame          # every row of results.parquet
    ok: pd.DataFrame             # rows of cells that completed, with a metric
    failed: pd.DataFrame         # one row per failed cell: cell_id, scene, seed, pipeline, error, traceback
    pipelines: list[str]
    scenes: list[str]
    seeds: list
    metrics: list[str]
    notes: list[str] = field(default_factory=list)

    @property
    def run(self) -> dict:
        """run.json as a dict (provenance, dates, status)."""
        return self.folder.info


def _ordered_unique(values) -> list:
    seen = []
    for v in values:
        if v is None or (isinstance(v, float) and math.isnan(v)) or v in seen:
            continue
        seen.append(v)
    return seen


def _distinct(col: pd.Series) -> list:
    """The distinct values of a column in order of first appearance (one hash pass, not a list scan per row)."""
    return pd.unique(col).tolist()


def _pipelines(folder: RunFolder, table: pd.DataFrame) -> list[str]:
    """The pipelines of ``table``: in the suite's order (run.json's resolved pipelines), then the table's."""
    in_table = _distinct(table["pipeline"].astype(str))
    return [p for p in _ordered_unique([*folder.pipelines, *in_table]) if p in set(in_table)]


def load_run(run_dir: str | os.PathLike, *, table: pd.DataFrame | None = None) -> RunData:
    """Read ``RUN/run.json`` and ``RUN/results.parquet``; see :class:`RunData`.

    ``table``: the results table when the caller holds it already, as
    :func:`harness.results.collect_cells` returned it (the rows, columns, dtypes and order
    that reading results.parquet gives back); then the file is not read.
    """
    folder = read_run(run_dir)
    if table is None:
        table = folder.results()
    ok = table[(table["status"] == "ok") & ~table["metric"].isin(["", "cell_failed"])].copy()
    failed = folder.failed_cells(table)
    ok = ok[~ok["cell_id"].astype(str).isin(set(failed["cell_id"]))]
    return RunData(run_dir=folder.path, folder=folder, table=table, ok=ok, failed=failed,
                   pipelines=_pipelines(folder, table),
                   scenes=_ordered_unique(_distinct(table["scene"].astype(str))),
                   seeds=sorted(_ordered_unique(_distinct(table["seed"]))),
                   metrics=_ordered_unique(_distinct(ok["metric"].astype(str))))


def load_cells(run_dir: str | os.PathLike, cells: pd.DataFrame) -> RunData:
    """What the scene blocks need of a run folder before its results table is written.

    ``cells`` is :func:`harness.results.cell_table` of the table to come (one row per cell,
    its cell columns). The :class:`RunData` has no rows (``table`` and ``failed`` empty,
    no metrics); ``ok`` holds the ok cells' rows of ``cells``, ``pipelines`` is what
    :func:`load_run` will find. An ok cell without a metric row is not told apart here:
    :func:`reports.report.build_report` compares its cell index with the table's.
    """
    folder = read_run(run_dir)
    ok = cells[cells["status"] == "ok"]
    return RunData(run_dir=folder.path, folder=folder, table=cells.iloc[:0], ok=ok,
                   failed=folder.failed_cells(cells.iloc[:0]), pipelines=_pipelines(folder, cells),
                   scenes=_ordered_unique(_distinct(cells["scene"].astype(str))),
                   seeds=sorted(_ordered_unique(_distinct(cells["seed"]))), metrics=[])


# ---------------------------------------------------------------- cell artifacts and sequences

def open_scene_sequence(data: RunData, *, scene: str, seed) -> Sequence | None:
    """The sequence of (scene label, seed) that run.json names, opened lazily; None when it is gone."""
    path = data.folder.sequence_dir(scene, seed)
    if path is None:
        return None
    try:
        return open_sequence(path)
    except (OSError, ValueError):  # a partial or foreign folder: the report says the sequence is missing
        return None


def read_stabilisation(cell_dir: Path) -> pd.DataFrame | None:
    """The cell's stabilisation.csv with the short names the plots use.

    Returns columns ``frame`` and, for ``a`` in ``x, y``: ``cum_a`` (estimated
    cumulative shift), ``line_a`` (fitted flight line), ``corr_a`` (correction),
    ``jit_a`` (estimated jitter), ``cum_true_a``, ``jit_true_a``, all px.
    """
    df = artifacts.read_stabilisation(cell_dir)
    if df is None:
        return None
    out = pd.DataFrame({"frame": df["frame"]})
    for a in ("x", "y"):
        out[f"cum_{a}"] = df[f"cumulative_{a}_px"]
        out[f"line_{a}"] = df[f"flight_line_{a}_px"]
        out[f"corr_{a}"] = df[f"correction_{a}_px"]
        out[f"jit_{a}"] = df[f"jitter_{a}_px"]
        out[f"cum_true_{a}"] = df[f"true_cumulative_{a}_px"]
        out[f"jit_true_{a}"] = df[f"true_jitter_{a}_px"]
    return out


def read_tracks(cell_dir: Path) -> pd.DataFrame | None:
    """The cell's tracks.csv as ``frame, source, track_id, seed_vehicle_id, x, y, x_filt, y_filt,
    x_true, y_true, visible`` (px). A track is the pair ``(source, track_id)``; the truth columns are
    filled for point tracks only (the vehicle the track was seeded on). ``visible``: whether that
    vehicle is in view in the frame as the metrics score it (1 / 0: a row under half visible is not; NaN in
    cell folders written before it was recorded)."""
    df = artifacts.read_tracks(cell_dir)
    if df is None:
        return None
    out = df[["frame", "source", "track_id", "seed_vehicle_id"]].copy()
    for short, col in (("x", "x_px"), ("y", "y_px"), ("x_filt", "x_filt_px"), ("y_filt", "y_filt_px"),
                       ("x_true", "true_x_px"), ("y_true", "true_y_px"), ("visible", "true_visible")):
        out[short] = df[col]
    return out


def point_errors_by_frame(tracks: pd.DataFrame) -> pd.DataFrame:
    """Per frame, the mean position error [px] of the point tracks over the rows the metrics score.

    The selection is :func:`harness.metrics.track_rows`' for the point tracker: rows seeded on a
    vehicle, with a finite filtered position, where that vehicle is visible (a vehicle that left
    the view has a projected centre but no score). ``tracks`` as :func:`read_tracks` returns it;
    ``visible`` NaN (an older cell folder) counts as visible wherever the true centre is known.

    Returns
    -------
    DataFrame
        ``frame`` (int, ascending), ``err_kalman`` (the mean of the frame's ``track_error``
        rows) and ``err_raw`` (of ``track_raw_error``: rows with a finite raw position), float px.
    """
    t = tracks[(tracks["source"] == "point") & tracks["seed_vehicle_id"].notna()]
    known = np.isfinite(t[["x_true", "y_true", "x_filt", "y_filt"]].to_numpy(float)).all(axis=1)
    visible = t["visible"].fillna(1.0).to_numpy(float) > 0
    t = t[known & visible]
    e = pd.DataFrame({"frame": t["frame"].astype(int),
                      "err_raw": position_error_px(t["x"], t["y"], t["x_true"], t["y_true"]),
                      "err_kalman": position_error_px(t["x_filt"], t["y_filt"], t["x_true"], t["y_true"])})
    # a mean over the finite values per column: a NaN raw position leaves that row out of err_raw only
    return e.groupby("frame", as_index=False, sort=True)[["err_kalman", "err_raw"]].mean()


def read_true_tracks(seq: Sequence | None) -> pd.DataFrame | None:
    """The sequence's tracks.csv (every vehicle's projected centre) as ``frame, vehicle_id, x, y,
    parked`` for the frames where the vehicle is visible; None without a sequence or without
    track truth (real footage with no ground-truth file)."""
    if seq is None or seq.tracks is None:  # real footage without identities has no tracks.csv
        return None
    df = seq.tracks
    df = df[df["visible"].astype(int) > 0]
    # real footage does not say which vehicles are parked: none is taken as parked
    parked = df["parked"].astype(int) if "parked" in df.columns else 0
    return pd.DataFrame({"frame": df["frame"].astype(int), "vehicle_id": df["vehicle_id"].astype(int),
                         "x": df["x_px"].astype(float), "y": df["y_px"].astype(float),
                         "parked": parked}
                        ).sort_values(["vehicle_id", "frame"], kind="stable").reset_index(drop=True)


def picture_frames(cell_dir: Path) -> list[int]:
    """Pairs for which the cell saved its estimated flow."""
    return artifacts.picture_pairs(cell_dir)


def read_cell_flow(cell_dir: Path, frame: int, *, local: bool = False) -> np.ndarray | None:
    """The total (or, with ``local``, total minus global) flow a cell saved for pair ``frame``; None if absent."""
    return artifacts.read_flow(cell_dir, frame, local=local)
