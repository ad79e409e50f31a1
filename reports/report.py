"""``write_report``: ``report.html`` and ``report.md`` of a run folder, from one numbers model.

:func:`reports.model.build_model` computes every number once;
:func:`reports.html.render_html` and :func:`reports.markdown.render_markdown`
render it. The report reads only the run folder (through :mod:`harness.run_folder`,
:mod:`harness.results` and :mod:`harness.cell_artifacts`) and the sequence folders
run.json names. The output is deterministic: the same run folder gives the same bytes.

Nearly all of a report's time is its pictures and figures, drawn scene by scene
(:func:`reports.html.scene_block`). With ``workers > 1`` they are drawn by that many
spawned processes while this one computes the numbers; the page is the same bytes.
The blocks read only the run folder and the sequences, so they can be handed out before
the results table exists (:func:`start_figures`: ``aerobench run`` does so when its
cells are done, and the figures are drawn while the results are collected); the report
uses them only if the cells they were drawn for are the table's.
"""

from __future__ import annotations

import dataclasses
import multiprocessing
import os
import sys
from collections.abc import Callable, Iterator, Mapping
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager, nullcontext
from pathlib import Path

import pandas as pd

from harness.run_folder import read_run
from reports.html import (FILES_DIR, SCENE_SECTIONS, SceneBlock, block_files, cell_index, render_html, render_html_bytes,
                          scene_block, scene_blocks)
from reports.load import RunData, load_cells, load_run, scene_base
from reports.markdown import render_markdown
from reports.model import ReportModel, build_model
from scenes.formats import atomic_write_bytes

__all__ = ["write_report", "build_report", "figure_pool", "start_figures", "Figures"]


def _warm_up() -> None:
    """In a fresh figure process: import what drawing needs (pandas, matplotlib, the report's modules)
    while the parent reads the results table."""
    import reports.html  # noqa: F401


def _draw_block(data: RunData, cells: pd.DataFrame, section: str, base: str) -> SceneBlock:
    """:func:`scene_block` in a figure process (a module-level function, so that spawn can find it)."""
    return scene_block(data, cells, section, base)


@contextmanager
def figure_pool(run_dir: str | os.PathLike, workers: int | None) -> Iterator[ProcessPoolExecutor | None]:
    """``workers`` spawned figure processes (None: one per core, at most one per scene), started and importing
    at once; None when one process (this one) is all there is to use. No more than the run has scene blocks.

    A figure process first imports what drawing needs (~2 s of CPU, about what one scene's blocks take to
    draw), so by default a one-scene report is drawn here: two processes started for it took twice the CPU
    (4.3 -> 8.4 s for `aerobench report` of tiny) and no less time."""
    from harness.executors import default_workers, worker_setup, worker_threads

    n = workers or default_workers()
    try:  # run.json names the cells: a block a section a scene at most
        scenes = len({scene_base(c.scene) for c in read_run(run_dir).cells})
        n = min(n, len(SCENE_SECTIONS) * scenes if workers else scenes)
    except (OSError, ValueError):  # load_run reports it, in one place
        pass
    if n <= 1:
        yield None
        return
    pool = ProcessPoolExecutor(max_workers=n, mp_context=multiprocessing.get_context("spawn"),
                               initializer=worker_setup, initargs=(worker_threads(n),))
    try:
        for _ in range(n):
            pool.submit(_warm_up)
        yield pool
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


@dataclasses.dataclass
class Figures:
    """Scene blocks handed to figure processes before the report is built (:func:`start_figures`)."""

    pool: ProcessPoolExecutor
    data: RunData                # the run folder without rows: what the blocks read
    cells: pd.DataFrame          # the cell index (:func:`reports.html.cell_index`) they are drawn for
    futures: dict[tuple[str, str], Future]
    lost: BrokenProcessPool | None = None  # the pool broke while they were handed out

    def fit(self, data: RunData, cells: pd.DataFrame) -> bool:
        """Whether these blocks are the ones ``data`` (with its cell index ``cells``) calls for:
        the same run folder, cells of run.json, pipelines (their colours) and cell index."""
        return (self.data.run_dir == data.run_dir and self.data.folder.cells == data.folder.cells
                and self.data.pipelines == data.pipelines and list(self.cells.columns) == list(cells.columns)
                and list(self.cells.dtypes) == list(cells.dtypes) and self.cells.equals(cells))

    def cancel(self) -> None:
        for fut in self.futures.values():
            fut.cancel()


def start_figures(run_dir: str | os.PathLike, cells: pd.DataFrame, pool: ProcessPoolExecutor) -> Figures:
    """Hand ``pool`` (:func:`figure_pool`) every scene block of ``run_dir`` before its results table exists.

    ``cells`` is :func:`harness.results.cell_table` of the table to come (the runner has it from
    the cells' rows: :meth:`harness.results.CellRowsReader.cells_table`). :func:`build_report`
    given the result uses the blocks when its own cell index, pipelines and run.json cells are the
    same (else it draws them again); a figure process that dies meanwhile costs only time.
    """
    data = load_cells(run_dir, cells)
    index = cell_index(data)
    light = dataclasses.replace(data, ok=data.ok.iloc[:0])
    figures = Figures(pool=pool, data=light, cells=index, futures={})
    try:
        for key in scene_blocks(index):
            figures.futures[key] = pool.submit(_draw_block, light, index, *key)
    except BrokenProcessPool as exc:  # already broken: the report draws the blocks not handed out
        figures.lost = exc
    return figures


def _draw_blocks(data: RunData, pool: ProcessPoolExecutor | None, progress: bool,
                 numbers: Callable[[], object], early: Figures | None = None
                 ) -> tuple[object, dict[tuple[str, str], SceneBlock]]:
    """``numbers()`` here while ``pool`` draws the scene blocks: (its result, the blocks).

    Without a pool, the numbers and then each block in this process. ``early``: blocks handed
    out already (:func:`start_figures`), used when they fit ``data``. A figure process that
    dies (killed, out of memory) costs nothing but time: the blocks it left are drawn here.
    """
    from tqdm import tqdm

    cells = cell_index(data)
    keys = scene_blocks(cells)
    bar = tqdm(total=len(keys), desc="report figures", unit="figure", disable=not progress, file=sys.stderr,
               dynamic_ncols=True)
    futures: dict[tuple[str, str], Future] = {}
    broken: list[BrokenProcessPool] = []

    def died(exc: BrokenProcessPool) -> None:
        if not broken:
            print(f"aerobench: warning: a report figure process died ({exc}); drawing the rest here",
                  file=sys.stderr)
        broken.append(exc)

    if early is not None and not early.fit(data, cells):
        early.cancel()  # drawn for other cells: drawn again below
        early = None
    try:
        if early is not None:
            futures = {key: early.futures[key] for key in keys if key in early.futures}
            for fut in futures.values():
                fut.add_done_callback(lambda _: bar.update())
            if early.lost is not None:
                died(early.lost)
        elif pool is not None and len(keys) > 1:
            # the processes need the folder, not its rows: the table is left out of what is pickled to them
            light = dataclasses.replace(data, table=data.table.iloc[:0], ok=data.ok.iloc[:0])
            try:
                for key in keys:
                    futures[key] = pool.submit(_draw_block, light, cells, *key)
                    futures[key].add_done_callback(lambda _: bar.update())
            except BrokenProcessPool as exc:  # already broken: the blocks not handed out are drawn here
                died(exc)
        result = numbers()
        blocks = {}
        for key in keys:
            if key in futures and not broken:
                try:
                    blocks[key] = futures[key].result()
                    continue
                except BrokenProcessPool as exc:
                    died(exc)
            blocks[key] = scene_block(data, cells, *key)
            bar.update()
        return result, blocks
    finally:
        bar.close()


def build_report(run_dir: str | os.PathLike, *, baseline: str | os.PathLike | None = None,
                 gate_verdict: str | os.PathLike | Mapping | None = None,
                 rules: str | os.PathLike | None = None, workers: int | None = 1,
                 progress: bool = False, table: pd.DataFrame | None = None,
                 figures: Figures | None = None) -> tuple[str, str]:
    """The HTML and Markdown text of the report of ``run_dir`` (see :func:`write_report`). The pictures the
    HTML references (``report_files/``) are not written: :func:`write_report` writes them."""
    model, blocks = _model_and_blocks(run_dir, baseline=baseline, gate_verdict=gate_verdict, rules=rules,
                                      workers=workers, progress=progress, table=table, figures=figures)
    return render_html(model, blocks), render_markdown(model)


def _model_and_blocks(run_dir: str | os.PathLike, *, baseline, gate_verdict, rules, workers: int | None,
                      progress: bool, table: pd.DataFrame | None, figures: Figures | None
                      ) -> tuple[ReportModel, dict[tuple[str, str], SceneBlock]]:
    """The numbers of the report and its scene blocks (see :func:`write_report`)."""
    # the processes start while the table is read; blocks handed out early come with their own
    with nullcontext(figures.pool) if figures is not None else figure_pool(run_dir, workers) as pool:
        data = load_run(run_dir, table=table)
        return _draw_blocks(data, pool, progress, lambda: build_model(
            run_dir, baseline=baseline, gate_verdict=gate_verdict, rules=rules, data=data), early=figures)


def write_report(run_dir: str | os.PathLike, *, baseline: str | os.PathLike | None = None,
                 gate_verdict: str | os.PathLike | Mapping | None = None, rules: str | os.PathLike | None = None,
                 out_dir: str | os.PathLike | None = None, workers: int | None = 1,
                 progress: bool = False, table: pd.DataFrame | None = None,
                 figures: Figures | None = None) -> dict[str, Path]:
    """Write ``report.html`` and ``report.md`` for the run folder ``run_dir``, and the pictures of
    report.html in ``report_files/`` beside it (downscaled to their shown size, named by their content;
    files of an earlier report that this one does not reference are removed).

    Parameters
    ----------
    run_dir : path
        A run folder (run.json, results.parquet, cells/).
    baseline : path, optional
        A baseline of ``aerobench baseline``; compared with the gate's rules (:func:`harness.gate.compare`).
    gate_verdict : path or dict, optional
        A verdict of ``aerobench gate --json``, shown at the top.
    rules : path, optional
        Gate rules YAML for the baseline comparison (default: the gate's ``gate_rules.yaml``).
    out_dir : path, optional
        Where to write; default ``run_dir``.
    workers : int, optional
        Processes drawing the pictures and figures (spawned; 1: this process alone, None: one
        per core). The bytes written do not depend on it.
    progress : bool
        A progress bar of the figures on stderr.
    table : DataFrame, optional
        The run's results table as :func:`harness.results.collect_cells` returned it (the same
        rows, dtypes and order as results.parquet reads back); default: read results.parquet.
    figures : Figures, optional
        Scene blocks handed out already (:func:`start_figures`); drawn by their pool, not
        ``workers`` new processes. Used only if they are the blocks of this run's table.

    Returns
    -------
    dict
        ``{"html": Path, "md": Path}`` (the pictures' folder is ``html.parent / "report_files"``).
    """
    model, blocks = _model_and_blocks(run_dir, baseline=baseline, gate_verdict=gate_verdict, rules=rules,
                                      workers=workers, progress=progress, table=table, figures=figures)
    out = Path(out_dir) if out_dir is not None else Path(run_dir)
    paths = {"html": out / "report.html", "md": out / "report.md"}
    files = block_files(blocks)
    _write_files(out / FILES_DIR, files)  # before the page that references them
    atomic_write_bytes(paths["html"], render_html_bytes(model, blocks))  # the text of build_report, encoded
    atomic_write_bytes(paths["md"], render_markdown(model).encode("utf-8"))
    _remove_stale(out / FILES_DIR, files)
    return paths


def _write_files(folder: Path, files: dict[str, bytes]) -> None:
    """The report's pictures into ``folder``; a file there already has the same bytes (named by them)."""
    if files:
        folder.mkdir(parents=True, exist_ok=True)
    for name, data in files.items():
        path = folder / name
        if not (path.is_file() and path.stat().st_size == len(data)):
            atomic_write_bytes(path, data)


def _remove_stale(folder: Path, files: dict[str, bytes]) -> None:
    """Files of an earlier report of this folder that the new one does not reference."""
    if not folder.is_dir():
        return
    for path in sorted(folder.iterdir()):
        if path.is_file() and path.name not in files:
            path.unlink()
    if not files:
        try:
            folder.rmdir()
        except OSError:  # something else was put there: left alone
            pass
