"""Constants shared by the harness tests (a module of its own: every test folder has a conftest)."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]

# The smallest suite that still goes through every stage: the tiny preset, few frames.
TINY_SUITE = {
    "name": "test-tiny",
    "description": "two pipelines on a short tiny scene",
    "scenes": [{"preset": "tiny", "overrides": {"image.n_frames": 4}}],
    "seeds": [1],
    "pipelines": ["thesis-lk", "dis"],
    "picture_pairs": [0],
}

# Six cells: enough that a kill after the first complete cell leaves work to resume.
# Its seed-1 thesis-lk and dis cells are the cells of TINY_SUITE (same ids, same numbers).
RESUME_SUITE = {**TINY_SUITE, "name": "test-resume", "seeds": [1, 2], "pipelines": ["thesis-lk", "thesis-hs", "dis"]}

KEY = ["scene", "seed", "pipeline", "sweep_param", "sweep_value", "metric", "region", "motion",
       "frame", "track_id"]


def accuracy_table(table: pd.DataFrame) -> pd.DataFrame:
    """The accuracy rows of a results table (timings vary run to run), in a canonical order."""
    acc = table[table["kind"] == "accuracy"]
    cols = [*KEY, "value", "sum", "count", "hist", "status"]
    return acc[cols].sort_values(KEY, na_position="first").reset_index(drop=True)
