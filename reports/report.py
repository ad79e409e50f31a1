"""``write_report``: ``report.html`` and ``report.md`` of a run folder, from one numbers model.

:func:`reports.model.build_model` computes every number once;
:func:`reports.html.render_html` and :func:`reports.markdown.render_markdown`
render it. The report reads only the run folder (through :mod:`harness.run_folder`,
:mod:`harness.results` and :mod:`harness.cell_artifacts`) and the sequence folders
run.json names. The output is deterministic: the same run folder gives the same bytes.

Nearly all of a report's time is its pictures and figures, drawn scene by scene
(:func:`reports.html.scene_block`). With ``workers > 1`` they are drawn by that many
spawned processes while this one computes the numbers; the page is the same bytes.
"""

from __future__ import annotations

import dataclasses
import multiprocessing
import os
import sys
from collections.abc import Mapping
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import pandas as pd

from reports.html import cell_index, render_html, scene_block, scene_blocks
from reports.load import RunData, load_run
from reports.markdown import render_markdown
from reports.model import build_model
from scenes.formats import atomic_write_bytes

__all__ = ["write_report", "build_report"]


def _draw_block(data: RunData, cells: pd.DataFrame, section: str, base: str) -> str:
    """:func:`scene_block` in a worker process (a module-level function, so that spawn can find it)."""
    return scene_block(data, cells, section, base)


def _draw_blocks(data: RunData, workers: int | None, progress: bool,
                 numbers) -> tuple[object, dict[tuple[str, str], str]]:
    """``numbers()`` here while the scene blocks are drawn by ``workers`` processes: (its result, the blocks)."""
    from tqdm import tqdm

    from harness.executors import default_workers, worker_setup, worker_threads

    cells = cell_index(data)
    keys = scene_blocks(cells)
    n = min(workers or default_workers(), len(keys))
    bar = tqdm(total=len(keys), desc="report figures", unit="figure", disable=not progress, file=sys.stderr,
               dynamic_ncols=True)
    try:
        if n <= 1:  # no process to spare: the numbers, then each block, in this process
            result = numbers()
            blocks = {}
            for key in keys:
                blocks[key] = scene_block(data, cells, *key)
                bar.update()
            return result, blocks
        # the workers need the folder, not its rows: leave the table out of what is pickled to them
        light = dataclasses.replace(data, table=data.table.iloc[:0], ok=data.ok.iloc[:0])
        with ProcessPoolExecutor(max_workers=n, mp_context=multiprocessing.get_context("spawn"),
                                 initializer=worker_setup, initargs=(worker_threads(n),)) as pool:
            futures = {key: pool.submit(_draw_block, light, cells, *key) for key in keys}
            for f in futures.values():
                f.add_done_callback(lambda _: bar.update())
            result = numbers()
            return result, {key: f.result() for key, f in futures.items()}
    finally:
        bar.close()


def build_report(run_dir: str | os.PathLike, *, baseline: str | os.PathLike | None = None,
                 gate_verdict: str | os.PathLike | Mapping | None = None,
                 rules: str | os.PathLike | None = None, workers: int | None = 1,
                 progress: bool = False) -> tuple[str, str]:
    """The HTML and Markdown text of the report of ``run_dir`` (see :func:`write_report`)."""
    data = load_run(run_dir)
    model, blocks = _draw_blocks(data, workers, progress, lambda: build_model(
        run_dir, baseline=baseline, gate_verdict=gate_verdict, rules=rules, data=data))
    return render_html(model, blocks), render_markdown(model)


def write_report(run_dir: str | os.PathLike, *, baseline: str | os.PathLike | None = None,
                 gate_verdict: str | os.PathLike | Mapping | None = None, rules: str | os.PathLike | None = None,
                 out_dir: str | os.PathLike | None = None, workers: int | None = 1,
                 progress: bool = False) -> dict[str, Path]:
    """Write ``report.html`` and ``report.md`` for the run folder ``run_dir``.

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

    Returns
    -------
    dict
        ``{"html": Path, "md": Path}``.
    """
    html_text, md_text = build_report(run_dir, baseline=baseline, gate_verdict=gate_verdict, rules=rules,
                                      workers=workers, progress=progress)
    out = Path(out_dir) if out_dir is not None else Path(run_dir)
    paths = {"html": out / "report.html", "md": out / "report.md"}
    atomic_write_bytes(paths["html"], html_text.encode("utf-8"))
    atomic_write_bytes(paths["md"], md_text.encode("utf-8"))
    return paths
