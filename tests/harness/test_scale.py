"""Scale: what the runner keeps in memory, the order it hands out work, what it records for readers.

Speed and peak memory themselves are measured by ``benchmarks/scale.py``, not here.
"""

from __future__ import annotations

import copy
import errno
import gc
import json
import weakref
from concurrent.futures import Future
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from tests.harness.harness_testdata import TINY_SUITE

import harness.executors
import harness.runner as runner
import harness.scheduling as scheduling
import harness.tasks as tasks
from harness.cli import main
from harness.suites import expand, parse_suite
from scenes.formats import read_flo


@pytest.mark.gl
def test_run_json_cells_name_their_sequence_folder(reference_run):
    meta = json.loads((reference_run.run_dir / "run.json").read_text())
    for cell in meta["cells"]:
        seq = Path(cell["sequence"])
        assert seq.is_absolute()
        assert (seq / "MANIFEST.json").is_file() and (seq / "meta.json").is_file(), seq
    scenes = reference_run.table.groupby("cell_id")["seed"].first()
    # cells of different seeds are different scenes: different folders
    by_seed = {scenes[c["cell_id"]]: c["sequence"] for c in meta["cells"]}
    assert len(set(by_seed.values())) == len(by_seed) == 2


@pytest.mark.gl
def test_picture_pairs_hold_the_local_flow_beside_the_total(reference_run):
    # the built-in pipelines of the suite compensate a shift: total - local is the pair's global shift
    for folder in sorted((reference_run.run_dir / "cells").iterdir()):
        total, local = read_flo(folder / "flow_000000.flo"), read_flo(folder / "local_flow_000000.flo")
        assert total.shape == local.shape
        global_part = (total - local).reshape(-1, 2)
        stab = pd.read_csv(folder / "stabilisation.csv")
        shift = stab.loc[1, ["cumulative_x_px", "cumulative_y_px"]].to_numpy(float) - \
            stab.loc[0, ["cumulative_x_px", "cumulative_y_px"]].to_numpy(float)
        np.testing.assert_allclose(global_part, np.broadcast_to(shift, global_part.shape), atol=1e-4)
        assert np.abs(local).max() > 0  # vehicles move against the ground: not just the global field


def test_an_os_error_in_run_is_one_line_naming_the_file(tmp_path, monkeypatch, capsys):
    full = tmp_path / "run" / "results.parquet"

    def disk_full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device", str(full))

    monkeypatch.setattr(runner, "run_suite", disk_full)
    assert main(["run", "smoke", "--out", str(tmp_path / "run"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"aerobench: error: No space left on device: {full}"


def test_an_os_error_without_a_file_says_so(tmp_path, monkeypatch, capsys):
    def eio(*args, **kwargs):
        raise OSError(errno.EIO, "Input/output error")

    monkeypatch.setattr(runner, "run_suite", eio)
    assert main(["run", "smoke", "--out", str(tmp_path / "run"), "--quiet"]) == 2
    assert capsys.readouterr().err.strip() == "aerobench: error: Input/output error: (no file named by the system)"


# --------------------------------------------------------------------------- scheduling


def _cells(scenes: list[dict], pipelines: list[str]):
    suite = parse_suite({"name": "order", "description": "d", "scenes": scenes, "seeds": [1],
                         "pipelines": pipelines, "picture_pairs": [0]})
    return expand(suite), suite


def test_cell_cost_grows_with_frames_pixels_and_method():
    cells, _ = _cells([{"preset": "tiny", "overrides": {"image.n_frames": 4}},
                       {"preset": "tiny", "label": "long", "overrides": {"image.n_frames": 8}}],
                      ["thesis-lk", "thesis-hs"])
    cost = {(c.variant.label, c.pipeline): scheduling.cell_cost(c) for c in cells}
    assert cost[("long", "thesis-lk")] == pytest.approx(2 * cost[("tiny", "thesis-lk")])
    assert cost[("tiny", "thesis-hs")] > cost[("tiny", "thesis-lk")]


class _Recorder:
    """A synchronous executor that records what was submitted, in order."""

    def __init__(self):
        self.log: list[tuple[str, str]] = []

    def submit(self, fn, *args):
        fut: Future = Future()
        if fn is tasks.render_task:
            key, spec = args[0], args[1]
            self.log.append(("render", f"{spec.image.n_frames}"))
            fut.set_result({"key": key, "path": "/nowhere", "reused": True, "error": None})
        else:
            p = args[0]
            self.log.append(("cell", f"{p['scene']}/{p['pipeline']}"))
            fut.set_result({"cell_id": p["cell_id"], "status": "ok", "error": "", "rows": 1})
        return fut


def test_renders_go_first_largest_scene_first_then_the_longest_cells(tmp_path, monkeypatch):
    cells, suite = _cells([{"preset": "tiny", "label": "short", "overrides": {"image.n_frames": 3}},
                           {"preset": "tiny", "label": "long", "overrides": {"image.n_frames": 9}}],
                          ["thesis-lk", "thesis-hs", "dis"])
    pool = _Recorder()

    @contextmanager
    def fake_executor(kind, *, workers=None, scheduler=None):
        yield pool

    monkeypatch.setattr(harness.executors, "open_executor", fake_executor)
    cells_dir = tmp_path / "cells"
    cells_dir.mkdir()
    scheduling.execute(cells, cells_dir, tmp_path / "cache", {}, suite, "process", 2, None, False)
    # costs (frames x method weight): long hs 36, short hs 12, long lk 9, long dis 4.5, short lk 3, short dis 1.5
    assert pool.log == [("render", "9"), ("render", "3"),
                        ("cell", "long/thesis-hs"), ("cell", "short/thesis-hs"), ("cell", "long/thesis-lk"),
                        ("cell", "long/dis"), ("cell", "short/thesis-lk"), ("cell", "short/dis")]


# --------------------------------------------------------------------------- memory


@pytest.mark.gl
def test_a_cell_keeps_no_pair_arrays_after_scoring_the_pair(tmp_path, render_cache, monkeypatch):
    """Peak memory is bounded by a few frames: every pair's arrays are freed once it is scored."""
    import harness.metrics
    from harness.provenance import collect
    from scenes import cached_sequence

    suite = parse_suite({**copy.deepcopy(TINY_SUITE), "scenes": [{"preset": "tiny",
                                                                  "overrides": {"image.n_frames": 9}}],
                         "pipelines": ["thesis-lk"]})
    (cell,) = expand(suite)
    real_score_pair = harness.metrics.score_pair
    refs: list[tuple[int, weakref.ref]] = []
    leaks: list[str] = []

    def watched_score_pair(estimate, truth, *, frame):
        gc.collect()
        leaks.extend(f"pair {i} still alive while scoring pair {frame}" for i, r in refs
                     if i < frame - 1 and r() is not None)
        refs.extend((frame, weakref.ref(a)) for a in (estimate.flow_total, estimate.flow_local,
                                                       estimate.flow_filtered, truth.flow, truth.flow_camera))
        rows = real_score_pair(estimate, truth, frame=frame)
        leaks.extend(f"row of pair {frame} holds an array ({k})" for r in rows for k, v in r.items()
                     if isinstance(v, np.ndarray) and v.size > 1)
        return rows

    monkeypatch.setattr(harness.metrics, "score_pair", watched_score_pair)
    prov = collect()
    payload = tasks.cell_payload(cell, tmp_path / "cells", {k: prov[k] for k in ("git_commit", "git_dirty", "machine")},
                              [])
    payload["sequence"] = str(cached_sequence(cell.variant.spec, render_cache))
    out = tasks.cell_task(payload)
    assert out["status"] == "ok", out["error"]
    assert len({i for i, _ in refs}) == 8  # every pair was scored through the watcher
    assert not leaks, leaks
