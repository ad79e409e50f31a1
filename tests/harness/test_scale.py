"""Scale: what the runner keeps in memory, the order it hands out work, what it records for readers.

Speed and peak memory themselves are measured by ``benchmarks/scale.py``, not here.
"""

from __future__ import annotations

import copy
import errno
import gc
import json
import math
import weakref
from concurrent.futures import Future
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from tests.harness.harness_testdata import TINY_SUITE

import harness.executors
import harness.suites
from algorithms.registry import register_flow
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
            self.log.append(("cells", "+".join(f"{p['scene']}/{p['pipeline']}" for p in args[0])))
            fut.set_result([{"cell_id": p["cell_id"], "status": "ok", "error": "", "rows": 1} for p in args[0]])
        return fut


def test_renders_go_first_largest_scene_first_then_the_longest_tasks_of_cells(tmp_path, monkeypatch):
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
    # costs (frames x method weight): long hs 36, short hs 12, long lk 9, long dis 4.5, short lk 3, short dis 1.5;
    # 2 scenes on 2 workers: each scene in two tasks of about equal cost, the longest task first
    assert pool.log == [("render", "9"), ("render", "3"),
                        ("cells", "long/thesis-hs"), ("cells", "long/thesis-lk+long/dis"),
                        ("cells", "short/thesis-hs"), ("cells", "short/thesis-lk+short/dis")]


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

    def watched_score_pair(estimate, truth, *, frame, **kw):
        gc.collect()
        leaks.extend(f"pair {i} still alive while scoring pair {frame}" for i, r in refs
                     if i < frame - 1 and r() is not None)
        refs.extend((frame, weakref.ref(a)) for a in (estimate.flow_total, estimate.flow_local,
                                                       estimate.flow_filtered, truth.flow, truth.flow_camera))
        rows = real_score_pair(estimate, truth, frame=frame, **kw)
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


def test_groups_per_scene_gives_two_tasks_a_worker_and_never_more_than_the_cells():
    assert scheduling.groups_per_scene(27, 7, 2) == 1  # standard on 2 workers: one task per scene
    assert scheduling.groups_per_scene(27, 7, 14) == 2
    assert scheduling.groups_per_scene(1, 7, 2) == 4
    assert scheduling.groups_per_scene(1, 3, 16) == 3
    assert scheduling.groups_per_scene(1, 7, 1) == 1  # one worker waits for nobody
    with pytest.raises(ValueError, match="expected positive counts"):
        scheduling.groups_per_scene(0, 7, 2)


def test_a_run_starts_by_default_no_more_workers_than_its_work_keeps_busy():
    tiny, _ = _cells([{"preset": "tiny"}], ["thesis-lk", "thesis-hs", "dis"])
    assert scheduling.run_workers(tiny, 8) == 1  # a one-scene tiny run: one worker, its cells in one task
    big, _ = _cells([{"preset": "tiny", "overrides": {"image.width_px": 640, "image.height_px": 480}}],
                    ["thesis-lk", "thesis-hs", "dis"])
    assert scheduling.run_workers(big, 2) == 2 and scheduling.run_workers(big, 1) == 1
    work = sum(scheduling.cell_cost(c) for c in big) + scheduling.scene_cost(big[0].variant)
    assert scheduling.run_workers(big, 64) == math.ceil(work / scheduling.WORKER_START_COST) < 64
    smoke = expand(harness.suites.load_suite("smoke"))
    assert scheduling.run_workers(smoke, 2) == 2  # CI's smoke run keeps both cores


def test_the_default_workers_reach_the_pool_and_explicit_workers_are_kept(tmp_path, monkeypatch):
    cells, suite = _cells([{"preset": "tiny"}], ["thesis-lk", "dis"])
    opened = []

    @contextmanager
    def fake_executor(kind, *, workers=None, scheduler=None):
        opened.append(workers)
        yield _Recorder()

    monkeypatch.setattr(harness.executors, "open_executor", fake_executor)
    monkeypatch.setattr(harness.executors, "default_workers", lambda: 4)
    monkeypatch.setattr(scheduling, "kernels_to_compile", lambda *a, **k: [])
    for workers in (None, 3):
        (tmp_path / str(workers)).mkdir()
        scheduling.execute(cells, tmp_path / str(workers), tmp_path / "cache", {}, suite, "process", workers, None,
                           False)
    assert opened == [1, 3]


def test_cell_groups_balance_the_cost_and_keep_every_cell_once():
    cells, _ = _cells([{"preset": "tiny", "overrides": {"image.n_frames": 5}}],
                      ["thesis-lk", "thesis-hs", "pyramidal-hs", "dis", "farneback", "tv-l1"])
    for n in (1, 2, 3, 6, 9):
        groups = scheduling.cell_groups(cells, n)
        assert len(groups) == min(n, len(cells))
        assert sorted(c.cell_id for g in groups for c in g) == sorted(c.cell_id for c in cells)
        costs = [sum(scheduling.cell_cost(c) for c in g) for g in groups]
        assert costs == sorted(costs, reverse=True)  # the longest task first
        # LPT: no group exceeds the mean by more than its largest cell
        assert max(costs) <= sum(costs) / len(groups) + max(scheduling.cell_cost(c) for c in cells)


_CALLS = {"n": 0}


@register_flow
def _fails_on_the_third_pair(frame0, frame1):
    """A flow method that raises on the third pair of a sequence (a cell that fails mid-run).

    The 64 x 64 frames of the numba warm-up (harness.cell_scoring.warm_up) do not count.
    """
    _CALLS["n"] += frame0.shape != (64, 64)
    if _CALLS["n"] == 3:
        raise RuntimeError("cannot do the third pair")
    return np.zeros(frame0.shape + (2,), np.float32), np.ones(frame0.shape, bool)


@pytest.mark.gl
def test_cells_run_together_give_the_rows_each_gives_alone(tmp_path, render_cache):
    """The lock-step task shares frames, pass 1 and truth; not a number may move, and a failing cell fails alone."""
    from harness.provenance import collect
    from harness.results import read_table
    from scenes import cached_sequence, open_sequence

    suite = parse_suite({**copy.deepcopy(TINY_SUITE), "scenes": [{"preset": "tiny"}],
                         "pipelines": ["thesis-lk", "thesis-hs", "dis"]})
    cells = expand(suite)
    prov = collect()
    prov = {k: prov[k] for k in ("git_commit", "git_dirty", "machine")}
    seq = str(cached_sequence(cells[0].variant.spec, render_cache))

    def payloads(folder):
        out = []
        for c in cells:
            p = tasks.cell_payload(c, tmp_path / folder, prov, [])
            p["sequence"] = seq
            out.append(p)
        return out

    alone = [tasks.cell_task(p) for k, p in enumerate(payloads("alone")) if k != 1]
    together_payloads = payloads("together")
    together_payloads[1]["pipeline_spec"] = {**together_payloads[1]["pipeline_spec"],
                                             "flow": {"method": "_fails_on_the_third_pair", "params": {}}}
    progress = tmp_path / "progress.txt"
    together = tasks.cells_task(together_payloads, str(progress))
    # every pair of every cell counted once, the failed cell's pairs after its failure too
    assert progress.read_text().split() == [str(3 * (len(open_sequence(seq)) - 1))] * 2
    assert [s["status"] for s in alone] == ["ok", "ok"]
    assert [s["status"] for s in together] == ["ok", "failed", "ok"]
    assert "the third pair" in together[1]["error"]
    accuracy = ["frame", "track_id", "metric", "region", "motion", "value", "sum", "count", "hist"]
    for k in (0, 2):
        a = read_table(tmp_path / "alone" / cells[k].cell_id / "rows.parquet")
        t = read_table(tmp_path / "together" / cells[k].cell_id / "rows.parquet")
        a, t = (x[x["kind"] != "timing"][accuracy].reset_index(drop=True) for x in (a, t))
        pd.testing.assert_frame_equal(a, t)
