"""The run folder's lifecycle: its lock, what a resumed run keeps, what a killed run left behind.

A run folder is written by one run at a time (an ``flock`` on ``RUN/.lock``, released
by the kernel even when the run is killed). ``resume=True`` keeps every complete cell
folder whose config hash matches (:func:`cell_complete`); the temporary files and
folders of a run killed mid-write are removed first (:func:`clean_partial`), so a run
killed at any moment (SIGKILL included) finishes with the same results. What run.json
holds is :mod:`harness.run_folder`'s; what a cell folder holds is :mod:`harness.cell_artifacts`'.
"""

from __future__ import annotations

import fcntl
import json
import os
import shutil
from pathlib import Path
from typing import Any

from harness import cell_artifacts as artifacts
from harness.results import ROWS_FILE
from harness.suites import Cell

__all__ = ["LOCK_FILE", "RunFolderError", "RunLock", "open_run_dir", "read_run_json", "cell_info",
           "cell_complete", "clean_partial", "remove_strays", "failures"]

LOCK_FILE = ".lock"


class RunFolderError(ValueError):
    """The run folder cannot be used: not empty without ``resume``, or locked by another run."""


class RunLock:
    """An exclusive ``flock`` on ``RUN/.lock``: released by the kernel even if the run is killed."""

    def __init__(self, run_dir: Path):
        self.path = run_dir / LOCK_FILE
        self.fd: int | None = None

    def __enter__(self) -> RunLock:
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


def open_run_dir(run_dir: Path, resume: bool) -> RunLock:
    """Create ``run_dir`` (or accept it, with ``resume``) and take its lock; the caller releases it."""
    if run_dir.exists() and not run_dir.is_dir():
        raise RunFolderError(f"{run_dir}: exists and is not a folder")
    if run_dir.is_dir() and not resume:
        others = [p.name for p in run_dir.iterdir() if p.name != LOCK_FILE]
        if others:
            raise RunFolderError(
                f"{run_dir}: the run folder is not empty; pass --resume to finish that run, or choose another --out"
            )
    run_dir.mkdir(parents=True, exist_ok=True)
    lock = RunLock(run_dir)
    try:
        lock.__enter__()
    except RuntimeError:
        raise RunFolderError(f"{run_dir}: another aerobench run is writing into this folder ({run_dir / LOCK_FILE})") from None
    return lock


def read_run_json(run_dir: Path) -> dict | None:
    """The run.json a previous run left (to compare config hashes on resume); None when absent or unreadable."""
    try:
        return json.loads((run_dir / "run.json").read_text())
    except (OSError, ValueError):
        return None


def cell_info(folder: Path) -> dict | None:
    """A cell folder's cell.json; None when partial, unreadable or of another cell format (run again)."""
    try:
        return artifacts.read_cell_info(folder)
    except artifacts.CellArtifactError:
        return None


def cell_complete(cells_dir: Path, cell: Cell) -> bool:
    """A cell folder is kept on resume when it is complete, succeeded, and has the same config hash."""
    folder = cells_dir / cell.cell_id
    info = cell_info(folder)
    return (
        info is not None
        and info.get("config_hash") == cell.config_hash
        and info.get("status") == "ok"
        and (folder / ROWS_FILE).is_file()
    )


def clean_partial(run_dir: Path) -> None:
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


def remove_strays(cells_dir: Path, cells: list[Cell]) -> None:
    """Cell folders that are not cells of this suite (cannot happen unless edited by hand)."""
    wanted = {c.cell_id for c in cells}
    for p in cells_dir.iterdir():
        if p.is_dir() and p.name not in wanted:
            shutil.rmtree(p, ignore_errors=True)


def failures(cells_dir: Path, cells: list[Cell]) -> list[str]:
    """One line per cell that did not succeed: ``"cell_id scene seed S x pipeline: error"``."""
    out = []
    for c in cells:
        info = cell_info(cells_dir / c.cell_id) or {}
        if info.get("status") != "ok":
            out.append(f"{c.cell_id} {c.variant.label} seed {c.variant.seed} x {c.pipeline}: "
                       f"{info.get('error') or 'no result'}")
    return out
