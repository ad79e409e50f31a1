"""How aerobench scales: smoke end to end, worker speed-up, peak memory per worker, suite wall time.

Every figure is measured in this run (no stored reference); each subcommand prints a
table and the command lines it ran. Run from the project root:

    python benchmarks/scale.py smoke [--workers 2]
    python benchmarks/scale.py speedup [--repeats 3] [--cells 8]
    python benchmarks/scale.py memory [--frames 60,300] [--size 1920x1080]
                                              [--pipelines thesis-lk,pyramidal-hs] [--cache DIR] [--keep]
    python benchmarks/scale.py standard [--cells N] [--workers 2]
    python benchmarks/scale.py cores [--max-workers 16] [--cells 32] [--pipeline thesis-lk[,tvl1,...]]
                                              [--suite standard]
    python benchmarks/scale.py cost [--preset nominal] [--pipelines a,b] [--pairs N] [--cache DIR]
    python benchmarks/scale.py scene --reference TREE [--presets nominal] [--workers 1] [--repeats 3]
    python benchmarks/scale.py replay RUN [--workers 1,2,4,8,14,16,32] [--serial]

- ``smoke``: ``aerobench run smoke`` (render, pipelines, metrics, report) with a cold
  render cache, then again into a fresh run folder with the cache warm; wall times, and
  the CLI's own "scenes: R rendered, U reused" line of each run.
- ``speedup``: a suite of ``--cells`` cells of similar cost (one scene, one pipeline, one
  seed per cell), cache warmed first; 1 and 2 workers run alternately ``--repeats``
  times each; the ratio of the median wall times.
- ``memory``: renders the scene at ``--size`` for each frame count (one child process per
  render, its peak RSS and wall time reported), then runs each pipeline as one cell in a
  fresh child process exactly as a pool worker runs it (``harness.runner.cell_task``); the
  child reports its peak RSS (``ru_maxrss``) and its RSS after the imports. The cache is
  deleted afterwards unless ``--keep`` (1920x1080 x 300 frames is ~10 GB of ``.flo``).
- ``standard``: the ``standard`` suite, or with ``--cells N`` a subset of N of its cells
  taken evenly over its scenes and pipelines (seed 1), timed and extrapolated to the whole
  suite by cell count; says which.
- ``cores``: the many-core curve. A suite of ``--cells`` cells of similar cost (cache
  warmed first) run with 1, 2, 4, ... up to ``--max-workers`` workers (default: the cores
  here); per worker count: wall time, cells per minute, speed-up over one worker, how
  busy the workers were (sum of the cells' own ``elapsed_s`` over workers x wall: what
  is missing is start-up, scheduling gaps, a serial tail or contention), and how long
  the driver's serial collection (``harness.results.collect_cells``: read, sort, write
  results.parquet, summary) takes on that run folder.
- ``cost``: the cost model of one cell. Renders ``--preset`` (seed 1) once, then runs each
  pipeline as one cell, in a fresh process each, exactly as a pool worker runs it, with a
  clock on every part: the flow method (its own ``stage_ms``), the rest of the pipeline
  (frame reading, global motion, filters, tracking), reading the ground truth, scoring
  the pairs, scoring the sequence, the cell files, building and writing ``rows.parquet``;
  with its size and the bytes of histograms. A suite's cell time is these figures summed
  over its scenes and pipelines (``--json`` keeps them).
- ``replay``: the many-core model of a finished run: its cells' measured ``elapsed_s``
  grouped and ordered as the runner does for 1, 2, 4, ... workers, on idle cores, plus the
  tail after the cells (``--serial`` measures, on a copy of the run, collection and the
  report's parts: its figure blocks, replayed on the same N workers in the order the report
  submits them, beside the collection and the numbers that the main process computes meanwhile,
  as ``aerobench run`` does). Says where scaling stops: the longest task, and what stays serial.
- ``scene``: the cells of one scene (``--presets``, seed 1, the standard's pipelines) run
  by ``aerobench run`` of this tree and of ``--reference`` (another source tree, e.g. a
  git worktree of an older commit), alternately, ``--repeats`` times each, warm cache, no
  report: median wall and CPU seconds (the CLI and its workers), their ratio, and whether
  the accuracy rows of the two are the same numbers.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

PY = sys.executable
MIB = 1024 * 1024


def _env(cache: Path | None = None) -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    env["PYOPENGL_PLATFORM"] = "egl"
    if cache is not None:
        env["AEROBENCH_CACHE"] = str(cache)
    return env


def _cli(args: list[str], cache: Path, shown: list[str]) -> tuple[float, subprocess.CompletedProcess]:
    """Run ``aerobench ARGS`` in a subprocess; (wall seconds, the completed process)."""
    cmd = [PY, "-m", "harness.cli", *args]
    shown.append(f"AEROBENCH_CACHE={cache} " + " ".join(cmd))
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=ROOT, env=_env(cache), capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        sys.stderr.write(proc.stdout + proc.stderr)
        raise SystemExit(f"failed ({proc.returncode}): {' '.join(cmd)}")
    return wall, proc


def _scenes_line(proc: subprocess.CompletedProcess) -> str:
    """The run's own summary line (stdout): "N cells (R reused), scenes R rendered / U reused, ..."."""
    for line in proc.stdout.splitlines():
        if " rendered / " in line:
            return line.split(" -> ")[0].strip()
    return "(no summary line)"


def _table(rows: list[tuple], header: tuple) -> str:
    cols = list(zip(header, *rows))
    widths = [max(len(str(v)) for v in c) for c in cols]
    lines = ["  ".join(str(v).ljust(w) for v, w in zip(r, widths)) for r in [header, *rows]]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def _print_commands(shown: list[str]) -> None:
    print("\ncommands:")
    for c in dict.fromkeys(shown):
        print(f"  {c}")


# --------------------------------------------------------------------------- smoke


def cmd_smoke(args: argparse.Namespace) -> None:
    work = Path(tempfile.mkdtemp(prefix="aerobench-scale-smoke-"))
    cache, shown, rows = work / "cache", [], []
    try:
        for label, out in (("cold cache", work / "run-cold"), ("warm cache", work / "run-warm")):
            wall, proc = _cli(["run", "smoke", "--out", str(out), "--workers", str(args.workers), "--quiet"],
                              cache, shown)
            report = "yes" if (out / "report.html").is_file() else "NO"
            rows.append((label, f"{wall:.1f}", report, _scenes_line(proc)))
        print(f"smoke suite end to end, {args.workers} workers (budget 60 s each)\n")
        print(_table(rows, ("run", "wall_s", "report", "the run's own cache line")))
        _print_commands(shown)
    finally:
        shutil.rmtree(work, ignore_errors=True)


# --------------------------------------------------------------------------- speed-up


def _speedup_suite(n_cells: int, frames: int, size: tuple[int, int]) -> dict:
    return {"name": "scale-speedup", "description": "cells of similar cost for the worker speed-up",
            "scenes": [{"preset": "nominal", "overrides": {"image.n_frames": frames, "image.width_px": size[0],
                                                           "image.height_px": size[1]}}],
            "seeds": list(range(1, n_cells + 1)), "pipelines": ["thesis-lk"], "picture_pairs": [0]}


def cmd_speedup(args: argparse.Namespace) -> None:
    import yaml

    work = Path(tempfile.mkdtemp(prefix="aerobench-scale-speedup-"))
    cache, shown = work / "cache", []
    size = tuple(int(v) for v in args.size.split("x"))
    suite = work / "suite.yaml"
    suite.write_text(yaml.safe_dump(_speedup_suite(args.cells, args.frames, size), sort_keys=False))
    try:
        _cli(["run", str(suite), "--out", str(work / "warmup"), "--workers", "2", "--quiet", "--no-report"],
             cache, shown)
        times: dict[int, list[float]] = {1: [], 2: []}
        for r in range(args.repeats):
            for w in (1, 2):  # alternately, so a slow spell of the machine hits both
                wall, proc = _cli(["run", str(suite), "--out", str(work / f"run-{w}-{r}"), "--workers", str(w),
                                   "--quiet", "--no-report"], cache, shown)
                if "0 rendered" not in _scenes_line(proc):
                    raise SystemExit(f"the cache was not warm: {_scenes_line(proc)}")
                times[w].append(wall)
        m1, m2 = statistics.median(times[1]), statistics.median(times[2])
        print(f"speed-up: {args.cells} cells (nominal {args.size} x {args.frames} frames, thesis-lk, one seed each), "
              f"warm cache, no report, median of {args.repeats} alternate runs\n")
        rows = [(w, " ".join(f"{t:.1f}" for t in times[w]), f"{statistics.median(times[w]):.1f}") for w in (1, 2)]
        print(_table(rows, ("workers", "runs_s", "median_s")))
        print(f"\nspeed-up 2 workers over 1: {m1 / m2:.2f}x (target >= 1.7x)")
        _print_commands(shown)
    finally:
        shutil.rmtree(work, ignore_errors=True)


# --------------------------------------------------------------------------- memory


def _rss_now_mib() -> float:
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def child_render(spec_json: str, cache: str) -> None:
    """Child: render one scene into the cache; print wall time and peak RSS as JSON."""
    from scenes import cached_sequence_result, load_scene_spec

    req = json.loads(spec_json)
    spec = load_scene_spec(req["preset"], overrides=req["overrides"])
    rss0 = _rss_now_mib()
    t0 = time.perf_counter()
    res = cached_sequence_result(spec, cache)
    print(json.dumps({"path": str(res.path), "rendered": res.rendered, "wall_s": time.perf_counter() - t0,
                      "rss_after_imports_mib": rss0,
                      "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))


def child_cell(payload_file: str) -> None:
    """Child: run one cell as a pool worker does; print wall time and peak RSS as JSON."""
    import harness.metrics  # noqa: F401  (what a worker has imported before its first cell)
    import algorithms.pipeline  # noqa: F401
    from harness.runner import cell_task

    payload = json.loads(Path(payload_file).read_text())
    rss0 = _rss_now_mib()
    t0 = time.perf_counter()
    out = cell_task(payload)
    print(json.dumps({**out, "wall_s": time.perf_counter() - t0, "rss_after_imports_mib": rss0,
                      "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))


def _child(args: list[str], shown: list[str]) -> dict:
    cmd = [PY, str(Path(__file__).resolve()), *args]
    shown.append(" ".join(cmd))
    proc = subprocess.run(cmd, cwd=ROOT, env=_env(), capture_output=True, text=True)
    if proc.returncode != 0:
        sys.stderr.write(proc.stdout + proc.stderr)
        raise SystemExit(f"child failed ({proc.returncode}): {' '.join(cmd)}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def cmd_memory(args: argparse.Namespace) -> None:
    from harness.provenance import collect as collect_provenance
    from harness.runner import _payload
    from harness.suites import expand, parse_suite

    width, height = (int(v) for v in args.size.split("x"))
    frame_counts = [int(v) for v in args.frames.split(",")]
    pipelines = args.pipelines.split(",")
    cache = Path(args.cache) if args.cache else Path(tempfile.mkdtemp(prefix="aerobench-scale-mem-"))
    work = Path(tempfile.mkdtemp(prefix="aerobench-scale-mem-run-"))
    shown: list[str] = []
    du = shutil.disk_usage(cache if cache.exists() else cache.parent)
    print(f"cache {cache}: {du.free / 1e9:.0f} GB free")
    prov = collect_provenance()
    provenance = {k: prov[k] for k in ("git_commit", "git_dirty", "machine")}
    render_rows, cell_rows = [], []
    try:
        for n in frame_counts:
            overrides = {"image.width_px": width, "image.height_px": height, "image.n_frames": n}
            r = _child(["_render", json.dumps({"preset": args.preset, "overrides": overrides}), str(cache)], shown)
            size_gb = sum(p.stat().st_size for p in Path(r["path"]).rglob("*") if p.is_file()) / 1e9
            render_rows.append((f"{args.size} x {n}", "rendered" if r["rendered"] else "reused", f"{r['wall_s']:.0f}",
                                f"{r['rss_after_imports_mib']:.0f}", f"{r['peak_rss_mib']:.0f}", f"{size_gb:.1f}"))
            print(f"render {n} frames: {r}", flush=True)
            suite = parse_suite({"name": "scale-memory", "description": "one scene, one seed",
                                 "scenes": [{"preset": args.preset, "overrides": overrides}],
                                 "seeds": [1], "pipelines": pipelines, "picture_pairs": [0]})
            for cell in expand(suite):
                payload = _payload(cell, work / f"cells-{n}", provenance, [])
                payload["sequence"] = r["path"]
                pfile = work / f"payload-{cell.cell_id}.json"
                pfile.write_text(json.dumps(payload))
                c = _child(["_cell", str(pfile)], shown)
                print(f"cell {n} frames {cell.pipeline}: {c}", flush=True)
                if c["status"] != "ok":
                    raise SystemExit(f"cell failed: {c['error']}")
                cell_rows.append((cell.pipeline, n, f"{c['wall_s']:.0f}", f"{c['rss_after_imports_mib']:.0f}",
                                  f"{c['peak_rss_mib']:.0f}"))
        print(f"\nrendering, {args.preset} preset, one child process each\n")
        print(_table(render_rows, ("sequence", "render", "wall_s", "rss_after_imports_MiB", "peak_rss_MiB",
                                   "on_disk_GB")))
        print(f"\none cell per child process (harness.runner.cell_task), {args.size}\n")
        print(_table(cell_rows, ("pipeline", "frames", "wall_s", "rss_after_imports_MiB", "peak_rss_MiB")))
        by = {}
        for p, n, _, _, peak in cell_rows:
            by.setdefault(p, {})[n] = float(peak)
        print()
        for p, d in by.items():
            lo, hi = min(frame_counts), max(frame_counts)
            if lo in d and hi in d:
                print(f"{p}: peak RSS {hi} frames / {lo} frames = {d[hi] / d[lo]:.3f} (target within 1.2); "
                      f"{hi} frames {d[hi] / 1024:.2f} GiB (target < 1.5 GiB)")
        _print_commands(shown)
    finally:
        shutil.rmtree(work, ignore_errors=True)
        if not args.keep:
            shutil.rmtree(cache, ignore_errors=True)


# --------------------------------------------------------------------------- standard


def cmd_standard(args: argparse.Namespace) -> None:
    import yaml

    from harness.suites import expand, load_suite

    work = Path(tempfile.mkdtemp(prefix="aerobench-scale-standard-"))
    cache = Path(args.cache) if args.cache else work / "cache"
    shown: list[str] = []
    full = load_suite("standard")
    n_full = len(expand(full))
    try:
        if args.cells:
            data = full.model_dump(mode="json")
            # a subset spread over scenes and pipelines: scene i with pipeline i (mod), seed 1
            scenes, pipes = data["scenes"], data["pipelines"]
            picks = [(scenes[i % len(scenes)], pipes[i % len(pipes)]) for i in range(args.cells)]
            names = []
            for k, (sc, pp) in enumerate(picks):
                sub = {**data, "name": f"standard-part{k}", "scenes": [sc], "pipelines": [pp], "seeds": [1]}
                path = work / f"part{k}.yaml"
                path.write_text(yaml.safe_dump(sub, sort_keys=False))
                names.append(path)
            # one suite holding the picked (scene, pipeline) pairs: run them as one run
            merged_cells = []
            t0 = time.perf_counter()
            for k, path in enumerate(names):
                _cli(["run", str(path), "--out", str(work / f"run{k}"), "--workers", str(args.workers),
                      "--quiet", "--no-report"], cache, shown)
                merged_cells.append(path)
            wall = time.perf_counter() - t0
            est = wall / args.cells * n_full
            print(f"standard subset: {args.cells} of {n_full} cells (seed 1, scene i x pipeline i), "
                  f"{args.workers} workers, cold cache, run one after another\n")
            print(_table([(args.cells, f"{wall:.0f}", f"{est / 60:.0f}")],
                         ("cells", "wall_s", "extrapolated_full_min")))
            print("(extrapolated by cell count; each subset run also renders its scene, which the full suite "
                  "shares between 21 cells: an upper estimate)")
        else:
            wall, proc = _cli(["run", "standard", "--out", str(work / "run"), "--workers", str(args.workers),
                               "--quiet"], cache, shown)
            print(_table([(n_full, f"{wall:.0f}", _scenes_line(proc))], ("cells", "wall_s", "cache line")))
        _print_commands(shown)
    finally:
        shutil.rmtree(work, ignore_errors=True)


# --------------------------------------------------------------------------- one scene, two trees


STANDARD_PIPELINES = "thesis-lk,thesis-hs,pyramidal-lk,pyramidal-hs,dis,farneback,tv-l1"


def _timed_run(tree: Path, suite: Path, out: Path, cache: Path, workers: int) -> tuple[float, float]:
    """``aerobench run`` of ``tree``'s code in a child process: (wall s, CPU s of it and its workers)."""
    env = _env(cache)
    env["PYTHONPATH"] = str(tree)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run([PY, "-m", "harness.cli", "run", str(suite), "--out", str(out), "--workers", str(workers),
                           "--quiet", "--no-report"], cwd=tree, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        sys.stderr.write(proc.stderr[-3000:])
        raise SystemExit(f"the run of {tree} failed (exit {proc.returncode})")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def cmd_scene(args: argparse.Namespace) -> None:
    """One scene's cells (the standard's pipelines, seed 1), this tree against ``--reference``, alternately."""
    import numpy as np
    import pandas as pd
    import yaml

    ref = Path(args.reference).resolve()
    if not (ref / "harness" / "cli.py").is_file():
        raise SystemExit(f"--reference {ref}: expected an aerobench source tree (harness/cli.py missing)")
    work = Path(tempfile.mkdtemp(prefix="aerobench-scale-scene-"))
    cache = Path(args.cache) if args.cache else work / "cache"
    suite = work / "scene.yaml"
    suite.write_text(yaml.safe_dump({"name": "scene", "description": "one scene, the standard pipelines",
                                     "scenes": [{"preset": p} for p in args.presets.split(",")], "seeds": [1],
                                     "pipelines": args.pipelines.split(","), "picture_pairs": [0, 10]}))
    trees = {"this": ROOT, "reference": ref}
    times: dict[str, list[tuple[float, float]]] = {k: [] for k in trees}
    try:
        _timed_run(ROOT, suite, work / "warm", cache, args.workers)  # renders into the cache
        for r in range(args.repeats):
            for name, tree in (trees.items() if r % 2 == 0 else reversed(trees.items())):
                times[name].append(_timed_run(tree, suite, work / f"{name}-{r}", cache, args.workers))
        # the accuracy rows of the last runs must be the same numbers
        cols = ["cell_id", "frame", "track_id", "metric", "region", "motion", "value", "sum", "count"]
        a, b = (pd.read_parquet(work / f"{n}-{args.repeats - 1}" / "results.parquet") for n in trees)
        a, b = (x[x["kind"] != "timing"][cols].sort_values(cols[:6]).reset_index(drop=True) for x in (a, b))
        same = a.shape == b.shape and a[cols[:6]].equals(b[cols[:6]])
        if same:
            va, vb = a["value"].to_numpy(float), b["value"].to_numpy(float)
            exact = (va == vb) | (np.isnan(va) & np.isnan(vb))
            rel = np.abs(va - vb)[~exact] / np.maximum(np.abs(va[~exact]), 1e-300)
            worst = float(rel.max()) if rel.size else 0.0
            same = f"{'yes' if worst <= 1e-9 else 'NO'} ({int(exact.sum())} of {len(va)} bit for bit, " \
                   f"largest relative difference {worst:.1e})"
        med = {k: (statistics.median(w for w, _ in v), statistics.median(c for _, c in v)) for k, v in times.items()}
        print(f"{args.presets} (seed 1) x {args.pipelines}: {args.workers} worker(s), warm cache, no report, "
              f"{args.repeats} runs each alternated; load average {os.getloadavg()[0]:.1f}\n")
        rows = [(k, f"{med[k][0]:.1f}", f"{med[k][1]:.1f}", " ".join(f"{w:.1f}" for w, _ in times[k])) for k in trees]
        print(_table(rows, ("tree", "wall_s_median", "cpu_s_median", "wall_s_runs")))
        print(f"\nthis / reference: wall {med['this'][0] / med['reference'][0]:.3f}, "
              f"CPU {med['this'][1] / med['reference'][1]:.3f}; accuracy rows the same to 1e-9: {same}")
    finally:
        shutil.rmtree(work, ignore_errors=True)


# --------------------------------------------------------------------------- many cores


def _worker_counts(max_workers: int) -> list[int]:
    counts, w = [], 1
    while w < max_workers:
        counts.append(w)
        w *= 2
    return counts + [max_workers]


def cmd_cores(args: argparse.Namespace) -> None:
    import yaml

    from harness.results import collect_cells

    max_workers = args.max_workers or os.cpu_count() or 1
    n_cells = args.cells or 2 * max_workers
    work = Path(tempfile.mkdtemp(prefix="aerobench-scale-cores-"))
    cache, shown, rows = work / "cache", [], []
    size = tuple(int(v) for v in args.size.split("x"))
    pipes = args.pipeline.split(",")
    if args.suite:  # a whole suite (e.g. standard) at each worker count
        from harness.suites import expand, load_suite

        data = load_suite(args.suite).model_dump(mode="json")
        n_cells = len(expand(load_suite(args.suite)))
    else:
        data = _speedup_suite(-(-n_cells // len(pipes)), args.frames, size)  # seeds x pipelines >= n_cells
        data["pipelines"] = pipes
        n_cells = len(data["seeds"]) * len(pipes)
    suite = work / "suite.yaml"
    suite.write_text(yaml.safe_dump(data, sort_keys=False))
    try:
        _cli(["run", str(suite), "--out", str(work / "warmup"), "--workers", str(max_workers), "--quiet",
              "--no-report"], cache, shown)
        base = None
        for w in _worker_counts(max_workers):
            out = work / f"run-{w}"
            wall, proc = _cli(["run", str(suite), "--out", str(out), "--workers", str(w), "--quiet", "--no-report"],
                              cache, shown)
            if "0 rendered" not in _scenes_line(proc):
                raise SystemExit(f"the cache was not warm: {_scenes_line(proc)}")
            busy = sum(json.loads(p.read_text())["elapsed_s"] for p in (out / "cells").glob("*/cell.json"))
            t0 = time.perf_counter()
            collect_cells(out)
            collect_s = time.perf_counter() - t0
            base = base or wall
            rows.append((w, f"{wall:.1f}", f"{60 * n_cells / wall:.1f}", f"{base / wall:.2f}",
                         f"{100 * busy / (w * wall):.0f}", f"{collect_s:.2f}"))
        what = (f"suite {args.suite}" if args.suite else
                f"{args.pipeline}, nominal {args.size} x {args.frames} frames, one seed each")
        print(f"many cores: {n_cells} cells ({what}), warm cache, no report; {os.cpu_count()} cores, "
              f"load average {os.getloadavg()[0]:.1f}\n")
        print(_table(rows, ("workers", "wall_s", "cells_per_min", "speedup", "busy_%", "collect_s")))
        _print_commands(shown)
    finally:
        shutil.rmtree(work, ignore_errors=True)


# --------------------------------------------------------------------------- replay on N cores


def replay_schedule(tasks: list[tuple[float, float]], workers: int, *, ordered: bool = True) -> float:
    """Wall time of ``tasks`` (cost the scheduler orders by, seconds it took) on ``workers`` idle workers.

    The runner's policy with every task ready (a warm cache): the costliest task first to
    the first free worker (``ordered=False``: in the given order, as a pool's queue hands
    them out). Returns when the last task ends.
    """
    import heapq

    free = [0.0] * workers
    for _, seconds in (sorted(tasks, key=lambda t: -t[0]) if ordered else tasks):
        start = heapq.heappop(free)
        heapq.heappush(free, start + seconds)
    return max(free)


def _report_parts(run_dir: Path, serial: dict) -> tuple[dict, list[float]]:
    """CPU seconds of the report's parts on ``run_dir``, one after the other in this process: reading the
    table (``load``), the numbers (``model``), each figure block in the order the report submits them, and
    joining the page and the Markdown (``page``)."""
    from reports.html import cell_index, render_html, scene_block, scene_blocks
    from reports.load import load_run
    from reports.markdown import render_markdown
    from reports.model import build_model

    t0 = time.process_time()
    data = load_run(run_dir)
    serial["load"] = time.process_time() - t0
    t0 = time.process_time()
    model = build_model(run_dir, data=data)
    serial["model"] = time.process_time() - t0
    cells = cell_index(data)
    blocks, drawn = [], {}
    for key in scene_blocks(cells):
        t0 = time.process_time()
        drawn[key] = scene_block(data, cells, *key)
        blocks.append(time.process_time() - t0)
    t0 = time.process_time()
    render_html(model, drawn), render_markdown(model)
    serial["page"] = time.process_time() - t0
    return serial, blocks


def cmd_replay(args: argparse.Namespace) -> None:
    """A finished run's measured cell times replayed through the runner's grouping and order on N workers."""
    from harness.results import CellRowsReader, collect_cells
    from harness.scheduling import cell_cost, cell_groups, groups_per_scene
    from harness.suites import expand, parse_suite

    run_dir = Path(args.run).resolve()
    run = json.loads((run_dir / "run.json").read_text())
    cells = expand(parse_suite(run["resolved_suite"]))
    elapsed = {}
    for c in cells:
        info = run_dir / "cells" / c.cell_id / "cell.json"
        if not info.is_file():
            raise SystemExit(f"{info}: missing; replay needs a complete run")
        elapsed[c.cell_id] = json.loads(info.read_text())["elapsed_s"]
    by_scene: dict[str, list] = {}
    for c in cells:
        by_scene.setdefault(c.variant.scene_hash, []).append(c)
    serial: dict[str, float] = {}
    blocks: list[float] = []
    if args.serial:
        work = Path(tempfile.mkdtemp(prefix="aerobench-replay-"))
        try:
            copy = work / "run"
            shutil.copytree(run_dir, copy, ignore=shutil.ignore_patterns("report.*"))
            read = CellRowsReader(copy)
            for c in cells:
                read.add(c.cell_id)  # as the driver does while the workers run
            t0 = time.process_time()
            collect_cells(copy, read=read)
            serial["collect"] = time.process_time() - t0
            serial, blocks = _report_parts(copy, serial)
        finally:
            shutil.rmtree(work, ignore_errors=True)

    def tail(w: int) -> float:
        """The serial tail on ``w`` workers as ``aerobench run`` has it: its figure blocks handed out when
        the cells are done, beside the collection and then the report's numbers on the table in hand (not
        read back: ``load`` is measured, not counted); one worker: all of it one after the other. Then the
        page."""
        if not serial:
            return 0.0
        figures = replay_schedule([(0.0, b) for b in blocks], w, ordered=False) if w > 1 else sum(blocks)
        main = serial["collect"] + serial["model"]
        return (max(main, figures) if w > 1 else main + figures) + serial["page"]
    total_cpu = sum(elapsed.values())
    rows, base = [], None
    for w in [int(x) for x in args.workers.split(",")]:
        tasks = []
        for scene_cells in by_scene.values():
            for group in cell_groups(scene_cells, groups_per_scene(len(by_scene), len(scene_cells), w)):
                tasks.append((sum(cell_cost(c) for c in group), sum(elapsed[c.cell_id] for c in group)))
        cells_s = replay_schedule(tasks, w) + args.startup
        wall = cells_s + tail(w)
        base = base or wall * w  # one worker's time, scaled
        rows.append((w, len(tasks), f"{cells_s:.0f}", f"{tail(w):.0f}", f"{wall:.0f}", f"{60 * len(cells) / wall:.0f}",
                     f"{100 * total_cpu / (w * cells_s):.0f}", f"{base / w / wall * 100 if w > 1 else 100:.0f}"))
    print(f"replay of {run_dir} ({len(cells)} cells, {len(by_scene)} scenes; cells' own time {total_cpu:.0f} s; "
          f"warm cache; + {args.startup:g} s pool start-up)\ntail after the cells, CPU s measured here: "
          + (", ".join(f"{k} {v:.1f}" for k, v in serial.items())
             + f", figure blocks {sum(blocks):.1f} ({len(blocks)}, the longest {max(blocks, default=0):.1f})"
             if serial else "not measured (--serial)") + "\n")
    print(_table(rows, ("workers", "tasks", "cells_s", "serial_s", "wall_s", "cells_per_min", "busy_%",
                        "efficiency_%")))
    print("\n(a model: each worker a core of its own, cells as long as they took in that run; efficiency is "
          "1-worker wall / (workers x wall))")


# --------------------------------------------------------------------------- cost model


def child_cost(seq_dir: str, pipeline_name: str, pairs: int) -> None:
    """In this process: one cell of ``pipeline_name`` on ``seq_dir`` as the runner runs it, timed by stage.

    Prints one JSON line: seconds in the pipeline (flow and the rest), the pair scoring, the
    sequence scoring, the cell files, building the rows table and writing it, and its size.
    """
    import numpy as np

    from algorithms.pipeline import get_pipeline
    from harness import cell_artifacts as artifacts
    from harness.executors import limit_threads
    from harness.metrics import score_pair, score_sequence
    from harness.results import rows_to_frame, write_table
    from harness.cell_scoring import _Frames, point_seeds
    from harness.cell_scoring import warm_up as _warm_up
    from scenes import open_sequence

    limit_threads(1)
    seq = open_sequence(seq_dir)
    pipeline = get_pipeline(pipeline_name)
    _warm_up(pipeline)
    frames = _Frames(seq)
    if pairs:
        class _Head:  # the first ``pairs + 1`` frames only
            def __len__(self):
                return min(len(frames), pairs + 1)

            def __getitem__(self, i):
                if i >= len(self):
                    raise IndexError(i)
                return frames[i]
        frames = _Head()
    t = dict.fromkeys(("pipeline", "flow", "score_pair", "truth_read", "score_sequence", "artifacts",
                       "rows_to_frame", "write_table"), 0.0)
    rows: list = []
    work = Path(tempfile.mkdtemp(prefix="aerobench-cost-"))
    n_pairs = 0
    try:
        it = pipeline.run(frames, seeds=point_seeds(seq.tracks))
        while True:
            t0 = time.perf_counter()
            try:
                est = next(it)
            except StopIteration:
                break
            t["pipeline"] += time.perf_counter() - t0
            if not hasattr(est, "flow_total"):
                seq_est = est
                continue
            n_pairs += 1
            t["flow"] += est.stage_ms.get("flow", 0.0) / 1000.0
            t0 = time.perf_counter()
            truth = seq.pair_truth(est.index)
            t["truth_read"] += time.perf_counter() - t0
            t0 = time.perf_counter()
            rows += score_pair(est, truth, frame=est.index)
            t["score_pair"] += time.perf_counter() - t0
            if est.index in (0, 10):
                t0 = time.perf_counter()
                artifacts.write_pair_flows(work, est.index, est.flow_total, est.flow_global)
                t["artifacts"] += time.perf_counter() - t0
        t0 = time.perf_counter()
        rows += score_sequence(seq_est, seq.camera, seq.tracks)
        t["score_sequence"] += time.perf_counter() - t0
        t0 = time.perf_counter()
        artifacts.write_stabilisation(work, artifacts.stabilisation_table(seq_est, seq.camera))
        artifacts.write_tracks(work, artifacts.tracks_table(seq_est, seq.tracks))
        t["artifacts"] += time.perf_counter() - t0
        t0 = time.perf_counter()
        table = rows_to_frame(rows, cell_id="x", scene="s", seed=1, pipeline=pipeline_name)
        t["rows_to_frame"] += time.perf_counter() - t0
        t0 = time.perf_counter()
        write_table(table, work / "rows.parquet")
        t["write_table"] += time.perf_counter() - t0
        size = (work / "rows.parquet").stat().st_size
    finally:
        shutil.rmtree(work, ignore_errors=True)
    t["pipeline_other"] = t["pipeline"] - t["flow"]
    print(json.dumps({"pipeline_name": pipeline_name, "pairs": n_pairs, "rows": len(table),
                      "rows_parquet_bytes": size, "seconds": t, "cpu_s": time.process_time(),
                      "hist_chars": int(np.sum([len(r.get("hist") or "") for r in rows]))}))


def cmd_cost(args: argparse.Namespace) -> None:
    """Where a cell's time goes, per pipeline, on one rendered scene (seed 1), one process per cell."""
    import yaml

    from harness.suites import expand, parse_suite

    shown: list[str] = []
    cache = Path(args.cache) if args.cache else Path(tempfile.mkdtemp(prefix="aerobench-scale-cost-"))
    suite = {"name": "cost", "scenes": [{"preset": args.preset}], "seeds": [1], "pipelines": ["dis"],
             "picture_pairs": [0]}
    path = cache / "cost-suite.yaml"
    cache.mkdir(parents=True, exist_ok=True)
    path.write_text(yaml.safe_dump(suite))
    t0 = time.perf_counter()
    _cli(["run", str(path), "--out", str(cache / f"run-{os.getpid()}"), "--workers", "1", "--quiet", "--no-report"],
         cache, shown)
    render_s = time.perf_counter() - t0
    from harness.runner import _sequence_dir

    seq_dir = _sequence_dir(expand(parse_suite(suite))[0].variant, cache)
    out = []
    for name in args.pipelines.split(","):
        cmd = [PY, str(Path(__file__).resolve()), "_cost", str(seq_dir), name, str(args.pairs)]
        shown.append(" ".join(cmd))
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, env=_env(cache), capture_output=True, text=True, cwd=ROOT)
        wall = time.perf_counter() - t0
        if proc.returncode != 0:
            sys.stderr.write(proc.stderr)
            raise SystemExit(f"failed: {' '.join(cmd)}")
        rec = json.loads(proc.stdout.strip().splitlines()[-1])
        rec["wall_s"] = wall
        out.append(rec)
    keys = ("flow", "pipeline_other", "truth_read", "score_pair", "score_sequence", "artifacts", "rows_to_frame",
            "write_table")
    rows = [(r["pipeline_name"], r["pairs"], f"{r['wall_s']:.1f}", *(f"{r['seconds'][k]:.2f}" for k in keys),
             r["rows"], f"{r['rows_parquet_bytes'] / 1e6:.2f}", f"{r['hist_chars'] / 1e6:.1f}") for r in out]
    print(f"cost of one cell by stage: {args.preset} seed 1, {args.pairs or 'all'} pairs, one process per cell, "
          f"one thread; first run (render or cache hit, + a dis cell) {render_s:.0f} s; "
          f"load average {os.getloadavg()[0]:.1f}\n")
    print(_table(rows, ("pipeline", "pairs", "wall_s", *keys, "rows", "parquet_MB", "hist_Mchar")))
    cpu = sum(r["cpu_s"] for r in out)
    wall = sum(r["wall_s"] for r in out)
    print(f"\nsum over the pipelines: {cpu:.0f} CPU-s ({wall:.0f} s wall, so this process got {cpu / wall:.2f} of a core)."
          f"\nA suite of --scenes {args.scenes} such scenes x these pipelines on --workers {args.workers}: cells "
          f"~{args.scenes * cpu / args.workers / 60:.1f} min if each worker has a core of its own "
          f"(CPU-s x scenes / workers; each process here also paid its imports, which a pool worker pays once)")
    _print_commands(shown)
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1))


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "_render":
        return child_render(sys.argv[2], sys.argv[3])
    if len(sys.argv) > 1 and sys.argv[1] == "_cell":
        return child_cell(sys.argv[2])
    if len(sys.argv) > 1 and sys.argv[1] == "_cost":
        return child_cost(sys.argv[2], sys.argv[3], int(sys.argv[4]))
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = p.add_subparsers(dest="command", required=True)
    s = sub.add_parser("smoke")
    s.add_argument("--workers", type=int, default=2)
    s.set_defaults(fn=cmd_smoke)
    s = sub.add_parser("speedup")
    s.add_argument("--repeats", type=int, default=3)
    s.add_argument("--cells", type=int, default=8)
    s.add_argument("--frames", type=int, default=30)
    s.add_argument("--size", default="640x480")
    s.set_defaults(fn=cmd_speedup)
    s = sub.add_parser("memory")
    s.add_argument("--frames", default="60,300")
    s.add_argument("--size", default="1920x1080")
    s.add_argument("--preset", default="nominal")
    s.add_argument("--pipelines", default="thesis-lk,pyramidal-hs")
    s.add_argument("--cache", default=None, help="render cache (default: a temp folder, deleted afterwards)")
    s.add_argument("--keep", action="store_true", help="keep the render cache")
    s.set_defaults(fn=cmd_memory)
    s = sub.add_parser("standard")
    s.add_argument("--cells", type=int, default=0, help="run a subset of this many cells and extrapolate")
    s.add_argument("--workers", type=int, default=2)
    s.add_argument("--cache", default=None)
    s.set_defaults(fn=cmd_standard)
    s = sub.add_parser("cores")
    s.add_argument("--max-workers", type=int, default=0, help="largest worker count (default: the cores here)")
    s.add_argument("--cells", type=int, default=0, help="cells in the suite (default: 2 per worker at most)")
    s.add_argument("--frames", type=int, default=30)
    s.add_argument("--size", default="640x480")
    s.add_argument("--pipeline", default="thesis-lk",
                   help="pipeline, or several comma-separated (each seed runs each: a mix of cell costs)")
    s.add_argument("--suite", default=None, help="run this suite (e.g. standard) instead, at each worker count")
    s.set_defaults(fn=cmd_cores)
    s = sub.add_parser("scene")
    s.add_argument("--reference", required=True, help="another aerobench source tree (a git worktree)")
    s.add_argument("--presets", default="nominal", help="scene presets, comma-separated (seed 1 each)")
    s.add_argument("--pipelines", default=STANDARD_PIPELINES)
    s.add_argument("--workers", type=int, default=1)
    s.add_argument("--repeats", type=int, default=3)
    s.add_argument("--cache", default=None, help="render cache (default: a temp folder, deleted afterwards)")
    s.set_defaults(fn=cmd_scene)
    s = sub.add_parser("replay")
    s.add_argument("run", help="a finished run folder")
    s.add_argument("--workers", default="1,2,4,8,14,16,32")
    s.add_argument("--startup", type=float, default=4.0, help="seconds for the pool's workers to start (imports)")
    s.add_argument("--serial", action="store_true", help="measure collection and the report on a copy of the run")
    s.set_defaults(fn=cmd_replay)
    s = sub.add_parser("cost")
    s.add_argument("--preset", default="nominal")
    s.add_argument("--pipelines", default=STANDARD_PIPELINES)
    s.add_argument("--pairs", type=int, default=0, help="only the first N pairs (default: all)")
    s.add_argument("--cache", default=None, help="render cache (default: a temp folder, kept)")
    s.add_argument("--json", default=None, help="also write the figures to this file")
    s.add_argument("--scenes", type=int, default=27, help="scenes of the suite to estimate (standard: 27)")
    s.add_argument("--workers", type=int, default=2, help="workers of the suite to estimate")
    s.set_defaults(fn=cmd_cost)
    args = p.parse_args()
    args.fn(args)


if __name__ == "__main__":
    main()
