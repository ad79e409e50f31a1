"""The results table: schema, atomic writes, reading, collecting cells, summaries; run.json.

One row per run x frame (or track) x metric x region x motion, long form
(:data:`COLUMNS`, dtypes in :data:`SCHEMA`). Schema version :data:`SCHEMA_VERSION`
is stored twice: in the ``schema_version`` column and in the parquet file's
key-value metadata (``aerobench.schema_version``); :func:`read_results` refuses
any other version with a message that says which one it found.

Columns beyond docs/architecture.md:

* ``kind``: "accuracy" or "timing" (the gate treats timings differently).
* ``hist``: for quantile metrics (``epe_median``, ``epe_p95``) the row's EPE
  histogram (0.01 px bins up to 100 px plus an overflow bin, whose samples are
  kept beside it as a sparse histogram of the same bins) as bytes in the
  compact binary form of :func:`harness.metrics.encode_hist` (the counts of the
  occupied bin range, zlib-compressed: about 0.5 kB for a 640x480 pair, where
  schema v1's "bin:count ..." text took about 2.5 kB); for HOTA's metrics
  (``hota``, ``deta``, ``assa``, ``loca``) their per-alpha numerators and
  denominators (:func:`harness.metrics.encode_alpha_totals`); empty (``b""``) for
  every other metric. Aggregates of quantiles sum these histograms exactly and read
  the quantile off (within 0.005 px of the pooled value); ``value`` holds the
  exact per-frame quantile, ``sum`` is NaN. HOTA's aggregates sum the per-alpha
  totals, then average over the alphas.
* ``schema_version``.

Weighting: ``sum`` and ``count`` are totals (see :mod:`harness.metrics` for each
metric's reduce rule); aggregates always come from summed totals, never from
averaging ``value``. ``frame`` and ``track_id`` are nullable integers (NA for
per-track and per-sequence rows respectively); ``sweep_param`` is "" and
``sweep_value`` "" when a cell has no sweep; ``sweep_value`` is the text of the
value (``str(value)``; use ``pandas.to_numeric`` to plot it).

Public functions
----------------
rows_to_frame(rows, **cell_columns)   metric rows (dicts) + cell columns -> typed DataFrame
check_schema(df, *, source)           validate / coerce a DataFrame to the schema
write_table(df, path)                 atomic parquet write (scenes.formats.atomic_write_bytes)
read_table(path)                      read one parquet file, schema version checked
read_results(run_dir)                 RUN/results.parquet, schema version checked
summarize(df)                         per pipeline x scene x sweep x metric x region x motion
collect_cells(run_dir)                cells/*/rows.parquet -> results.parquet + summary.csv
cell_table(df)                        one row per cell: its cell columns, in table order
write_run_json(run_dir, data), read_run_json(run_dir)   RUN/run.json, atomic
aggregate (re-exported from harness.metrics)
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable, Mapping
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from harness.metrics import aggregate
from scenes.formats import atomic_write_bytes

__all__ = [
    "SCHEMA_VERSION", "SCHEMA", "COLUMNS", "CELL_COLUMNS", "SUMMARY_KEYS", "ResultsError", "SchemaError",
    "rows_to_frame", "check_schema", "write_table", "read_table", "read_results", "summarize",
    "collect_cells", "cell_table", "CellRowsReader", "read_cell_rows", "ROW_ORDER", "write_run_json",
    "read_run_json", "aggregate",
    "RESULTS_FILE", "SUMMARY_FILE", "RUN_FILE", "ROWS_FILE",
]

SCHEMA_VERSION = 2  # 2: hist as compact binary (v1: text)
RESULTS_FILE = "results.parquet"
SUMMARY_FILE = "summary.csv"
RUN_FILE = "run.json"
ROWS_FILE = "rows.parquet"
_META_KEY = b"aerobench.schema_version"

# column -> pandas dtype, in table order
SCHEMA: dict[str, str] = {
    "cell_id": "str", "scene": "str", "scene_hash": "str", "seed": "int64",
    "pipeline": "str", "pipeline_hash": "str", "sweep_param": "str", "sweep_value": "str",
    "frame": "Int64", "track_id": "Int64",
    "metric": "str", "region": "str", "motion": "str", "kind": "str",
    "value": "float64", "sum": "float64", "count": "float64",
    "unit": "str", "higher_is_better": "bool", "hist": "bytes",
    "status": "str", "error": "str",
    "config_hash": "str", "git_commit": "str", "git_dirty": "bool", "renderer": "str", "machine": "str",
    "schema_version": "int64",
}
COLUMNS = tuple(SCHEMA)
# what the runner supplies for every row of a cell (rows_to_frame keyword arguments)
CELL_COLUMNS = ("cell_id", "scene", "scene_hash", "seed", "pipeline", "pipeline_hash", "sweep_param",
                "sweep_value", "status", "error", "config_hash", "git_commit", "git_dirty", "renderer",
                "machine")
SUMMARY_KEYS = ("pipeline", "scene", "sweep_param", "sweep_value")
_DEFAULTS = {"str": "", "int64": 0, "float64": np.nan, "bool": False, "Int64": pd.NA, "bytes": b""}


class ResultsError(ValueError):
    """A results file cannot be used (the CLI reports it in one line with exit code 2)."""


class SchemaError(ResultsError):
    """A results table does not have the schema this version of aerobench reads."""


def check_schema(df: pd.DataFrame, *, source: str = "table") -> pd.DataFrame:
    """Return ``df`` with exactly :data:`COLUMNS` in order and their dtypes; missing columns are an error.

    ``schema_version`` may be missing (it is then set); present, it must equal
    :data:`SCHEMA_VERSION`.
    """
    df = df.copy()
    if "schema_version" not in df.columns:
        df["schema_version"] = SCHEMA_VERSION
    missing = [c for c in COLUMNS if c not in df.columns]
    if missing:
        raise SchemaError(f"{source}: missing column(s) {missing}; expected the aerobench results "
                          f"schema v{SCHEMA_VERSION}: {list(COLUMNS)}")
    versions = set(pd.unique(df["schema_version"]).tolist()) if len(df) else set()
    if versions - {SCHEMA_VERSION}:
        raise SchemaError(f"{source}: schema version {sorted(versions)}, this aerobench reads "
                          f"v{SCHEMA_VERSION}; re-run the suite into a new run folder to rebuild it")
    out = {}
    for c, dt in SCHEMA.items():
        col = df[c]
        if _has_dtype(col, dt):  # as read from our own parquet: nothing to convert (converting costs seconds)
            out[c] = col.reset_index(drop=True)
            continue
        try:
            if dt == "str":
                col = col.astype(object).where(col.notna(), "").astype(str)
            elif dt == "bool":
                col = col.fillna(False).astype(bool)
            elif dt == "bytes":
                col = pd.Series([_as_bytes(v) for v in col], index=col.index, dtype=object)
            elif dt == "Int64":
                col = pd.to_numeric(col, errors="raise").astype("Int64")
            else:
                col = col.astype(dt)
        except (TypeError, ValueError) as exc:
            raise SchemaError(f"{source}: column {c!r} cannot be {dt}: {exc}") from None
        out[c] = col.reset_index(drop=True)
    return pd.DataFrame(out, columns=list(COLUMNS))


def _as_bytes(v) -> bytes:
    """A ``hist`` cell: bytes as they are; missing or "" (no histogram) -> b""; anything else is an error."""
    if isinstance(v, (bytes, bytearray)):
        return bytes(v)
    if v is None or (isinstance(v, float) and np.isnan(v)) or v is pd.NA or (isinstance(v, str) and v == ""):
        return b""
    raise TypeError(f"expected bytes from harness.metrics.encode_hist, got {type(v).__name__} {str(v)[:40]!r}")


def _has_dtype(col: pd.Series, dt: str) -> bool:
    """``col`` already holds ``dt`` with nothing to fill: what the conversion in :func:`check_schema` would give."""
    if dt == "bytes":  # an object column: all bytes (a C-level scan), or checked value by value
        return col.dtype == object and (len(col) == 0 or pd.api.types.infer_dtype(col, skipna=False) == "bytes")
    if dt == "str":
        return isinstance(col.dtype, pd.StringDtype) and col.dtype == _STR_DTYPE and not col.hasnans
    return str(col.dtype) == dt


_STR_DTYPE = pd.Series([""]).astype(str).dtype


def rows_to_frame(rows: Iterable[Mapping], **cell_columns) -> pd.DataFrame:
    """Build a typed results table from metric rows (dicts from :mod:`harness.metrics`).

    ``cell_columns`` (any of :data:`CELL_COLUMNS`) are set on every row; other
    missing columns get defaults ("" / 0 / NaN / NA / False, ``status`` "ok").
    """
    unknown = set(cell_columns) - set(COLUMNS)
    if unknown:
        raise ValueError(f"unknown column(s) {sorted(unknown)}; valid: {list(COLUMNS)}")
    df = pd.DataFrame(list(rows))
    for c, v in cell_columns.items():
        df[c] = "" if v is None and SCHEMA[c] == "str" else (str(v) if SCHEMA[c] == "str" else v)
    for c, dt in SCHEMA.items():
        if c not in df.columns:
            df[c] = "ok" if c == "status" else (SCHEMA_VERSION if c == "schema_version" else _DEFAULTS[dt])
    return check_schema(df, source="rows")


def write_table(df: pd.DataFrame, path: str | os.PathLike) -> Path:
    """Write a results table as parquet atomically: temp file in the folder, fsync, rename."""
    path = Path(path)
    df = check_schema(df, source=str(path))
    table = pa.Table.from_pandas(df, preserve_index=False)
    meta = dict(table.schema.metadata or {})
    meta[_META_KEY] = str(SCHEMA_VERSION).encode()
    table = table.replace_schema_metadata(meta)
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink)
    # one home for atomic writes (temp file, fsync, rename; umask mode; ENOSPC names the file)
    atomic_write_bytes(path, sink.getvalue().to_pybytes())
    return path


def read_table(path: str | os.PathLike) -> pd.DataFrame:
    """Read a parquet results table (results.parquet or a cell's rows.parquet), schema checked."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such results table")
    meta = pq.read_schema(path).metadata or {}
    found = meta.get(_META_KEY)
    if found is None:
        raise SchemaError(f"{path}: no aerobench schema version in the file (written by an older aerobench "
                          f"or another tool); this aerobench reads v{SCHEMA_VERSION}")
    if found.decode() != str(SCHEMA_VERSION):
        raise SchemaError(f"{path}: results schema v{found.decode()}, this aerobench reads v{SCHEMA_VERSION}; "
                          "re-run the suite into a new run folder to rebuild it")
    return check_schema(pq.read_table(path).to_pandas(), source=str(path))


def read_results(run_dir: str | os.PathLike) -> pd.DataFrame:
    """The results table of a run folder (or a path to a .parquet file), schema version checked."""
    p = Path(run_dir)
    return read_table(p if p.suffix == ".parquet" else p / RESULTS_FILE)


def summarize(df: pd.DataFrame) -> pd.DataFrame:
    """Aggregates per pipeline x scene x sweep_param x sweep_value x metric x region x motion.

    Recomputed from summed totals (see :func:`harness.metrics.aggregate`); rows of
    failed cells are left out; ``n_cells`` counts the cells behind each row.
    """
    ok = df[df["status"] == "ok"] if "status" in df.columns else df
    out = aggregate(ok, by=list(SUMMARY_KEYS))
    if "cell_id" in ok.columns and len(out):
        keys = [*SUMMARY_KEYS, "metric", "region", "motion"]
        n = ok.groupby(keys, dropna=False)["cell_id"].nunique().rename("n_cells").reset_index()
        out = out.merge(n, on=keys, how="left")
    else:
        out["n_cells"] = pd.Series(dtype="int64")
    return out


# the order of a cell's rows in results.parquet (cells in cell_id order)
ROW_ORDER = ("metric", "region", "motion", "frame", "track_id")


def read_cell_rows(path: str | os.PathLike) -> pd.DataFrame:
    """A cell's ``rows.parquet``, schema checked, its rows in :data:`ROW_ORDER` (stable, NaN first)."""
    return read_table(path).sort_values(list(ROW_ORDER), na_position="first", kind="stable").reset_index(drop=True)


class CellRowsReader:
    """Reads cells' rows as they finish, so that :func:`collect_cells` at the end of a run only joins them.

    The runner calls :meth:`add` for every cell a worker completed (while the others work);
    a cell folder rewritten afterwards (a retried task) is read again by ``collect_cells``.
    """

    def __init__(self, run_dir: str | os.PathLike):
        self.cells_dir = Path(run_dir) / "cells"
        self.parts: dict[str, tuple[tuple[int, int], pd.DataFrame]] = {}

    def add(self, cell_id: str) -> None:
        """Read ``cells/<cell_id>/rows.parquet`` now (a missing file is left for collection to report)."""
        path = self.cells_dir / cell_id / ROWS_FILE
        try:
            stamp = _stamp(path)
            self.parts[cell_id] = (stamp, read_cell_rows(path))
        except FileNotFoundError:
            pass

    def get(self, path: Path) -> pd.DataFrame | None:
        """The rows read earlier for ``path``, if the file is still the one read."""
        hit = self.parts.get(path.parent.name)
        if hit is None or hit[0] != _stamp(path):
            return None
        return hit[1]

    def cells_table(self) -> pd.DataFrame | None:
        """:func:`cell_table` of the table :func:`collect_cells` is about to write, from the rows read
        so far (no file is read: milliseconds, where collecting takes seconds).

        None when a cell folder holds rows not read here (a cell kept by ``resume``, a folder
        rewritten since), or when the folders are not named by their rows' cell_id.
        """
        heads = []
        for path in _row_files(self.cells_dir):
            part = self.get(path)
            if part is None:
                return None
            heads.append(part.iloc[:1])
        if not heads:
            return None
        df = pd.concat(heads, ignore_index=True)
        if not df["cell_id"].is_monotonic_increasing:  # collect_cells re-sorts such a table: leave it to it
            return None
        return cell_table(df)


def _stamp(path: Path) -> tuple[int, int]:
    st = path.stat()
    return st.st_mtime_ns, st.st_size


def _row_files(cells_dir: Path) -> list[Path]:
    """The cells' rows.parquet files that make the results table, in its order.

    Cell folders are named by cell_id: in name order, each cell's rows in ROW_ORDER is the
    table's order. Folders whose name starts with "." (cells still being written) are left out.
    """
    return [p for p in sorted(cells_dir.glob(f"*/{ROWS_FILE}")) if not p.parent.name.startswith(".")]


def cell_table(df: pd.DataFrame) -> pd.DataFrame:
    """One row per cell of the results table ``df``: the :data:`CELL_COLUMNS` of its first row.

    Cells in the order of ``df``; index 0..n-1, dtypes as in ``df``. Every row of a cell holds
    the same cell columns (:func:`rows_to_frame` sets them on each), so the first says it all.
    """
    return df.drop_duplicates("cell_id")[list(CELL_COLUMNS)].reset_index(drop=True)


def collect_cells(run_dir: str | os.PathLike, *, read: CellRowsReader | None = None) -> pd.DataFrame:
    """Concatenate ``cells/*/rows.parquet`` into ``results.parquet`` and write ``summary.csv``.

    Folders whose name starts with "." (cells still being written) are skipped.
    Rows are sorted (cell, then :data:`ROW_ORDER`: metric, region, motion, frame, track)
    so the file does not depend on the order in which cells finished. Cells already in
    ``read`` (read while the run went on) are not read again. Returns the table.
    """
    run_dir = Path(run_dir)
    parts = []
    for p in _row_files(run_dir / "cells"):
        part = read.get(p) if read is not None else None
        parts.append(part if part is not None else read_cell_rows(p))
    df = pd.concat(parts, ignore_index=True) if parts else rows_to_frame([])
    if not df["cell_id"].is_monotonic_increasing:  # a folder not named by its rows' cell_id
        df = df.sort_values(["cell_id", *ROW_ORDER], na_position="first", kind="stable").reset_index(drop=True)
    # the summary is computed while the table is encoded and written: parquet's encoder and zlib (the
    # summary's histograms) release the GIL, and this is a serial step at the end of every run
    with ThreadPoolExecutor(1, thread_name_prefix="summary") as pool:
        summary = pool.submit(summarize, df)
        write_table(df, run_dir / RESULTS_FILE)
        summary = summary.result()
    atomic_write_bytes(run_dir / SUMMARY_FILE, summary.drop(columns=["hist"]).to_csv(index=False).encode())
    return df


def write_run_json(run_dir: str | os.PathLike, data: Mapping) -> Path:
    """Write ``RUN/run.json`` atomically (sorted keys, indented; NaN refused).

    Keys the gate and reports read: ``suite`` (name), ``config_hash``,
    ``provenance`` (from :func:`harness.provenance.collect`, holding ``machine``),
    plus ``resolved_suite``, ``cache_dir``, ``cells``, ``status``, ``started``, ``finished``.
    """
    path = Path(run_dir) / RUN_FILE
    text = json.dumps(data, indent=2, sort_keys=True, allow_nan=False, default=_json_default)
    atomic_write_bytes(path, (text + "\n").encode())
    return path


def read_run_json(run_dir: str | os.PathLike) -> dict:
    """Read ``RUN/run.json``; a missing or unreadable file raises with the path in the message."""
    path = Path(run_dir)
    path = path if path.suffix == ".json" else path / RUN_FILE
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no run.json (not a run folder, or the run never started)")
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not valid JSON: {exc}") from None


def _json_default(o):
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.floating,)):
        return float(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"run.json: cannot write a {type(o).__name__}")
