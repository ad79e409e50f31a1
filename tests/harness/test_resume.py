"""harness.resume: the run folder's lock, what a resumed run keeps, the clean-up after a killed run."""

from __future__ import annotations

import copy

import pytest

from harness import cell_artifacts as artifacts
from harness.results import ROWS_FILE
from harness.resume import (LOCK_FILE, RunFolderError, cell_complete, clean_partial, failures, open_run_dir,
                            read_run_json, remove_strays)
from harness.suites import expand, parse_suite
from tests.harness.harness_testdata import TINY_SUITE


@pytest.fixture
def cells():
    return expand(parse_suite({**copy.deepcopy(TINY_SUITE), "pipelines": ["thesis-lk", "dis"]}))


def _finish(cells_dir, cell, *, status="ok", config_hash=None, rows=True):
    folder = cells_dir / cell.cell_id
    folder.mkdir(parents=True)
    if rows:
        (folder / ROWS_FILE).write_bytes(b"rows")
    artifacts.write_cell_info(folder, {"cell_id": cell.cell_id, "config_hash": config_hash or cell.config_hash,
                                       "status": status, "error": "" if status == "ok" else "boom", "rows": 1,
                                       "elapsed_s": 0.1, "scene": cell.variant.label, "seed": cell.variant.seed,
                                       "pipeline": cell.pipeline})
    return folder


def test_a_folder_is_locked_once_and_a_used_one_needs_resume(tmp_path):
    run = tmp_path / "run"
    lock = open_run_dir(run, resume=False)
    try:
        assert (run / LOCK_FILE).read_text().strip().isdigit()
        with pytest.raises(RunFolderError, match=r"another aerobench run is writing into this folder"):
            open_run_dir(run, resume=True)
    finally:
        lock.__exit__(None, None, None)
    (run / "run.json").write_text('{"config_hash": "abc"}')
    with pytest.raises(RunFolderError, match=r"not empty; pass --resume"):
        open_run_dir(run, resume=False)
    open_run_dir(run, resume=True).__exit__(None, None, None)  # released: the next run may take it
    assert read_run_json(run) == {"config_hash": "abc"}
    (tmp_path / "file").write_text("x")
    with pytest.raises(RunFolderError, match=r"exists and is not a folder"):
        open_run_dir(tmp_path / "file", resume=True)


def test_resume_keeps_only_complete_successful_cells_of_the_same_configuration(tmp_path, cells):
    cells_dir = tmp_path / "cells"
    ok, failed = cells[0], cells[1]
    _finish(cells_dir, ok)
    _finish(cells_dir, failed, status="failed")
    assert cell_complete(cells_dir, ok) and not cell_complete(cells_dir, failed)
    other = tmp_path / "other"
    _finish(other, ok, config_hash="changed")
    assert not cell_complete(other, ok)
    no_rows = tmp_path / "no_rows"
    _finish(no_rows, ok, rows=False)
    assert not cell_complete(no_rows, ok)
    assert failures(cells_dir, cells) == [f"{failed.cell_id} {failed.variant.label} seed {failed.variant.seed} x "
                                          f"{failed.pipeline}: boom"]


def test_what_a_killed_run_left_half_written_is_removed(tmp_path, cells):
    run = tmp_path / "run"
    cells_dir = run / "cells"
    keep = _finish(cells_dir, cells[0])
    for partial in (cells_dir / ".tmp-x-1234", cells_dir / ".old-y-5678"):
        partial.mkdir()
    (run / ".run.json.abc.tmp").write_text("{")
    (run / "run.json").write_text("{}")
    clean_partial(run)
    assert sorted(p.name for p in cells_dir.iterdir()) == [keep.name]
    assert sorted(p.name for p in run.iterdir()) == ["cells", "run.json"]
    (cells_dir / "not-a-cell-of-this-suite").mkdir()
    remove_strays(cells_dir, cells)
    assert sorted(p.name for p in cells_dir.iterdir()) == [keep.name]
