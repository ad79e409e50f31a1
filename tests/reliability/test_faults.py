"""Faults survived: a worker killed mid-task, the whole run killed at random points, a GL failure.

Nothing may be lost: every cell that completed stays complete, ``--resume`` finishes the
run with exactly the numbers of an uninterrupted run, and no file is ever seen half-written.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from tests.reliability.rel_plugin import GL_FAIL_WIDTH_PX
from tests.reliability.rel_support import ROOT, assert_all_readable, assert_bit_identical, partial_files, suite, tree_state

from harness.results import read_results, read_run_json
from harness.runner import run_suite
from harness.suites import parse_suite

KILL_SEED = 20261122
N_KILLS = 3  # at random points; then one more just after a cell is finished


def _dying_suite(marker: Path) -> dict:
    return suite(imports=["tests.reliability.rel_plugin"], pipelines=[
        "thesis-lk",
        {"name": "dies", "base": "thesis-lk", "spec": {"flow": {"method": "die_once", "params": {"marker": str(marker)}}}},
    ])


def _complete_cells(run_dir: Path) -> dict[str, str]:
    """Cell folders under their final name -> a hash of their rows (the results a resume must keep)."""
    cells = run_dir / "cells"
    state = tree_state(cells)
    return {k: v for k, v in state.items() if not k.startswith(".") and k.endswith("rows.parquet")}


@pytest.mark.gl
@pytest.mark.slow
def test_a_worker_killed_mid_task_is_retried_and_nothing_is_lost(tmp_path, rel_cache):
    marker = tmp_path / "die"
    marker.touch()
    out = tmp_path / "run"
    result = run_suite(parse_suite(_dying_suite(marker)), out, workers=2, cache_dir=rel_cache, progress=False)
    assert not marker.exists(), "the worker never ran the dying cell"
    # the killed task ran again in a fresh worker (the marker is gone, so it succeeds there)
    assert result.ok, result.failed_cells
    assert result.cells == 4 and result.table["cell_id"].nunique() == 4
    assert read_run_json(out)["status"] == "ok"
    assert_all_readable(out)
    _assert_nothing_half_written(out)
    assert not partial_files(out)


@pytest.mark.gl
@pytest.mark.slow
def test_a_cell_that_always_kills_its_worker_is_recorded_as_failed(tmp_path, rel_cache):
    marker = tmp_path / "die"
    marker.touch()
    s = _dying_suite(marker)
    s["seeds"] = [1]
    s["pipelines"][1]["spec"]["flow"]["params"]["always"] = True
    out = tmp_path / "run"
    result = run_suite(parse_suite(s), out, workers=1, cache_dir=rel_cache, progress=False)
    assert result.status == "failed" and result.cells == 2
    (line,) = result.failed_cells
    assert " x dies: " in line and re.search(r"worker process died", line), line
    table = read_results(out)
    assert set(table.loc[table["status"] == "ok", "pipeline"]) == {"thesis-lk"}  # the other cell is kept
    assert read_run_json(out)["status"] == "failed"
    assert not partial_files(out)


@pytest.mark.gl
@pytest.mark.slow
def test_a_gl_failure_fails_the_cells_of_that_scene_not_the_run(tmp_path, rel_cache):
    s = suite(imports=["tests.reliability.rel_plugin"], seeds=[1], pipelines=["dis"], scenes=[
        {"preset": "tiny", "overrides": {"image.n_frames": 3}},
        {"preset": "tiny", "label": "broken-gl",
         "overrides": {"image.n_frames": 3, "image.width_px": GL_FAIL_WIDTH_PX, "image.height_px": 54}},
    ])
    result = run_suite(parse_suite(s), tmp_path / "run", workers=2, cache_dir=rel_cache, progress=False)
    assert result.status == "failed" and result.cells == 2
    (line,) = result.failed_cells
    assert "broken-gl" in line and "RendererUnavailableError" in line and "simulated GL failure" in line
    table = read_results(tmp_path / "run")
    assert set(table.loc[table["status"] == "failed", "scene"]) == {"broken-gl"}
    ok = table[table["status"] == "ok"]
    assert set(ok["scene"]) == {"tiny"} and "epe_mean" in set(ok["metric"])
    failed_id = table.loc[table["status"] == "failed", "cell_id"].iloc[0]
    assert "simulated GL failure" in (tmp_path / "run" / "cells" / failed_id / "error.txt").read_text()
    assert not [p for p in rel_cache.iterdir() if ".partial-" in p.name]  # the failed render left nothing


def _cli_run(out: Path, suite_file: Path, env: dict, *extra: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "harness.cli", "run", str(suite_file), "--out", str(out),
                             "--workers", "1", "--quiet", "--no-report", *extra],
                            cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            start_new_session=True, text=True)


def _finished_cells(out: Path) -> dict[Path, int]:
    """cell.json of every finished cell (the folder under its final name) -> its modification time."""
    return {p: p.stat().st_mtime_ns for p in (out / "cells").glob("*/cell.json") if not p.parent.name.startswith(".")}


def _kill_after_a_new_cell(out: Path, suite_file: Path, env: dict) -> dict[Path, int] | None:
    """Resume the run and SIGKILL it as soon as it finishes a cell: the finished cells then, or None if
    the run ended before finishing a new one."""
    before = set(_finished_cells(out)) if out.exists() else set()
    proc = _cli_run(out, suite_file, env, "--resume")
    deadline = time.monotonic() + 120
    try:
        while (time.monotonic() < deadline and proc.poll() is None
               and not (out.exists() and set(_finished_cells(out)) - before)):
            time.sleep(0.02)
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)  # the CLI and its pool workers, like a lost machine
        proc.wait(timeout=30)
        if proc.returncode == 0:
            return None
        assert proc.returncode == -signal.SIGKILL, f"the run failed (exit {proc.returncode}): {proc.stderr.read()}"
    finally:
        proc.stderr.close()
    _assert_nothing_half_written(out)
    kept = _finished_cells(out)
    assert set(kept) - before, "no cell was finished within two minutes"
    return kept


def _assert_nothing_half_written(out: Path) -> None:
    assert_all_readable(out)  # final names only ever hold whole files
    for cell in (out / "cells").iterdir() if (out / "cells").is_dir() else ():
        if not cell.name.startswith("."):  # a cell folder under its final name is complete
            assert (cell / "cell.json").is_file() and (cell / "rows.parquet").is_file(), cell


@pytest.mark.gl
@pytest.mark.slow
def test_sigkill_at_random_points_then_resume_gives_the_uninterrupted_numbers(reference_run, tmp_path, rel_env):
    import yaml

    suite_file = tmp_path / "suite.yaml"
    suite_file.write_text(yaml.safe_dump(suite(), sort_keys=False))
    out = tmp_path / "run"
    rng = np.random.default_rng(KILL_SEED)
    full_s = reference_run.elapsed_s + 2.0  # the CLI's own start-up on top of the in-process run
    kills, tries = [], 0
    while len(kills) < N_KILLS and tries < 3 * N_KILLS:
        tries += 1
        delay = float(rng.uniform(0.1, 0.7) * full_s)
        fresh, started = not out.exists(), time.monotonic()
        proc = _cli_run(out, suite_file, rel_env, "--resume")
        try:
            proc.wait(timeout=delay)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)  # the CLI and its workers, like a lost machine
            proc.wait(timeout=30)
            kills.append(round(delay, 2))
        else:  # it finished before the kill: fine
            assert proc.returncode == 0, proc.stderr.read()
            if fresh:
                # a whole CLI run, timed beside whatever else runs now (another pytest worker): the
                # scale of the next kills, where the reference run's time, taken earlier, may be far off
                full_s = time.monotonic() - started
        proc.stderr.close()
        _assert_nothing_half_written(out)
        if proc.returncode == 0:
            # a finished run resumes in a second or two, where few kills can land: the next
            # segment starts the run afresh, so that every kill interrupts real work
            shutil.rmtree(out)
    assert len(kills) == N_KILLS, f"only {len(kills)} kills landed in {tries} runs: {kills}"
    # the last kill lands just after a cell is written: the resumed run must take that cell as it is
    kept = _kill_after_a_new_cell(out, suite_file, rel_env)
    if kept is None:  # the run finished first: afresh, so that the kill interrupts real work
        shutil.rmtree(out)
        kept = _kill_after_a_new_cell(out, suite_file, rel_env)
    assert kept, "no cell was written before the run ended"

    final = _cli_run(out, suite_file, rel_env, "--resume")
    _, err = final.communicate(timeout=120)
    assert final.returncode == 0, err
    meta = read_run_json(out)
    assert meta["status"] == "ok" and meta["cells_reused"] >= len(kept)
    assert {cell: cell.stat().st_mtime_ns for cell in kept} == kept, "a finished cell was computed again"
    assert_bit_identical(read_results(out), reference_run.table)
    assert not partial_files(out), partial_files(out)
    _assert_nothing_half_written(out)
