"""Helpers of the reliability tests (a module of its own: several test folders have a conftest)."""

from __future__ import annotations

import copy
import hashlib
import json
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[2]  # the project: where `python -m harness.cli` runs

# Four cells on a three-frame tiny scene: every stage runs, the whole run takes seconds.
SUITE = {
    "name": "reliability",
    "description": "two seeds x two pipelines on a short tiny scene",
    "scenes": [{"preset": "tiny", "overrides": {"image.n_frames": 3}}],
    "seeds": [1, 2],
    "pipelines": ["thesis-lk", "dis"],
    "picture_pairs": [0],
}

KEY = ["cell_id", "scene", "seed", "pipeline", "sweep_param", "sweep_value", "metric", "region", "motion",
       "frame", "track_id"]


def suite(**changes) -> dict:
    """A deep copy of :data:`SUITE` with top-level keys replaced."""
    return {**copy.deepcopy(SUITE), **copy.deepcopy(changes)}


def accuracy_rows(table: pd.DataFrame) -> pd.DataFrame:
    """Every column of the accuracy rows except provenance, in a canonical order (timings vary)."""
    acc = table[table["kind"] != "timing"]
    drop = ["git_commit", "git_dirty", "machine", "renderer"]
    return (acc.drop(columns=drop).sort_values(KEY, na_position="first", kind="stable")
            .reset_index(drop=True))


def assert_bit_identical(a: pd.DataFrame, b: pd.DataFrame) -> None:
    """Equal tables, floats compared exactly (``assert_frame_equal`` alone allows rtol 1e-5)."""
    a, b = accuracy_rows(a), accuracy_rows(b)
    assert len(a) > 0
    pd.testing.assert_frame_equal(a, b, check_exact=True)
    for c in ("value", "sum", "count"):  # NaN == NaN, and -0.0 vs 0.0 or last-bit changes caught
        assert a[c].to_numpy().tobytes() == b[c].to_numpy().tobytes(), c


def tree_state(root: Path) -> dict[str, str]:
    """relative path -> sha256 (or "dir") of everything under ``root``: a before/after snapshot."""
    root = Path(root)
    if not root.exists():
        return {}
    out = {}
    for p in sorted(root.rglob("*")):
        rel = str(p.relative_to(root))
        out[rel] = "dir" if p.is_dir() else hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def partial_files(root: Path) -> list[str]:
    """Names that only an interrupted write leaves behind (temp files and folders)."""
    return sorted(str(p) for p in Path(root).rglob("*")
                  if p.name.startswith((".tmp-", ".old-")) or p.name.endswith(".tmp") or ".partial-" in p.name)


def assert_all_readable(run_dir: Path) -> int:
    """Every final-named parquet / json / csv under ``run_dir`` reads whole; returns how many files."""
    import pyarrow.parquet as pq

    n = 0
    for p in Path(run_dir).rglob("*"):
        if not p.is_file() or p.name.startswith("."):
            continue
        if p.suffix == ".parquet":
            pq.read_table(p)
        elif p.suffix == ".json":
            json.loads(p.read_text())
        elif p.suffix == ".csv":
            pd.read_csv(p)
        else:
            continue
        n += 1
    return n
