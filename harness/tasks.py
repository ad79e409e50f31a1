"""What a worker does: the two tasks of a run, plain functions of plain data.

Any :class:`concurrent.futures.Executor` (local processes or Dask) can run them:

1. :func:`render_task`, one per distinct scene variant: ``scenes.cached_sequence``
   renders into the shared cache, or finds the sequence already there.
2. :func:`cells_task`, on the payloads (:func:`cell_payload`) of cells that share a
   rendered sequence, usually all cells of a scene variant: runs them together
   (:func:`harness.cell_scoring.score_cells`: frames, pass 1 and each pair's truth
   computed once), writes each cell's rows and artifacts into a temporary folder and
   renames it to ``cells/<cell_id>/``. A cell that raises is recorded (``status =
   "failed"`` with its error) and the others go on. :func:`cell_task` is one cell.

A cell's results depend only on its payload (no shared RNG).
"""

from __future__ import annotations

import math
import os
import shutil
import time
import traceback
import uuid
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from harness import cell_artifacts as artifacts
from harness.cell_scoring import CellOutcome, score_cells
from harness.results import ROWS_FILE, rows_to_frame, write_table
from harness.suites import Cell

__all__ = ["render_task", "cell_task", "cells_task", "cell_payload"]


def _prepare_worker() -> None:
    # Before anything imports OpenGL: headless EGL (see README).
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")


def _import_plugins(modules: Iterable[str], folders: Iterable[str] | None = None) -> None:
    from harness.suites import import_modules

    import_modules(list(modules), source="worker", folders=None if folders is None else list(folders))


def render_progress_writer(path: str | None):
    """A ``progress(done, total)`` callback that writes ``"done total"`` into ``path`` (replaced whole,
    so a reader never sees half a line), or None without a path. Errors are ignored: progress only."""
    if path is None:
        return None

    def progress(done: int, total: int) -> None:
        try:
            tmp = f"{path}.{os.getpid()}.tmp"
            with open(tmp, "w") as fh:
                fh.write(f"{done} {total}")
            os.replace(tmp, path)
        except OSError:
            pass

    return progress


def render_task(variant_key: str, spec: Any, cache_dir: str, imports: Iterable[str] = (),
                import_paths: Iterable[str] | None = None, progress_file: str | None = None) -> dict:
    """Render one scene variant into the cache (or find it there); returns where and whether reused.

    ``imports`` are looked up in ``import_paths`` after the installed packages
    (:func:`harness.suites.import_paths`; default: the worker's working folder). With
    ``progress_file``, the frames rendered so far are written there as ``"done total"`` (the parent
    shows them in its progress bar)."""
    _prepare_worker()
    t0 = time.perf_counter()
    try:
        _import_plugins(imports, import_paths)
        from scenes import cached_sequence_result

        result = cached_sequence_result(spec, cache_dir, progress=render_progress_writer(progress_file))
    except Exception as exc:  # the cells of this scene are recorded as failed, the run goes on
        return {"key": variant_key, "path": None, "reused": False,
                "error": f"rendering failed: {type(exc).__name__}: {exc}",
                "traceback": traceback.format_exc()}
    return {"key": variant_key, "path": str(result.path), "reused": not result.rendered, "error": None,
            "render_s": time.perf_counter() - t0}


def cell_payload(cell: Cell, cells_dir: Path, provenance: dict, imports: list[str],
                 import_paths: list[str] | None = None) -> dict:
    """The plain-data input of :func:`cell_task` (the caller adds ``sequence``, the rendered folder);
    ``import_paths``: where ``imports`` are looked up (:func:`harness.suites.import_paths`)."""
    v = cell.variant
    return {
        "cell_id": cell.cell_id,
        "config_hash": cell.config_hash,
        "scene": v.label,
        "scene_hash": v.scene_hash,
        "seed": v.seed,
        "sweep_param": v.sweep_param,
        "sweep_value": None if v.sweep_value is None else str(v.sweep_value),
        "pipeline": cell.pipeline,
        "pipeline_spec": cell.pipeline_spec,
        "pipeline_hash": cell.pipeline_hash,
        "metrics": list(cell.metrics) if cell.metrics is not None else None,
        "picture_pairs": list(cell.picture_pairs),
        "cells_dir": str(cells_dir),
        "provenance": provenance,
        "imports": imports,
        "import_paths": import_paths,
    }


def _cell_columns(payload: Mapping) -> dict:
    return {
        "cell_id": payload["cell_id"],
        "scene": payload["scene"],
        "scene_hash": payload["scene_hash"],
        "seed": payload["seed"],
        "pipeline": payload["pipeline"],
        "pipeline_hash": payload["pipeline_hash"],
        "sweep_param": payload["sweep_param"],
        "sweep_value": payload["sweep_value"],
        "config_hash": payload["config_hash"],
        **payload["provenance"],
    }


def cell_task(payload: Mapping) -> dict:
    """Run, score and write one cell; never raises for a failure of the cell itself.

    Returns a small summary dict (``cell_id``, ``status``, ``error``, ``rows``).
    """
    return cells_task([payload])[0]


def cells_task(payloads: list[Mapping], progress_file: str | None = None) -> list[dict]:
    """Run, score and write cells of one sequence together (:func:`harness.cell_scoring.score_cells`).

    Each cell gets its own folder exactly as :func:`cell_task` writes it; a cell that
    fails is recorded and the others go on. Never raises for a failure of a cell.
    With ``progress_file``, the pairs scored so far over all the cells are written there as
    ``"done total"`` (the parent shows them in its progress bar: a 1080p clip's cells take minutes).
    Returns one summary dict per payload, in order.
    """
    _prepare_worker()
    t0 = time.perf_counter()
    todo: list[tuple[Mapping, Path]] = []
    failed: dict[str, tuple[BaseException, str]] = {}  # cell_id -> (error, traceback)
    tmps: dict[str, Path] = {}
    for payload in payloads:
        cells_dir = Path(payload["cells_dir"])
        tmp = cells_dir / f".tmp-{payload['cell_id']}-{uuid.uuid4().hex[:8]}"
        tmp.mkdir(parents=True)
        tmps[payload["cell_id"]] = tmp
        try:
            _import_plugins(payload.get("imports", ()), payload.get("import_paths"))
            if payload.get("render_error"):
                raise RuntimeError(payload["render_error"])
            todo.append((payload, tmp))
        except Exception as exc:
            failed[payload["cell_id"]] = (exc, traceback.format_exc())
    outcomes: dict[str, CellOutcome] = {}
    if todo:
        try:
            for (payload, _), outcome in zip(todo, score_cells([p for p, _ in todo], [t for _, t in todo],
                                                                     progress=render_progress_writer(progress_file))):
                outcomes[payload["cell_id"]] = outcome
        except Exception as exc:  # the sequence itself cannot be read: every cell of it fails
            tb = traceback.format_exc()
            for payload, _ in todo:
                failed[payload["cell_id"]] = (exc, tb)
    shared_s = (time.perf_counter() - t0) - sum(o.seconds for o in outcomes.values())
    summaries = []
    for payload in payloads:
        cid = payload["cell_id"]
        outcome = outcomes.get(cid)
        seconds = outcome.seconds if outcome is not None else 0.0
        if outcome is not None and outcome.error is not None:
            failed[cid] = (outcome.error, "".join(traceback.format_exception(outcome.error)))
        elif outcome is not None and not outcome.rows:
            failed[cid] = (RuntimeError("the cell produced no result rows (no metric applies?)"), "")
        summaries.append(_write_cell(payload, tmps[cid], outcome, failed.get(cid),
                                     seconds + max(shared_s, 0.0) / len(payloads)))
    return summaries


def _write_cell(payload: Mapping, tmp: Path, outcome: CellOutcome | None,
                failure: tuple[BaseException, str] | None, elapsed_s: float) -> dict:
    """Write a cell's rows, info (and error) into ``tmp`` and rename it to ``cells/<cell_id>/``."""
    if failure is None:
        status, error, rows, renderer = "ok", "", outcome.rows, outcome.renderer
    else:
        exc, tb = failure
        status, error = "failed", f"{type(exc).__name__}: {exc}"
        rows = [{"metric": "cell_failed", "value": math.nan, "sum": math.nan, "count": 0.0}]
        renderer = outcome.renderer if outcome is not None else ""
        artifacts.write_error(tmp, tb + payload.get("render_traceback", ""))
    table = rows_to_frame(rows, **_cell_columns(payload), renderer=renderer, status=status, error=error)
    write_table(table, tmp / ROWS_FILE)
    artifacts.write_cell_info(tmp, {
        "cell_id": payload["cell_id"], "config_hash": payload["config_hash"], "status": status,
        "error": error, "rows": len(table), "elapsed_s": round(elapsed_s, 3),
        "scene": payload["scene"], "seed": payload["seed"], "pipeline": payload["pipeline"],
    })
    _rename_into_place(tmp, Path(payload["cells_dir"]) / payload["cell_id"])
    return {"cell_id": payload["cell_id"], "status": status, "error": error, "rows": len(table)}


def _rename_into_place(tmp: Path, final: Path) -> None:
    """Make ``tmp`` the folder ``final``; an older folder there (a failed try) is moved aside first."""
    if final.exists():
        old = final.with_name(f".old-{final.name}-{uuid.uuid4().hex[:8]}")
        os.rename(final, old)
        os.rename(tmp, final)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.rename(tmp, final)
