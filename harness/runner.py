"""Run a suite: render its scenes (cached), run its cells on an executor, collect the results.

:func:`run_suite` is the library entry point; ``aerobench run`` only parses, calls it,
prints and picks the exit code. The run folder is laid out as docs/architecture.md says.

Work comes in two kinds of task, both plain functions of plain data so that any
:class:`concurrent.futures.Executor` (local processes or Dask) can run them:

1. :func:`render_task`, one per distinct scene variant: ``scenes.cached_sequence``
   renders into the shared cache, or finds the sequence already there.
2. :func:`cell_task`, one per (scene variant, seed, pipeline): opens the sequence
   lazily, runs the pipeline pair by pair, scores each pair at once and drops its
   arrays, scores the sequence, writes the cell's rows and artifacts into a temporary
   folder and renames it to ``cells/<cell_id>/``. A cell that raises is recorded
   (``status = "failed"`` with its error) and the run goes on.

A cell's results depend only on its inputs (no shared RNG), and rows are sorted on
collection, so the accuracy numbers do not depend on the executor or the number of
workers. ``resume=True`` keeps every complete cell folder whose config hash matches,
so a run killed at any moment (SIGKILL included) finishes with the same results.
"""

from __future__ import annotations

import fcntl
import heapq
import itertools
import json
import math
import os
import shutil
import sys
import time
import traceback
import uuid
from collections.abc import Iterable, Mapping
from concurrent.futures import FIRST_COMPLETED, Future, wait
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from harness import cell_artifacts as artifacts
from harness.results import ROWS_FILE, collect_cells, rows_to_frame, write_table
from harness.run_folder import cell_entry, write_run
from harness.suites import Cell, SceneVariant, Suite, expand, load_suite

__all__ = ["RunFolderError", "RunResult", "default_cache_dir", "run_suite", "render_task", "cell_task"]

CELL_FILE = artifacts.CELL_FILE  # written last inside a cell folder, before the rename
LOCK_FILE = ".lock"
CACHE_ENV = "AEROBENCH_CACHE"


class RunFolderError(ValueError):
    """The run folder cannot be used: not empty without ``resume``, or locked by another run."""


@dataclass
class RunResult:
    """What :func:`run_suite` returns: the results table and how the run went."""

    run_dir: Path
    table: pd.DataFrame
    status: str  # "ok" | "failed"
    cells: int
    failed_cells: list[str] = field(default_factory=list)  # "cell_id scene seed pipeline: error"
    reused_cells: int = 0
    scenes_rendered: int = 0
    scenes_reused: int = 0
    elapsed_s: float = 0.0

    @property
    def ok(self) -> bool:
        return self.status == "ok"


def default_cache_dir() -> Path:
    """The render cache: ``$AEROBENCH_CACHE``, else ``$XDG_CACHE_HOME/aerobench`` (``~/.cache/aerobench``)."""
    env = os.environ.get(CACHE_ENV)
    if env:
        return Path(env).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "aerobench"


# --------------------------------------------------------------------------- worker side


def _prepare_worker() -> None:
    # Before anything imports OpenGL: headless EGL (see README).
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")


def _import_plugins(modules: Iterable[str]) -> None:
    from harness.suites import import_modules

    import_modules(list(modules), source="worker")


def render_task(variant_key: str, spec: Any, cache_dir: str, imports: Iterable[str] = ()) -> dict:
    """Render one scene variant into the cache (or find it there); returns where and whether reused."""
    _prepare_worker()
    t0 = time.perf_counter()
    try:
        _import_plugins(imports)
        from scenes import cached_sequence_result

        result = cached_sequence_result(spec, cache_dir)
    except Exception as exc:  # the cells of this scene are recorded as failed, the run goes on
        return {"key": variant_key, "path": None, "reused": False,
                "error": f"rendering failed: {type(exc).__name__}: {exc}",
                "traceback": traceback.format_exc()}
    return {"key": variant_key, "path": str(result.path), "reused": not result.rendered, "error": None,
            "render_s": time.perf_counter() - t0}


class _Frames:
    """The frames of a sequence as an indexable (``len``, ``[i]``) read lazily from disk."""

    def __init__(self, seq: Any):
        self._seq = seq

    def __len__(self) -> int:
        return len(self._seq)

    def __getitem__(self, i: int) -> np.ndarray:
        if not 0 <= i < len(self._seq):
            raise IndexError(i)
        return self._seq.frame(i)


def point_seeds(tracks: pd.DataFrame) -> list[tuple[int, float, float]]:
    """Seeds for the point tracker: ground-truth centres of the vehicles visible in frame 0."""
    if tracks is None or len(tracks) == 0:
        return []
    first = tracks[(tracks["frame"] == 0) & (tracks["visible"].astype(int) == 1)]
    first = first.sort_values("vehicle_id")
    return [(int(r.vehicle_id), float(r.x_px), float(r.y_px)) for r in first.itertuples()]


def _as_rows(rows: Any) -> list[dict]:
    if rows is None:
        return []
    if isinstance(rows, pd.DataFrame):
        return rows.to_dict("records")
    return [dict(r) for r in rows]


def _renderer_of(meta: Mapping) -> str:
    """One line naming what rendered a sequence (renderer and GL strings of meta.json)."""
    parts = [str(meta.get(k)) for k in ("renderer", "gl_renderer", "gl_version") if meta.get(k)]
    return " | ".join(parts)


# pipeline hashes this process has already run once (see _warm_up)
_WARMED: set[str] = set()


def _warm_up(pipeline: Any) -> None:
    """Run ``pipeline`` once, untimed, on a small synthetic sequence.

    The first call of a numba kernel compiles it (about 6 s for Horn-Schunck
    without an on-disk cache); without this, that cost lands in the stage
    timings of whichever cell a worker happens to run first, and the report's
    time per frame depends on scheduling. Failures are left to the real run.
    """
    if pipeline.hash in _WARMED:
        return
    _WARMED.add(pipeline.hash)
    import cv2

    rng = np.random.default_rng(0)
    texture = cv2.GaussianBlur((rng.random((96, 96)) * 255).astype(np.float32), (0, 0), 1.5)
    frames = [np.ascontiguousarray(texture[k:k + 64, k:k + 64]).astype(np.uint8) for k in range(3)]
    try:
        for _ in pipeline.run(frames, seeds=[(1, 32.0, 32.0)]):
            pass
    except Exception:  # noqa: BLE001 - a warm-up only; the real run reports errors
        pass


def _score_cell(payload: Mapping, tmp: Path) -> tuple[list[dict], str]:
    """Run one cell's pipeline on its sequence and score it; artifacts go into ``tmp``."""
    from algorithms.pipeline import Pipeline
    from harness.metrics import score_pair, score_sequence
    from scenes import open_sequence

    seq = open_sequence(payload["sequence"])
    pipeline = Pipeline.from_dict(payload["pipeline_spec"])
    _warm_up(pipeline)
    pictures = set(payload["picture_pairs"])
    rows: list[dict] = []
    seq_est = None
    for est in pipeline.run(_Frames(seq), seeds=point_seeds(seq.tracks)):
        if not hasattr(est, "flow_total"):  # the SequenceEstimate comes last
            seq_est = est
            continue
        truth = seq.pair_truth(est.index)
        rows += _as_rows(score_pair(est, truth, frame=est.index))
        if est.index in pictures:
            artifacts.write_pair_flows(tmp, est.index, est.flow_total, est.flow_global)
        del est, truth  # the arrays of a pair live no longer than its scoring
    if seq_est is None:
        raise RuntimeError("the pipeline yielded no SequenceEstimate")
    rows += _as_rows(score_sequence(seq_est, seq.camera, seq.tracks))
    artifacts.write_stabilisation(tmp, artifacts.stabilisation_table(seq_est, seq.camera))
    artifacts.write_tracks(tmp, artifacts.tracks_table(seq_est, seq.tracks))
    if payload["metrics"] is not None:
        keep = set(payload["metrics"])
        rows = [r for r in rows if r["metric"] in keep]
    return rows, _renderer_of(seq.meta or {})


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
    _prepare_worker()
    cells_dir = Path(payload["cells_dir"])
    final = cells_dir / payload["cell_id"]
    tmp = cells_dir / f".tmp-{payload['cell_id']}-{uuid.uuid4().hex[:8]}"
    tmp.mkdir(parents=True)
    t0 = time.perf_counter()
    status, error, tb, renderer = "ok", "", "", ""
    try:
        _import_plugins(payload.get("imports", ()))
        if payload.get("render_error"):
            raise RuntimeError(payload["render_error"])
        rows, renderer = _score_cell(payload, tmp)
        if not rows:
            raise RuntimeError("the cell produced no result rows (no metric applies?)")
    except Exception as exc:
        status, error, tb = "failed", f"{type(exc).__name__}: {exc}", traceback.format_exc()
        rows = [{"metric": "cell_failed", "value": math.nan, "sum": math.nan, "count": 0.0}]
        artifacts.write_error(tmp, tb + payload.get("render_traceback", ""))
    table = rows_to_frame(rows, **_cell_columns(payload), renderer=renderer, status=status, error=error)
    write_table(table, tmp / ROWS_FILE)
    artifacts.write_cell_info(tmp, {
        "cell_id": payload["cell_id"], "config_hash": payload["config_hash"], "status": status,
        "error": error, "rows": len(table), "elapsed_s": round(time.perf_counter() - t0, 3),
        "scene": payload["scene"], "seed": payload["seed"], "pipeline": payload["pipeline"],
    })
    _rename_into_place(tmp, final)
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


# --------------------------------------------------------------------------- files


def _cell_info(folder: Path) -> dict | None:
    """A cell folder's cell.json; None when partial, unreadable or of another cell format (run again)."""
    try:
        return artifacts.read_cell_info(folder)
    except artifacts.CellArtifactError:
        return None


def _read_json(path: Path) -> dict | None:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


# --------------------------------------------------------------------------- driver side


def _say(progress: bool, msg: str) -> None:
    if progress:
        print(msg, file=sys.stderr, flush=True)


class _Lock:
    """An exclusive ``flock`` on ``RUN/.lock``: released by the kernel even if the run is killed."""

    def __init__(self, run_dir: Path):
        self.path = run_dir / LOCK_FILE
        self.fd: int | None = None

    def __enter__(self) -> _Lock:
        self.fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(self.fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(self.fd)
            self.fd = None
            raise RuntimeError from None
        os.ftruncate(self.fd, 0)
        os.write(self.fd, f"{os.getpid()}\n".encode())
        return self

    def __exit__(self, *exc: Any) -> None:
        if self.fd is not None:
            fcntl.flock(self.fd, fcntl.LOCK_UN)
            os.close(self.fd)


def _open_run_dir(run_dir: Path, resume: bool) -> _Lock:
    if run_dir.exists() and not run_dir.is_dir():
        raise RunFolderError(f"{run_dir}: exists and is not a folder")
    if run_dir.is_dir() and not resume:
        others = [p.name for p in run_dir.iterdir() if p.name != LOCK_FILE]
        if others:
            raise RunFolderError(
                f"{run_dir}: the run folder is not empty; pass --resume to finish that run, or choose another --out"
            )
    run_dir.mkdir(parents=True, exist_ok=True)
    lock = _Lock(run_dir)
    try:
        lock.__enter__()
    except RuntimeError:
        raise RunFolderError(f"{run_dir}: another aerobench run is writing into this folder ({run_dir / LOCK_FILE})") from None
    return lock


def _cell_complete(cells_dir: Path, cell: Cell) -> bool:
    """A cell folder is kept on resume when it is complete, succeeded, and has the same config hash."""
    folder = cells_dir / cell.cell_id
    info = _cell_info(folder)
    return (
        info is not None
        and info.get("config_hash") == cell.config_hash
        and info.get("status") == "ok"
        and (folder / ROWS_FILE).is_file()
    )


def _clean_partial(run_dir: Path) -> None:
    """What a killed run left half-written: temp folders of running cells, and the temp files
    of atomic writes (``.run.json.*.tmp``, ``.results.parquet.*.tmp``, ...) in the run folder.

    Called with the run folder's lock held, so no other writer owns these.
    """
    for p in run_dir.glob(".*.tmp"):
        if p.is_file():
            p.unlink(missing_ok=True)
    cells_dir = run_dir / "cells"
    for p in cells_dir.glob(".tmp-*"):
        shutil.rmtree(p, ignore_errors=True)
    for p in cells_dir.glob(".old-*"):
        shutil.rmtree(p, ignore_errors=True)


def _variant_key(v: SceneVariant) -> str:
    return v.scene_hash


def _payload(cell: Cell, cells_dir: Path, provenance: dict, imports: list[str]) -> dict:
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
    }


def run_suite(
    suite: Suite | str | os.PathLike,
    out_dir: str | os.PathLike,
    *,
    workers: int | None = None,
    resume: bool = False,
    executor: str = "process",
    scheduler: str | None = None,
    cache_dir: str | os.PathLike | None = None,
    progress: bool = True,
) -> RunResult:
    """Run every cell of ``suite`` into the run folder ``out_dir`` and collect the results.

    Parameters
    ----------
    suite : Suite, built-in suite name or path to a suite YAML
    out_dir : path
        The run folder; must be empty or absent unless ``resume``.
    workers : int, optional
        Worker processes (``process``, ``dask-local``); default one per core.
    resume : bool
        Keep the cells already in ``out_dir`` that succeeded with the same config hash,
        and run the rest (failed cells are tried again).
    executor : {"process", "dask", "dask-local"}
    scheduler : str, optional
        Dask scheduler address for ``executor="dask"``.
    cache_dir : path, optional
        The render cache shared between runs; default :func:`default_cache_dir`.
    progress : bool
        Progress bar and status lines on stderr.

    Returns
    -------
    RunResult
        ``status`` is ``"failed"`` when any cell failed; the table holds every row.

    Raises
    ------
    harness.suites.SuiteError
        the suite is invalid (nothing is written).
    RunFolderError
        ``out_dir`` is not empty without ``resume``, or another run holds it.
    harness.executors.ExecutorError
        the executor cannot be made (dask missing, scheduler unreachable).
    """
    from harness.executors import check_executor
    from harness.provenance import collect as collect_provenance
    from harness.provenance import config_hash

    t_start = time.perf_counter()
    started = datetime.now(timezone.utc).isoformat(timespec="seconds")
    source = str(suite) if not isinstance(suite, Suite) else suite.name
    if not isinstance(suite, Suite):
        suite = load_suite(suite)
    check_executor(executor, workers=workers, scheduler=scheduler)
    cells = expand(suite, source=source)  # validates everything before a file is written
    suite_dict = suite.model_dump(mode="json")
    suite_hash = config_hash(suite_dict)
    cache = Path(cache_dir).expanduser() if cache_dir is not None else default_cache_dir()
    run_dir = Path(out_dir)

    lock = _open_run_dir(run_dir, resume)
    try:
        cells_dir = run_dir / "cells"
        cells_dir.mkdir(exist_ok=True)
        _clean_partial(run_dir)
        old = _read_json(run_dir / "run.json")
        if resume and old is not None and old.get("config_hash") not in (None, suite_hash):
            raise RunFolderError(
                f"{run_dir}: holds a run of another suite configuration (config hash "
                f"{old.get('config_hash')}, this suite {suite_hash}); choose another --out"
            )
        todo = [c for c in cells if not (resume and _cell_complete(cells_dir, c))]
        reused_cells = len(cells) - len(todo)
        if reused_cells:
            _say(progress, f"resume: {reused_cells} of {len(cells)} cells already complete")

        prov = collect_provenance()
        provenance = {k: prov[k] for k in ("git_commit", "git_dirty", "machine")}
        run_info = {
            "suite": suite.name, "suite_source": source, "resolved_suite": suite_dict,
            "config_hash": suite_hash, "provenance": prov, "cache_dir": str(cache),
            "pipelines": list({c.pipeline: {**c.pipeline_spec, "name": c.pipeline} for c in cells}.values()),
            "cells": [_cell_entry(c, cache) for c in cells], "status": "running",
            "started": started, "finished": None, "executor": executor,
            "workers": workers,
        }
        write_run(run_dir, run_info)

        try:
            rendered, reused, failed = _execute(
                todo, cells_dir, cache, provenance, suite, executor, workers, scheduler, progress
            )
        except BaseException as exc:  # Ctrl-C, a lost scheduler: say so in run.json, keep the cells
            run_info.update(status="aborted", error=f"{type(exc).__name__}: {exc}",
                            finished=datetime.now(timezone.utc).isoformat(timespec="seconds"))
            write_run(run_dir, run_info)
            raise
        _say(progress, f"scenes: {rendered} rendered, {reused} reused from the cache ({cache})")

        _remove_strays(cells_dir, cells)
        table = collect_cells(run_dir)  # sorted rows: independent of the order cells finished
        failed_cells = _failures(cells_dir, cells)
        status = "failed" if failed_cells else "ok"
        renderers = sorted(set(table["renderer"]) - {""}) if len(table) else []
        prov["renderer"] = "; ".join(renderers)
        run_info.update(status=status, failed_cells=failed_cells, provenance=prov,
                        finished=datetime.now(timezone.utc).isoformat(timespec="seconds"),
                        scenes_rendered=rendered, scenes_reused=reused, cells_reused=reused_cells)
        write_run(run_dir, run_info)
    finally:
        lock.__exit__(None, None, None)
    return RunResult(run_dir=run_dir, table=table, status=status, cells=len(cells),
                     failed_cells=failed_cells, reused_cells=reused_cells, scenes_rendered=rendered,
                     scenes_reused=reused, elapsed_s=time.perf_counter() - t_start)


def _sequence_dir(v: SceneVariant, cache: Path) -> Path:
    """Where the render cache keeps (or will keep) the sequence of ``v``: its absolute path."""
    from scenes.cache import cache_key

    return (cache / cache_key(v.spec)).resolve()


def _cell_entry(c: Cell, cache: Path) -> dict:
    """A cell in run.json; ``sequence`` is its sequence folder, so readers need not scan the cache."""
    return cell_entry(cell_id=c.cell_id, scene=c.variant.label, seed=c.variant.seed, pipeline=c.pipeline,
                      config_hash=c.config_hash, sequence=_sequence_dir(c.variant, cache))


def _failures(cells_dir: Path, cells: list[Cell]) -> list[str]:
    out = []
    for c in cells:
        info = _cell_info(cells_dir / c.cell_id) or {}
        if info.get("status") != "ok":
            out.append(f"{c.cell_id} {c.variant.label} seed {c.variant.seed} x {c.pipeline}: "
                       f"{info.get('error') or 'no result'}")
    return out


def _remove_strays(cells_dir: Path, cells: list[Cell]) -> None:
    """Cell folders that are not cells of this suite (cannot happen unless edited by hand)."""
    wanted = {c.cell_id for c in cells}
    for p in cells_dir.iterdir():
        if p.is_dir() and p.name not in wanted:
            shutil.rmtree(p, ignore_errors=True)


# A task whose worker process died is retried: first in a fresh pool with the other lost
# tasks (most were only queued behind the one that died), then alone in a pool of its own,
# so that one task that kills its worker cannot take an innocent task down with it.
RETRY_ROUNDS = ("parallel", "parallel", "isolated")


@dataclass
class _Work:
    """What ``_execute`` still has to do, and what it has seen so far."""

    renders: list[str]  # scene keys to render
    cells: list[tuple[Cell, dict]]  # cells ready to run, with their render result
    rendered: int = 0
    reused: int = 0
    render_failed: int = 0


def _execute(todo: list[Cell], cells_dir: Path, cache: Path, provenance: dict, suite: Suite,
             executor: str, workers: int | None, scheduler: str | None,
             progress: bool) -> tuple[int, int, int]:
    """Render the scenes ``todo`` needs, then run its cells as their scene becomes ready.

    Returns (scenes rendered, scenes reused from the cache, scenes that failed to render).
    """
    from tqdm import tqdm

    if not todo:
        return 0, 0, 0
    imports = list(getattr(suite, "imports", None) or [])
    by_scene: dict[str, list[Cell]] = {}
    variants: dict[str, SceneVariant] = {}
    for c in todo:
        key = _variant_key(c.variant)
        by_scene.setdefault(key, []).append(c)
        variants[key] = c.variant
    cache.mkdir(parents=True, exist_ok=True)
    bar = tqdm(total=len(variants) + len(todo), desc="scenes+cells", unit="task",
               disable=not progress, file=sys.stderr, dynamic_ncols=True)
    ctx = {"cells_dir": cells_dir, "cache": cache, "provenance": provenance, "imports": imports,
           "variants": variants, "by_scene": by_scene, "bar": bar, "progress": progress}
    work = _Work(renders=list(variants), cells=[])
    for mode in RETRY_ROUNDS:
        if not work.renders and not work.cells:
            break
        if mode == "parallel":
            work = _round(work, ctx, executor, workers, scheduler)
        else:  # each remaining task alone in a fresh single-worker pool
            left = _Work(renders=[], cells=[], rendered=work.rendered, reused=work.reused,
                         render_failed=work.render_failed)
            for item in [("render", k) for k in work.renders] + [("cell", c) for c in work.cells]:
                one = _Work(renders=[item[1]] if item[0] == "render" else [],
                            cells=[item[1]] if item[0] == "cell" else [])
                one = _round(one, ctx, executor, 1 if executor != "dask" else None, scheduler)
                left.renders += one.renders
                left.cells += one.cells
                left.rendered += one.rendered
                left.reused += one.reused
                left.render_failed += one.render_failed
            work = left
        lost = len(work.renders) + len(work.cells)
        if lost:
            _say(progress, f"{lost} task(s) lost with a worker process that died; retrying them")
    # still lost after every retry: the task itself kills its worker (a crash in native code, OOM)
    lost_msg = f"WorkerLost: the worker process died {len(RETRY_ROUNDS)} times running this"
    for key in work.renders:
        work.render_failed += 1
        for c in by_scene[key]:
            work.cells.append((c, {"path": None, "error": f"{lost_msg} scene's rendering"}))
    for c, render in work.cells:
        payload = _cell_payload(c, render, ctx)
        payload["render_error"] = render.get("error") or f"{lost_msg} cell"
        cell_task(payload)  # records the failure (in this process: it raises before any work)
        bar.update(1)
    bar.close()
    return work.rendered, work.reused, work.render_failed


def _cell_payload(c: Cell, render: dict, ctx: dict) -> dict:
    payload = _payload(c, ctx["cells_dir"], ctx["provenance"], ctx["imports"])
    payload["sequence"] = render["path"]
    if render.get("error"):
        payload["render_error"] = render["error"]
        payload["render_traceback"] = render.get("traceback", "")
    return payload


# Rough cost of a pair of frames per pixel, relative to Lucas-Kanade, by flow method: only the
# order of cells depends on it (longest first), never a result. Unknown methods count as 2.
FLOW_COST = {"lucas_kanade": 1.0, "farneback": 1.0, "dis": 0.5, "ilk": 2.0, "horn_schunck": 4.0, "tvl1": 8.0,
             "tv_l1": 4.0}


def _scene_cost(v: SceneVariant) -> float:
    """Frames x pixels of a scene variant (the work of rendering it, and of each of its cells)."""
    img = getattr(v.spec, "image", None)
    if img is None:
        return 1.0
    return float(img.n_frames) * float(img.width_px) * float(img.height_px)


def cell_cost(cell: Cell) -> float:
    """Estimated work of a cell: frames x pixels x the flow method's :data:`FLOW_COST`."""
    flow = cell.pipeline_spec.get("flow") if isinstance(cell.pipeline_spec, Mapping) else None
    method = flow.get("method") if isinstance(flow, Mapping) else None
    return _scene_cost(cell.variant) * FLOW_COST.get(str(method), 2.0)


def _in_flight_limit(executor: str, workers: int | None) -> int | None:
    """Tasks handed to the executor at once: one per worker and one queued behind them.

    Holding the rest back lets the runner pick the next task when a worker frees up
    (renders first, then the longest ready cell), instead of the pool's first-in-first-out
    queue. A remote dask cluster has its own workers and scheduler: no limit there.
    """
    from harness.executors import default_workers

    if executor == "dask":
        return None
    return (workers or default_workers()) + 1


def _round(work: _Work, ctx: dict, executor: str, workers: int | None, scheduler: str | None) -> _Work:
    """Run ``work`` on one executor; returns what was lost with a dead worker (to retry).

    Scheduling: renders go first, largest scene first (they unblock cells); a scene's
    cells become ready when its render returns; whenever a worker frees up, the longest
    ready cell (:func:`cell_cost`) is handed out, so the run does not end on a long cell
    started last while the other workers idle.
    """
    from harness.executors import open_executor

    lost = _Work(renders=[], cells=[], rendered=work.rendered, reused=work.reused,
                 render_failed=work.render_failed)
    bar = ctx["bar"]
    limit = _in_flight_limit(executor, workers)
    renders = sorted(work.renders, key=lambda k: -_scene_cost(ctx["variants"][k]))
    ready: list[tuple[float, int, tuple[Cell, dict]]] = []  # a heap: the longest cell on top
    order = itertools.count()  # ties keep the suite's order

    def make_ready(item: tuple[Cell, dict]) -> None:
        heapq.heappush(ready, (-cell_cost(item[0]), next(order), item))

    for item in work.cells:
        make_ready(item)
    with open_executor(executor, workers=workers, scheduler=scheduler) as pool:
        pending: dict[Future, tuple[str, Any]] = {}

        def fill() -> None:
            """Hand out tasks until the in-flight limit: renders first, then the longest cell."""
            while renders or ready:
                if limit is not None and len(pending) >= limit:
                    return
                if renders:
                    submit("render", renders.pop(0))
                else:
                    submit("cell", heapq.heappop(ready)[2])

        def submit(kind: str, item: Any) -> None:
            try:
                if kind == "render":
                    v = ctx["variants"][item]
                    fut = pool.submit(render_task, item, v.spec, str(ctx["cache"]), ctx["imports"])
                else:
                    fut = pool.submit(cell_task, _cell_payload(item[0], item[1], ctx))
            except RuntimeError:  # BrokenProcessPool (a RuntimeError) or a shut-down executor
                (lost.renders.append(item) if kind == "render" else lost.cells.append(item))
                return
            pending[fut] = (kind, item)

        fill()
        while pending:
            done, _ = wait(list(pending), return_when=FIRST_COMPLETED)
            for fut in done:
                kind, item = pending.pop(fut)
                try:
                    result = fut.result()
                except Exception:  # our tasks record their own failures: this is a lost worker
                    (lost.renders.append(item) if kind == "render" else lost.cells.append(item))
                    continue
                bar.update(1)
                if kind == "render":
                    if result["error"]:
                        lost.render_failed += 1
                    elif result["reused"]:
                        lost.reused += 1
                    else:
                        lost.rendered += 1
                    for c in ctx["by_scene"][item]:
                        make_ready((c, result))
                elif result["status"] != "ok" and ctx["progress"]:
                    bar.write(f"cell {result['cell_id']} failed: {result['error']}", file=sys.stderr)
            fill()  # after a broken pool, every submit lands in ``lost`` and ``pending`` empties
    return lost
