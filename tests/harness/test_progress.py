"""Progress that a user sees: `aerobench render`'s bar, the frames of renders inside `aerobench run`,
and the first run's numba compilation said aloud and done once, ahead, while the scenes render."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from concurrent.futures import Future
from contextlib import contextmanager
from pathlib import Path

import pytest

import harness.cell_scoring
import harness.executors
import harness.scheduling as scheduling
import harness.tasks as tasks
from harness.suites import expand, parse_suite

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.gl
@pytest.mark.parametrize("cold, quiet", [(["scenes._codec_kernels.avg_filter"], False), ([], False), ([], True)],
                         ids=["cold", "warm", "quiet"])
def test_render_shows_a_bar_of_frames_and_quiet_shows_none(tmp_path, monkeypatch, capsys, cold, quiet):
    """A render whose PNG kernels numba's cache lacks says that it compiles; the bar counts the frames.

    Which kernels an empty cache lacks is read from numba itself in
    :func:`test_an_empty_numba_cache_lists_the_kernels_and_compiling_them_fills_it`; compiling them here
    again would only cost time."""
    from harness.cli import main

    monkeypatch.setattr(scheduling, "kernels_to_compile", lambda *a, **k: cold)
    out = tmp_path / "seq"
    assert main(["render", "tiny", "--set", "image.n_frames=3", "--out", str(out), *(["--quiet"] if quiet else [])]) == 0
    shown = capsys.readouterr()
    assert f"wrote {out}" in shown.out  # the result line stays, quiet or not
    assert len(list((out / "frames").glob("*.png"))) == 3
    if quiet:
        assert shown.err == ""
        return
    assert ("compiling numerical kernels (first run only" in shown.err) == bool(cold)
    assert "rendering tiny" in shown.err and "3/3" in shown.err and "frame" in shown.err


def test_render_progress_is_written_whole_and_read_back(tmp_path):
    path = str(tmp_path / "k.txt")
    assert scheduling.read_render_progress(path) is None  # nothing written yet
    progress = tasks.render_progress_writer(path)
    progress(7, 60)
    assert scheduling.read_render_progress(path) == (7, 60)
    progress(8, 60)
    assert scheduling.read_render_progress(path) == (8, 60)
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]
    assert tasks.render_progress_writer(None) is None
    tasks.render_progress_writer(str(tmp_path / "missing" / "k.txt"))(1, 2)  # a folder it cannot see: no error


def _cells(pipelines: list[str]):
    suite = parse_suite({"name": "p", "description": "d", "scenes": [{"preset": "tiny"}], "seeds": [1],
                         "pipelines": pipelines, "picture_pairs": [0]})
    return expand(suite), suite


class _Pool:
    """A synchronous executor: renders report frames through their progress file, cells are logged."""

    def __init__(self, ready_when_cells: list):
        self.log: list[str] = []
        self.ready_when_cells = ready_when_cells
        self.progress_seen: list = []

    def submit(self, fn, *args):
        fut: Future = Future()
        if fn is tasks.render_task:
            key, spec, progress_file = args[0], args[1], args[5]  # (key, spec, cache, imports, import_paths, progress_file)
            if progress_file is not None:
                tasks.render_progress_writer(progress_file)(2, spec.image.n_frames)
            self.progress_seen.append(scheduling.read_render_progress(progress_file))
            self.log.append("render")
            fut.set_result({"key": key, "path": "/nowhere", "reused": False, "error": None})
        else:
            self.ready_when_cells.append(self.event.is_set())
            self.log.append("cells")
            fut.set_result([{"cell_id": p["cell_id"], "status": "ok", "error": "", "rows": 1} for p in args[0]])
        return fut


def _execute(tmp_path, monkeypatch, *, cold: list[str], progress: bool):
    cells, suite = _cells(["thesis-lk", "dis"])
    ready_when_cells: list[bool] = []
    pool = _Pool(ready_when_cells)
    warmed: list[str] = []
    real_compile_ahead = scheduling.compile_ahead

    def slow_warm_up(pipeline):
        time.sleep(0.3)
        warmed.append(pipeline.name if hasattr(pipeline, "name") else pipeline.hash)

    def compile_ahead(todo, ctx, *, local):
        event = real_compile_ahead(todo, ctx, local=local)
        pool.event = event
        return event

    @contextmanager
    def fake_executor(kind, *, workers=None, scheduler=None):
        yield pool

    monkeypatch.setattr(harness.executors, "open_executor", fake_executor)
    monkeypatch.setattr(scheduling, "kernels_to_compile", lambda *a, **k: cold)
    monkeypatch.setattr(scheduling, "compile_ahead", compile_ahead)
    monkeypatch.setattr(harness.cell_scoring, "warm_up", slow_warm_up)
    (tmp_path / "cells").mkdir()
    scheduling.execute(cells, tmp_path / "cells", tmp_path / "cache", {}, suite, "process", 2, None, progress)
    return pool, warmed, ready_when_cells


def test_a_cold_numba_cache_is_said_and_compiled_once_before_any_cell_starts(tmp_path, monkeypatch, capsys):
    pool, warmed, ready_when_cells = _execute(tmp_path, monkeypatch, cold=["algorithms.x.kernel"], progress=True)
    err = capsys.readouterr().err
    assert "compiling numerical kernels (first run only" in err
    assert len(warmed) == 2  # each pipeline of the suite once, in this process
    assert pool.log[0] == "render" and ready_when_cells and all(ready_when_cells)
    assert pool.progress_seen == [(2, 6)]  # the render's frames (tiny: 6) reached the parent


def test_a_warm_cache_compiles_nothing_ahead_and_quiet_says_nothing(tmp_path, monkeypatch, capsys):
    pool, warmed, ready_when_cells = _execute(tmp_path, monkeypatch, cold=[], progress=False)
    assert warmed == [] and all(ready_when_cells) and "cells" in pool.log
    assert capsys.readouterr().err == ""
    assert pool.progress_seen == [None]  # --quiet: no progress files at all


def test_the_bar_names_each_render_in_flight_with_its_frames(tmp_path):
    class V:
        label = "realistic"

    ctx = {"progress_dir": str(tmp_path), "variants": {"k1": V(), "k2": V()}, "kernels_ready": threading.Event()}
    tasks.render_progress_writer(str(tmp_path / "k1.txt"))(23, 60)
    status = scheduling._render_status({1: ("render", "k1"), 2: ("render", "k2"), 3: ("cells", [])}, ctx)
    assert status == ("rendering realistic 23/60, realistic starting; "
                      "compiling numerical kernels (first run only)")
    ctx["kernels_ready"].set()
    assert scheduling._render_status({}, ctx) == ""


def test_the_bar_shows_the_pairs_of_each_task_of_cells_in_flight(tmp_path):
    """A 1080p clip's cells run for minutes: the bar says how far their pipelines are, pair by pair."""
    class V:
        label = "clip"

    class C:
        def __init__(self, cell_id, pipeline):
            self.cell_id, self.pipeline, self.variant = cell_id, pipeline, V()

    ctx = {"progress_dir": str(tmp_path), "variants": {}, "kernels_ready": threading.Event()}
    ctx["kernels_ready"].set()
    pending = {1: ("cells", [(C("a1", "dis"), {}), (C("a2", "tv-l1"), {})]), 2: ("cells", [(C("b1", "farneback"), {})])}
    assert scheduling._render_status(pending, ctx) == ""  # nothing scored yet: nothing said
    tasks.render_progress_writer(scheduling._progress_file(ctx, "cells-a1"))(40, 198)
    assert scheduling._render_status(pending, ctx) == "clip: dis, tv-l1 40/198 pairs"
    tasks.render_progress_writer(scheduling._progress_file(ctx, "cells-b1"))(7, 99)
    assert scheduling._render_status(pending, ctx) == "clip: dis, tv-l1 40/198 pairs; clip: farneback 7/99 pairs"


def test_only_the_kernels_of_the_suites_pipelines_count():
    from algorithms.pipeline import PIPELINES

    smoke = scheduling.pipeline_kernel_modules([PIPELINES[n] for n in ("thesis-lk", "thesis-hs", "dis")])
    assert {"algorithms.lucas_kanade_flow", "algorithms.horn_schunck_flow", "algorithms.pipeline"} <= smoke
    assert "algorithms.tv_l1_flow" not in smoke
    assert "algorithms.tv_l1_flow" in scheduling.pipeline_kernel_modules([PIPELINES["tv-l1"]])


@pytest.mark.slow
def test_an_empty_numba_cache_lists_the_kernels_and_compiling_them_fills_it(tmp_path):
    code = """
import numpy as np
from harness.scheduling import kernels_to_compile
mods = {"algorithms.lucas_kanade_flow"}
before = kernels_to_compile(modules=mods)
from algorithms import lucas_kanade
rng = np.random.default_rng(0)
f = (rng.random((32, 32)) * 255).astype(np.float32)
lucas_kanade(f, np.roll(f, 1, axis=1))
after = kernels_to_compile(modules=mods)
print(len(before), len(after), all(k.startswith("algorithms.lucas_kanade_flow.") for k in before))
# what `aerobench render` looks for before it says that it compiles
print(*kernels_to_compile("scenes", modules={"scenes._codec_kernels"}))
"""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"), PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=280)
    assert out.returncode == 0, out.stderr
    counts, render_cold = out.stdout.splitlines()
    n_before, n_after, named = counts.split()
    assert int(n_before) >= 1 and int(n_after) == 0 and named == "True", out.stdout
    assert {"scenes._codec_kernels.avg_filter", "scenes._codec_kernels.deflate_huffman"} <= set(render_cold.split())
