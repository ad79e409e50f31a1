"""The runner: failing cells recorded, same numbers on 1 or 2 workers, run folder rules (kill -9 and resume:
tests/reliability/test_faults.py)."""

from __future__ import annotations

import copy
import fcntl
from pathlib import Path

import pandas as pd
import numpy as np
import pytest
from tests.harness.harness_testdata import RESUME_SUITE, TINY_SUITE, accuracy_table

from harness.cli import main
from harness.results import read_results, read_run_json
from harness.runner import RunFolderError, run_suite
from harness.suites import parse_suite

def _partial_files(run_dir: Path) -> list[str]:
    return [str(p) for p in run_dir.rglob("*") if p.name.startswith((".tmp-", ".old-")) or p.name.endswith(".tmp")]


@pytest.mark.gl
@pytest.mark.slow
def test_run_folder_is_complete(reference_run):
    run_dir = reference_run.run_dir
    table = read_results(run_dir)
    assert table["cell_id"].nunique() == reference_run.cells == 6
    assert set(table["status"]) == {"ok"}
    assert {"epe_mean", "shift_error"} <= set(table["metric"])
    meta = read_run_json(run_dir)
    assert meta["status"] == "ok" and meta["suite"] == "test-resume"
    assert len(meta["cells"]) == 6 and meta["config_hash"]
    assert meta["provenance"]["git_commit"] == table["git_commit"].iloc[0]
    assert (run_dir / "summary.csv").stat().st_size > 0
    for cell in meta["cells"]:
        folder = run_dir / "cells" / cell["cell_id"]
        assert (folder / "rows.parquet").is_file()
        assert (folder / "flow_000000.flo").is_file()
        stab = pd.read_csv(folder / "stabilisation.csv")
        assert len(stab) == 4 and "true_jitter_x_px" in stab
        assert (folder / "tracks.csv").is_file()
        assert not (folder / "error.txt").exists()
    assert not _partial_files(run_dir)


@pytest.mark.gl
@pytest.mark.slow
def test_two_workers_give_the_same_numbers(reference_run, tmp_path, render_cache):
    result = run_suite(parse_suite(copy.deepcopy(RESUME_SUITE)), tmp_path / "run", workers=2,
                       cache_dir=render_cache, progress=False)
    assert result.ok
    assert result.scenes_rendered == 0 and result.scenes_reused == 2  # the cache is shared
    pd.testing.assert_frame_equal(accuracy_table(result.table), accuracy_table(reference_run.table))


@pytest.mark.gl
@pytest.mark.slow
def test_a_failing_cell_is_recorded_and_the_run_goes_on(tmp_path, render_cache, write_suite, capsys):
    # the plugin's flow method raises on 64 px wide frames only: one scene of two fails
    suite = {**copy.deepcopy(TINY_SUITE), "name": "test-failing", "imports": ["tests.harness.aerobench_test_plugin"],
             "scenes": [{"preset": "tiny", "overrides": {"image.n_frames": 3}},
                        {"preset": "tiny", "label": "narrow",
                         "overrides": {"image.n_frames": 3, "image.width_px": 64, "image.height_px": 48}}],
             "pipelines": [{"name": "explodes-on-narrow", "base": "thesis-lk",
                            "spec": {"flow": {"method": "raise_on_narrow", "params": {}}}}]}
    code = main(["run", str(write_suite(suite)), "--out", str(tmp_path / "run"), "--workers", "2",
                 "--cache", str(render_cache), "--quiet", "--no-report"])
    assert code == 1  # the run finished, and says that something failed
    err = capsys.readouterr().err
    assert "1 of 2 cells failed" in err
    assert "narrow" in err and "planned failure on a narrow frame" in err
    table = read_results(tmp_path / "run")
    failed = table[table["status"] == "failed"]
    assert set(failed["scene"]) == {"narrow"}
    assert failed["error"].str.contains("planned failure").all()
    assert set(table[table["status"] == "ok"]["scene"]) == {"tiny"}
    folder = tmp_path / "run" / "cells" / failed["cell_id"].iloc[0]
    assert "RuntimeError" in (folder / "error.txt").read_text()
    assert read_run_json(tmp_path / "run")["status"] == "failed"


def test_a_non_empty_folder_is_refused_without_resume(tmp_path):
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(RunFolderError, match=r"not empty; pass --resume"):
        run_suite(parse_suite(copy.deepcopy(TINY_SUITE)), tmp_path, progress=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]


def test_two_runs_into_one_folder_are_refused(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    with open(out / ".lock", "w") as fh:  # what a running aerobench holds
        fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        with pytest.raises(RunFolderError, match=r"another aerobench run is writing into this folder"):
            run_suite(parse_suite(copy.deepcopy(TINY_SUITE)), out, resume=True, progress=False)


def test_each_pipeline_is_warmed_up_once_per_process_before_timing(monkeypatch):
    from harness import cell_scoring

    runs = []

    class Recording:
        hash = "pipeline-under-test"

        def run(self, frames, *, seeds):
            runs.append((len(frames), frames[0].shape, frames[0].dtype, seeds))
            yield from ()

    monkeypatch.setattr(cell_scoring, "_WARMED", set())
    cell_scoring.warm_up(Recording())
    cell_scoring.warm_up(Recording())  # the same pipeline again: no second warm-up
    assert runs == [(3, (64, 64), np.dtype(np.uint8), [(1, 32.0, 32.0)])]
