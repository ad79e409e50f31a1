"""Run a suite: the library entry point :func:`run_suite`, and what it returns.

``aerobench run`` only parses, calls :func:`run_suite`, prints and picks the exit code.
The run folder is laid out as docs/architecture.md says. The jobs of a run each have
their own module:

- :mod:`harness.resume`: the run folder's lock, what a resumed run keeps, clean-up
  after a killed run;
- :mod:`harness.scheduling`: the executor rounds, retries after a lost worker, the
  cost model that orders cells, progress;
- :mod:`harness.tasks`: what a worker does (render a scene, run a cell into its folder);
- :mod:`harness.cell_scoring`: a cell's pipeline run and its scores;
- :mod:`harness.run_folder` and :mod:`harness.cell_artifacts`: the files written.

A cell's results depend only on its inputs (no shared RNG), and rows are sorted on
collection, so the accuracy numbers do not depend on the executor or the number of
workers. ``resume=True`` keeps every complete cell folder whose config hash matches,
so a run killed at any moment (SIGKILL included) finishes with the same results.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import pandas as pd

from harness.cell_scoring import point_seeds
from harness.resume import (RunFolderError, cell_complete, clean_partial, failures, open_run_dir, read_run_json,
                            remove_strays)
from harness.results import CellRowsReader, collect_cells
from harness.run_folder import cell_entry, write_run
from harness.scheduling import cell_cost, execute, say
from harness.suites import Cell, SceneVariant, Suite, expand, load_suite
from harness.tasks import cell_payload, cell_task, render_task

__all__ = ["RunFolderError", "RunResult", "default_cache_dir", "run_suite", "render_task", "cell_task",
           "point_seeds", "cell_cost"]

CACHE_ENV = "AEROBENCH_CACHE"

# the names benchmarks and older callers used when all of this lived here
_payload = cell_payload
_execute = execute


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
    on_cells_done: Callable[[Path, pd.DataFrame | None], object] | None = None,
) -> RunResult:
    """Run every cell of ``suite`` into the run folder ``out_dir`` and collect the results.

    Parameters
    ----------
    suite : Suite, built-in suite name or path to a suite YAML
    out_dir : path
        The run folder; must be empty or absent unless ``resume``.
    workers : int, optional
        Worker processes (``process``, ``dask-local``); default one per core, fewer when the
        work would not keep them busy (:func:`harness.scheduling.run_workers`).
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
    on_cells_done : callable, optional
        Called here once every cell is done, before the results are collected, with the run
        folder and :meth:`harness.results.CellRowsReader.cells_table` (one row per cell of the
        table about to be written; None when it is not at hand without reading every cell,
        e.g. cells kept by ``resume``). Work that needs only the cell folders can start then
        (``aerobench run`` starts drawing the report's figures while the results are collected);
        what it raises propagates.

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

    lock = open_run_dir(run_dir, resume)
    try:
        cells_dir = run_dir / "cells"
        cells_dir.mkdir(exist_ok=True)
        clean_partial(run_dir)
        old = read_run_json(run_dir)
        if resume and old is not None and old.get("config_hash") not in (None, suite_hash):
            raise RunFolderError(
                f"{run_dir}: holds a run of another suite configuration (config hash "
                f"{old.get('config_hash')}, this suite {suite_hash}); choose another --out"
            )
        todo = [c for c in cells if not (resume and cell_complete(cells_dir, c))]
        reused_cells = len(cells) - len(todo)
        if reused_cells:
            say(progress, f"resume: {reused_cells} of {len(cells)} cells already complete")

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
            read = CellRowsReader(run_dir)
            rendered, reused, failed = execute(
                todo, cells_dir, cache, provenance, suite, executor, workers, scheduler, progress, read
            )
        except BaseException as exc:  # Ctrl-C, a lost scheduler: say so in run.json, keep the cells
            run_info.update(status="aborted", error=f"{type(exc).__name__}: {exc}",
                            finished=datetime.now(timezone.utc).isoformat(timespec="seconds"))
            write_run(run_dir, run_info)
            raise
        say(progress, f"scenes: {rendered} rendered, {reused} reused from the cache ({cache})")

        remove_strays(cells_dir, cells)
        if on_cells_done is not None:
            on_cells_done(run_dir, read.cells_table())
        table = collect_cells(run_dir, read=read)  # sorted rows: independent of the order cells finished
        failed_cells = failures(cells_dir, cells)
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
    from scenes.footage import FootageSpec, footage_key

    if isinstance(v.spec, FootageSpec):  # its scene hash is the footage hash: the files are not read again
        return (cache / footage_key(v.spec, v.scene_hash)).resolve()
    return (cache / cache_key(v.spec)).resolve()


def _cell_entry(c: Cell, cache: Path) -> dict:
    """A cell in run.json; ``sequence`` is its sequence folder, so readers need not scan the cache;
    ``source`` says whether it is real footage (the report's "Synthetic vs real" splits by it)."""
    from scenes.footage import FootageSpec

    return cell_entry(cell_id=c.cell_id, scene=c.variant.label, seed=c.variant.seed, pipeline=c.pipeline,
                      config_hash=c.config_hash, sequence=_sequence_dir(c.variant, cache),
                      source="real" if isinstance(c.variant.spec, FootageSpec) else "synthetic")
