"""The run folder: ``run.json`` written and read in one schema, and where each part of a run lives.

Layout (docs/architecture.md, "Run folder")::

    RUN/run.json  results.parquet  summary.csv  cells/<cell_id>/  report.html  report.md

``run.json`` carries :data:`RUN_FORMAT` under ``format``; :func:`read_run` refuses
another format with a message that names it (a run.json without ``format`` was
written before the format was stamped and has the same keys). The writer is
:func:`write_run`; :class:`RunFolder` is the one reader: the suite, provenance,
cells with their sequence folders, and each pipeline's resolved spec, from which
its flow method is known (``RunFolder.flow_method``), so no reader has to guess
a pipeline's kind from its name.

Public functions
----------------
write_run(run_dir, info) -> Path        run.json, atomic, ``format`` stamped
read_run(run_dir) -> RunFolder          run.json read and checked
RunFolder.results() / .cell_dir(cell_id) / .sequence_dir(scene, seed) / .flow_method(pipeline)
RunFolder.failed_cells() -> DataFrame   one row per failed cell: error and traceback
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from harness.cell_artifacts import read_error
from harness.results import RESULTS_FILE, read_results, read_run_json, write_run_json

__all__ = ["RUN_FORMAT", "RUN_KEYS", "CELLS_DIR", "RunFolderFormatError", "CellEntry", "RunFolder",
           "write_run", "read_run", "cell_entry"]

RUN_FORMAT = "aerobench-run/1"
CELLS_DIR = "cells"
# the keys run.json holds once a run has started (status, finished and the counts change at the end)
RUN_KEYS = ("suite", "suite_source", "resolved_suite", "pipelines", "config_hash", "provenance", "cache_dir",
            "cells", "status", "started", "finished")


class RunFolderFormatError(ValueError):
    """run.json is of another format than this aerobench writes, or lacks what a reader needs."""


@dataclass(frozen=True)
class CellEntry:
    """A cell as run.json lists it: ids, the absolute path of its sequence folder, and whether that
    sequence is rendered (``source`` "synthetic") or real footage ("real")."""

    cell_id: str
    scene: str
    seed: int
    pipeline: str
    config_hash: str
    sequence: Path | None
    source: str = "synthetic"


def cell_entry(*, cell_id: str, scene: str, seed: int, pipeline: str, config_hash: str,
               sequence: str | os.PathLike | None, source: str = "synthetic") -> dict:
    """One cell of run.json's ``cells`` list, as :func:`write_run` expects it; ``source`` is
    "synthetic" (a rendered scene) or "real" (footage, a suite's ``real:`` scene)."""
    if source not in ("synthetic", "real"):
        raise ValueError(f"source: expected 'synthetic' or 'real', got {source!r}")
    return {"cell_id": str(cell_id), "scene": str(scene), "seed": int(seed), "pipeline": str(pipeline),
            "config_hash": str(config_hash), "sequence": None if sequence is None else str(sequence),
            "source": source}


def write_run(run_dir: str | os.PathLike, info: Mapping) -> Path:
    """Write ``RUN/run.json`` atomically with ``format`` = :data:`RUN_FORMAT`.

    ``info`` must hold :data:`RUN_KEYS` (``pipelines``: the resolved pipeline dicts in suite order,
    each with its ``name``;
    ``cells``: dicts from :func:`cell_entry`); other keys (counts, executor, error)
    are kept as given.
    """
    missing = [k for k in RUN_KEYS if k not in info]
    if missing:
        raise ValueError(f"run.json: missing key(s) {missing}; expected {list(RUN_KEYS)}")
    return write_run_json(run_dir, {**dict(info), "format": RUN_FORMAT})


def _opt_str(v) -> str:
    return "" if v is None or (isinstance(v, float) and math.isnan(v)) else str(v)


@dataclass
class RunFolder:
    """A run folder as its run.json describes it (see :func:`read_run`)."""

    path: Path
    info: dict
    cells: list[CellEntry] = field(default_factory=list)

    @property
    def suite(self) -> str:
        s = self.info.get("suite", "")
        return str(s.get("name", "")) if isinstance(s, Mapping) else _opt_str(s)

    @property
    def provenance(self) -> dict:
        p = self.info.get("provenance")
        return dict(p) if isinstance(p, Mapping) else {}

    @property
    def pipelines(self) -> dict[str, dict]:
        """Pipeline name -> resolved pipeline dict (``Pipeline.from_dict`` form), in suite order."""
        p = self.info.get("pipelines")
        if not isinstance(p, list):
            return {}
        return {str(v["name"]): dict(v) for v in p if isinstance(v, Mapping) and v.get("name")}

    @property
    def cache_dir(self) -> Path | None:
        c = self.info.get("cache_dir")
        if not c:
            return None
        p = Path(str(c))
        return p if p.is_absolute() else self.path / p

    def flow_method(self, pipeline: str) -> str | None:
        """The flow method (registry name, e.g. ``lucas_kanade``) of ``pipeline``; None if unknown."""
        flow = self.pipelines.get(pipeline, {}).get("flow")
        return str(flow.get("method")) if isinstance(flow, Mapping) and flow.get("method") else None

    def results(self) -> pd.DataFrame:
        """``results.parquet`` through :func:`harness.results.read_results` (schema version checked)."""
        return read_results(self.path / RESULTS_FILE)

    def cell_dir(self, cell_id: str) -> Path:
        return self.path / CELLS_DIR / str(cell_id)

    @property
    def real_scenes(self) -> list[str]:
        """Labels of the scenes that are real footage (run.json's cells with ``source`` "real"; a
        run.json written before real footage has none), sorted."""
        return sorted({c.scene for c in self.cells if c.source == "real"})

    def sequence_dir(self, scene: str, seed) -> Path | None:
        """The sequence folder of (scene label, seed) as run.json names it; None when it is gone."""
        for c in self.cells:
            if c.scene == str(scene) and str(c.seed) == str(seed) and c.sequence is not None:
                return c.sequence if c.sequence.is_dir() else None
        return None

    def failed_cells(self, table: pd.DataFrame) -> pd.DataFrame:
        """One row per cell whose rows in ``table`` are not ok: ``cell_id, scene, seed, pipeline,
        status, error`` (from the table) and ``traceback`` (from the cell's error.txt)."""
        cols = ["cell_id", "scene", "seed", "pipeline", "status", "error", "traceback"]
        bad = table[table["status"].astype(str) != "ok"]
        rows = []
        for cell_id, g in bad.groupby("cell_id", sort=True):
            first = g.iloc[0]
            errors = "; ".join(e for e in dict.fromkeys(g["error"].map(_opt_str)) if e)
            tb = read_error(self.cell_dir(str(cell_id)))
            rows.append({"cell_id": str(cell_id), "scene": _opt_str(first["scene"]), "seed": _opt_str(first["seed"]),
                         "pipeline": _opt_str(first["pipeline"]), "status": _opt_str(first["status"]),
                         "error": errors or (tb.splitlines()[-1] if tb else ""), "traceback": tb})
        return pd.DataFrame(rows, columns=cols)


def read_run(run_dir: str | os.PathLike) -> RunFolder:
    """Read ``RUN/run.json``.

    Raises
    ------
    FileNotFoundError
        No run folder or no run.json in it.
    RunFolderFormatError
        run.json is not a JSON object, or of another format than :data:`RUN_FORMAT`.
    """
    path = Path(run_dir)
    if not path.is_dir():
        raise FileNotFoundError(f"{path}: not a run folder")
    try:
        info = read_run_json(path)
    except ValueError as exc:
        raise RunFolderFormatError(str(exc)) from None
    if not isinstance(info, dict):
        raise RunFolderFormatError(f"{path / 'run.json'}: expected a JSON object, got {type(info).__name__}")
    fmt = info.get("format", RUN_FORMAT)
    if fmt != RUN_FORMAT:
        raise RunFolderFormatError(f"{path / 'run.json'}: run format {fmt!r}, this aerobench reads {RUN_FORMAT!r}; "
                                   "re-run the suite into a new run folder")
    cells = []
    for c in info.get("cells") or []:
        if not isinstance(c, Mapping) or "cell_id" not in c:
            raise RunFolderFormatError(f"{path / 'run.json'}: a cell entry without cell_id: {c!r}")
        seq = c.get("sequence")
        cells.append(CellEntry(cell_id=str(c["cell_id"]), scene=_opt_str(c.get("scene")),
                               seed=int(c.get("seed", 0)), pipeline=_opt_str(c.get("pipeline")),
                               config_hash=_opt_str(c.get("config_hash")), sequence=Path(seq) if seq else None,
                               source=_opt_str(c.get("source")) or "synthetic"))
    return RunFolder(path=path, info=info, cells=cells)
