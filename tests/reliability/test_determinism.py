"""Determinism: the same suite and seeds give bit-identical results, whatever the run or the worker count.

tests/harness/test_executors.py compares the dask-local executor with the process pool
(accuracy rows, pandas' default float tolerance); here every non-timing column is
compared exactly, across a second run with another worker count, and rendering itself
is repeated into a fresh cache.
"""

from __future__ import annotations

import json
import multiprocessing
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pandas as pd
import pytest
from tests.reliability.rel_support import assert_bit_identical, suite

from harness.results import read_results
from harness.runner import render_task, run_suite
from harness.suites import expand, parse_suite


@pytest.mark.gl
@pytest.mark.slow
def test_two_workers_and_a_second_run_give_bit_identical_tables(reference_run, tmp_path, rel_cache):
    again = run_suite(parse_suite(suite()), tmp_path / "run", workers=2, cache_dir=rel_cache, progress=False)
    assert again.ok and again.scenes_rendered == 0
    assert_bit_identical(again.table, reference_run.table)
    # what is on disk equals what was returned, and both runs' files agree too
    assert_bit_identical(read_results(tmp_path / "run"), read_results(reference_run.run_dir))
    a = pd.read_csv(tmp_path / "run" / "summary.csv")
    b = pd.read_csv(reference_run.run_dir / "summary.csv")
    acc = a["kind"] != "timing"
    pd.testing.assert_frame_equal(a[acc].reset_index(drop=True), b[b["kind"] != "timing"].reset_index(drop=True),
                                  check_exact=True)


def _manifest_hashes(path) -> dict[str, str]:
    doc = json.loads((path / "MANIFEST.json").read_text())
    return {rel: info["sha256"] for rel, info in doc["files"].items()
            if rel.startswith(("frames/", "flow/", "flow_camera/", "valid/", "instances/")) or rel.endswith(".csv")}


@pytest.mark.gl
@pytest.mark.slow
def test_rendering_the_same_spec_again_gives_the_same_bytes(reference_run, tmp_path, rel_cache):
    (cell, *_) = expand(parse_suite(suite()))
    spec = cell.variant.spec
    ctx = multiprocessing.get_context("spawn")  # this process must never hold a GL context before a fork
    with ProcessPoolExecutor(1, mp_context=ctx) as pool:
        fresh = pool.submit(render_task, "k", spec, str(tmp_path / "cache")).result(timeout=120)
        cached = pool.submit(render_task, "k", spec, str(rel_cache)).result(timeout=120)
    assert fresh["error"] is None and not fresh["reused"] and cached["reused"]
    from pathlib import Path

    a, b = _manifest_hashes(Path(fresh["path"])), _manifest_hashes(Path(cached["path"]))
    assert len(a) >= 3 * 3 + 2 and a == b


def test_aggregate_is_exact_whatever_the_row_order():
    # sums of floats depend on their order; the results must not depend on which cell finished first
    from harness.metrics import aggregate

    rng = np.random.default_rng(7)
    n = 400
    rows = pd.DataFrame({"pipeline": "p", "metric": "epe_mean", "region": "all", "motion": "total",
                         "kind": "accuracy", "value": 0.0, "sum": rng.lognormal(0, 3, n) * 1e3,
                         "count": rng.integers(1, 10_000, n).astype(float), "unit": "px",
                         "higher_is_better": False, "hist": "", "status": "ok"})
    ref = aggregate(rows, by=["pipeline"])
    for _ in range(5):
        shuffled = rows.sample(frac=1.0, random_state=int(rng.integers(1 << 31)))
        got = aggregate(shuffled, by=["pipeline"])
        assert got["value"].to_numpy().tobytes() == ref["value"].to_numpy().tobytes()
        assert got["sum"].to_numpy().tobytes() == ref["sum"].to_numpy().tobytes()


def _second_frame(name: str, overrides: dict, out) -> np.ndarray:
    import cv2

    from scenes.sequence import render_sequence
    from scenes.spec import load_scene_spec

    return cv2.imread(str(render_sequence(load_scene_spec(name, overrides), out) / "frames" / "000001.png"))


@pytest.mark.gl
@pytest.mark.slow
def test_a_frame_does_not_depend_on_what_the_process_rendered_before(tmp_path):
    """Workers reuse one renderer for many scenes: `nominal` rendered after `realistic` (sun, shadow maps,
    rolling-shutter bands: other shader programs) must give the pixels a fresh process gives. A cache of
    uniform locations keyed by program once broke this: `standard` rendered near-black frames."""
    # half the presets' 640x480: the same shader programs (the realistic frame still spans three shutter bands)
    two = {"image.n_frames": 2, "image.width_px": 320, "image.height_px": 240}
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as fresh:
        expected = fresh.submit(_second_frame, "nominal", two, tmp_path / "fresh").result()
    _second_frame("realistic", {**two, "light.mode": "sun"}, tmp_path / "before")
    np.testing.assert_array_equal(_second_frame("nominal", two, tmp_path / "after"), expected)
