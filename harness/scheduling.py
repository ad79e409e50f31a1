"""Hand a run's tasks to an executor: renders first, then the longest ready cell; retries; progress.

Scheduling only decides the order and the retries, never a result: rows are sorted
on collection, so the accuracy numbers do not depend on the executor or the number
of workers. The cost of a cell comes from the flow method's registered relative cost
(:func:`algorithms.registry.flow_cost`), so plugins take part without a table here.
"""

from __future__ import annotations

import heapq
import itertools
import math
import shutil
import sys
import tempfile
import threading
from collections.abc import Mapping
from concurrent.futures import FIRST_COMPLETED, Future, wait
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from harness.suites import Cell, SceneVariant, Suite
from harness.tasks import cell_payload, cell_task, cells_task, render_task

__all__ = ["RETRY_ROUNDS", "execute", "run_workers", "compile_ahead", "kernels_to_compile", "read_render_progress", "cell_cost", "scene_cost", "cell_groups", "groups_per_scene", "say"]


def say(progress: bool, msg: str) -> None:
    """A status line on stderr when ``progress`` is on."""
    if progress:
        print(msg, file=sys.stderr, flush=True)


# --------------------------------------------------------------------------- cost model


def scene_cost(v: SceneVariant) -> float:
    """Frames x pixels of a scene variant (the work of rendering it, and of each of its cells)."""
    img = getattr(v.spec, "image", None)
    if img is None:
        return 1.0
    return float(img.n_frames) * float(img.width_px) * float(img.height_px)


def cell_cost(cell: Cell) -> float:
    """Estimated work of a cell: frames x pixels x the flow method's registered relative cost.

    Only the order of cells depends on it (longest first), never a result.
    """
    from algorithms.registry import flow_cost

    flow = cell.pipeline_spec.get("flow") if isinstance(cell.pipeline_spec, Mapping) else None
    method = flow.get("method") if isinstance(flow, Mapping) else None
    return scene_cost(cell.variant) * flow_cost(str(method))


# A worker process's start in cost units (frames x pixels x relative flow cost, :func:`cell_cost`): its imports
# and numba kernels loaded take ~3 s of CPU, about what Lucas-Kanade does on a million pixel-frames with its
# scoring (tiny, 160x120x6: ~0.35 s a cell). Only how many processes start depends on it, never a result.
WORKER_START_COST = 1.0e6


def run_workers(todo: list[Cell], available: int) -> int:
    """Worker processes a run of ``todo`` starts by default: one per ``available`` core, but no more than
    the work keeps busy beyond their start (:data:`WORKER_START_COST` a worker, renders counted at
    :func:`scene_cost`).

    A one-scene run of the tiny preset (three cells) ran in one worker in half the CPU time of two
    (6.3 s against 13 s; 3 tasks of one cell each read its frames and truth three times) and no
    longer. Real footage has no size here (:func:`scene_cost` is 1): its runs use every core.
    """
    variants = {c.variant.scene_hash: c.variant for c in todo}
    if any(getattr(v.spec, "image", None) is None for v in variants.values()):
        return available
    work = sum(cell_cost(c) for c in todo) + sum(scene_cost(v) for v in variants.values())
    return max(1, min(available, math.ceil(work / WORKER_START_COST)))


def groups_per_scene(n_scenes: int, n_cells: int, workers: int) -> int:
    """How many tasks a scene's ``n_cells`` cells are split into: enough for two tasks a worker.

    One task per scene shares the most (frames, pass 1, truth read once); a suite of
    fewer scenes than twice the workers splits each scene so that no worker idles.
    One worker has nobody to wait for: one task per scene.
    """
    if n_scenes < 1 or n_cells < 1 or workers < 1:
        raise ValueError(f"expected positive counts, got {n_scenes} scenes, {n_cells} cells, {workers} workers")
    if workers == 1:
        return 1
    return max(1, min(n_cells, math.ceil(2 * workers / n_scenes)))


def cell_groups(cells: list[Cell], n_groups: int) -> list[list[Cell]]:
    """``cells`` (of one scene) in ``n_groups`` groups of about equal :func:`cell_cost`, longest first.

    Longest cell first to the cheapest group (LPT); inside a group cells keep the suite's order.
    """
    n_groups = max(1, min(n_groups, len(cells)))
    order = {id(c): k for k, c in enumerate(cells)}
    cost = {id(c): cell_cost(c) for c in cells}
    groups: list[list[Cell]] = [[] for _ in range(n_groups)]
    load = [0.0] * n_groups
    for c in sorted(cells, key=lambda c: -cost[id(c)]):  # stable: ties keep the suite's order
        k = min(range(n_groups), key=lambda g: (load[g], g))
        groups[k].append(c)
        load[k] += cost[id(c)]
    ranked = sorted(range(n_groups), key=lambda g: -load[g])  # stable: equal loads keep their order
    return [sorted(groups[g], key=lambda c: order[id(c)]) for g in ranked if groups[g]]


# --------------------------------------------------------------------------- scheduling


# A task whose worker process died is retried: first in a fresh pool with the other lost
# tasks (most were only queued behind the one that died), then alone in a pool of its own,
# so that one task that kills its worker cannot take an innocent task down with it.
RETRY_ROUNDS = ("parallel", "parallel", "isolated")


@dataclass
class _Work:
    """What ``execute`` still has to do, and what it has seen so far."""

    renders: list[str]  # scene keys to render
    cells: list[tuple[Cell, dict]]  # cells ready to run, with their render result
    rendered: int = 0
    reused: int = 0
    render_failed: int = 0


def _variant_key(v: SceneVariant) -> str:
    return v.scene_hash


def execute(todo: list[Cell], cells_dir: Path, cache: Path, provenance: dict, suite: Suite,
            executor: str, workers: int | None, scheduler: str | None,
            progress: bool, read: Any = None) -> tuple[int, int, int]:
    """Render the scenes ``todo`` needs, then run its cells as their scene becomes ready.

    ``read``, a :class:`harness.results.CellRowsReader`, is given each cell a worker
    completed, while the other workers go on (so that collection at the end only joins).
    Returns (scenes rendered, scenes reused from the cache, scenes that failed to render).
    """
    from tqdm import tqdm

    if not todo:
        return 0, 0, 0
    from harness.suites import import_paths

    imports = list(getattr(suite, "imports", None) or [])
    by_scene: dict[str, list[Cell]] = {}
    variants: dict[str, SceneVariant] = {}
    for c in todo:
        key = _variant_key(c.variant)
        by_scene.setdefault(key, []).append(c)
        variants[key] = c.variant
    cache.mkdir(parents=True, exist_ok=True)
    bar = tqdm(total=len(variants) + len(todo), desc="scenes+cells", unit="task",
               disable=not progress, file=sys.stderr, dynamic_ncols=True)
    # render tasks write their frames done here (local workers only: elsewhere the writes fail quietly)
    progress_dir = tempfile.mkdtemp(prefix="aerobench-progress-") if progress else None
    ctx = {"cells_dir": cells_dir, "cache": cache, "provenance": provenance, "imports": imports,
           "import_paths": import_paths(suite),
           "variants": variants, "by_scene": by_scene, "bar": bar, "progress": progress, "read": read,
           "progress_dir": progress_dir}
    try:
        return _execute(ctx, todo, executor, workers, scheduler)
    finally:
        bar.close()
        if progress_dir is not None:
            shutil.rmtree(progress_dir, ignore_errors=True)


def _execute(ctx: dict, todo: list[Cell], executor: str, workers: int | None,
             scheduler: str | None) -> tuple[int, int, int]:
    variants, by_scene, bar, progress = ctx["variants"], ctx["by_scene"], ctx["bar"], ctx["progress"]
    ctx["kernels_ready"] = compile_ahead(todo, ctx, local=executor != "dask")
    if workers is None and executor != "dask":  # a remote cluster has its own workers
        from harness.executors import default_workers

        workers = run_workers(todo, default_workers())
    work = _Work(renders=list(variants), cells=[])
    for mode in RETRY_ROUNDS:
        if not work.renders and not work.cells:
            break
        if mode == "parallel":
            work = _round(work, ctx, executor, workers, scheduler)
        else:  # each remaining task alone in a fresh single-worker pool
            left = _Work(renders=[], cells=[], rendered=work.rendered, reused=work.reused,
                         render_failed=work.render_failed)
            for item in [("render", k) for k in work.renders] + [("cell", c) for c in work.cells]:
                one = _Work(renders=[item[1]] if item[0] == "render" else [],
                            cells=[item[1]] if item[0] == "cell" else [])
                one = _round(one, ctx, executor, 1 if executor != "dask" else None, scheduler)
                left.renders += one.renders
                left.cells += one.cells
                left.rendered += one.rendered
                left.reused += one.reused
                left.render_failed += one.render_failed
            work = left
        lost = len(work.renders) + len(work.cells)
        if lost:
            say(progress, f"{lost} task(s) lost with a worker process that died; retrying them")
    # still lost after every retry: the task itself kills its worker (a crash in native code, OOM)
    lost_msg = f"WorkerLost: the worker process died {len(RETRY_ROUNDS)} times running this"
    for key in work.renders:
        work.render_failed += 1
        for c in by_scene[key]:
            work.cells.append((c, {"path": None, "error": f"{lost_msg} scene's rendering"}))
    for c, render in work.cells:
        payload = _cell_payload(c, render, ctx)
        payload["render_error"] = render.get("error") or f"{lost_msg} cell"
        cell_task(payload)  # records the failure (in this process: it raises before any work)
        bar.update(1)
    return work.rendered, work.reused, work.render_failed


# modules whose kernels every pipeline runs (besides its flow and global-motion methods')
PIPELINE_KERNEL_MODULES = ("algorithms.pipeline", "algorithms.filters", "algorithms.tracking")


def pipeline_kernel_modules(specs: list[Any]) -> set[str]:
    """The modules whose numba kernels the pipelines ``specs`` (resolved dicts) run: their flow and
    global-motion methods' modules and :data:`PIPELINE_KERNEL_MODULES`."""
    import algorithms.pipeline  # noqa: F401  (registers every built-in stage)
    from algorithms.registry import STAGES

    modules = set(PIPELINE_KERNEL_MODULES)
    for spec in specs:
        for kind in ("flow", "global_motion"):
            stage = spec.get(kind) if isinstance(spec, Mapping) else None
            fn = STAGES.get(kind, {}).get(stage.get("method")) if isinstance(stage, Mapping) else None
            if fn is not None:
                modules.add(fn.__module__)
    return modules


def kernels_to_compile(package: str = "algorithms", *, modules: set[str] | None = None) -> list[str]:
    """Names of the numba kernels of ``package`` (``"algorithms"`` or ``"scenes"``; only those of
    ``modules`` when given) that numba's on-disk cache lacks (or holds for another version of
    their source): what a first run compiles (the pipelines' kernels about a minute of CPU, the
    scenes' about ten seconds).

    Reads numba's cache index through its caching module; if that changes, nothing is reported.
    """
    import importlib

    for module in {"algorithms": ("algorithms.pipeline",),  # imports every built-in stage and its kernels
                   "scenes": ("scenes._truth_kernels", "scenes._codec_kernels")}[package]:
        importlib.import_module(module)
    try:
        from numba.core.registry import CPUDispatcher
    except ImportError:
        return []
    cold = []
    for name, module in sorted(sys.modules.items()):
        if not name.startswith(f"{package}.") or module is None or (modules is not None and name not in modules):
            continue
        for attr, obj in vars(module).items():
            if not isinstance(obj, CPUDispatcher) or getattr(obj, "__module__", name) != name:
                continue
            if obj.targetoptions.get("inline") == "always":  # compiled into its callers, never cached alone
                continue
            cache = getattr(obj, "_cache", None)
            try:
                if not cache._cache_file._load_index():  # {} when absent or stale
                    cold.append(f"{name}.{attr}")
            except Exception:  # noqa: BLE001 - another numba: say nothing rather than guess
                return []
    return cold


def compile_ahead(todo: list[Cell], ctx: dict, *, local: bool) -> threading.Event:
    """Compile the numba kernels once in this process while the workers render, if the cache is cold.

    Only the kernels of the modules these pipelines run count (:func:`pipeline_kernel_modules`: a
    suite without TV-L1 never compiles its kernels). Without this every worker compiled the same
    kernels at its first cell (the first smoke run
    sat at ``4/24`` for over a minute, saying nothing). Here the pipelines of ``todo`` run once
    on a tiny sequence (``harness.cell_scoring.warm_up``) in a thread, numba writes its cache,
    and cells are handed out when the returned event is set (renders go on meanwhile); the
    workers then load the kernels from the cache. Set at once when the cache is warm, or the
    workers are not on this machine (``local=False``).
    """
    ready = threading.Event()
    specs = {c.pipeline_hash: c.pipeline_spec for c in todo}
    cold = (kernels_to_compile(modules=pipeline_kernel_modules(list(specs.values()))) if local and todo
            else [])
    if not cold:
        ready.set()
        return ready
    if ctx["progress"]:
        ctx["bar"].write(f"compiling numerical kernels (first run only: {len(cold)} numba kernels, about a "
                         "minute); the scenes render meanwhile", file=sys.stderr)

    def run() -> None:
        from algorithms.pipeline import Pipeline
        from harness.cell_scoring import warm_up

        try:
            for spec in specs.values():
                try:
                    warm_up(Pipeline.from_dict(spec))
                except Exception:  # noqa: BLE001 - the cell reports its own error
                    pass
        finally:
            ready.set()

    threading.Thread(target=run, name="aerobench-compile-ahead", daemon=True).start()
    return ready


def _cell_payload(c: Cell, render: dict, ctx: dict) -> dict:
    payload = cell_payload(c, ctx["cells_dir"], ctx["provenance"], ctx["imports"], ctx["import_paths"])
    payload["sequence"] = render["path"]
    if render.get("error"):
        payload["render_error"] = render["error"]
        payload["render_traceback"] = render.get("traceback", "")
    return payload


PROGRESS_POLL_S = 0.5  # how often the bar shows the frames of the renders in flight


def _progress_file(ctx: dict, key: str) -> str | None:
    """Where a render task writes its frames done (``render_task``'s ``progress_file``), or None."""
    folder = ctx.get("progress_dir")
    return None if folder is None else str(Path(folder) / f"{key}.txt")


def read_render_progress(path: str | None) -> tuple[int, int] | None:
    """(frames done, total) a render task last wrote to ``path``; None before it wrote or if unreadable."""
    if path is None:
        return None
    try:
        done, total = Path(path).read_text().split()
        return int(done), int(total)
    except (OSError, ValueError):
        return None


def _render_status(pending: dict, ctx: dict) -> str:
    """The bar's postfix: each render in flight with its frames (``rendering realistic 23/60``), and each
    task of cells with the pairs its pipelines have scored (``clip: dis, tv-l1 40/198 pairs``)."""
    parts, cells = [], []
    for kind, item in pending.values():
        if kind != "render":
            if not item:
                continue
            got = read_render_progress(_progress_file(ctx, f"cells-{item[0][0].cell_id}"))
            if got:
                names = ", ".join(c.pipeline for c, _ in item)
                cells.append(f"{item[0][0].variant.label}: {names} {got[0]}/{got[1]} pairs")
            continue
        got = read_render_progress(_progress_file(ctx, item))
        label = ctx["variants"][item].label
        parts.append(f"{label} {got[0]}/{got[1]}" if got else f"{label} starting")
    status = "; ".join(x for x in (("rendering " + ", ".join(parts)) if parts else "", "; ".join(cells)) if x)
    if not ctx["kernels_ready"].is_set():
        status = "; ".join(x for x in (status, "compiling numerical kernels (first run only)") if x)
    return status


def _in_flight_limit(executor: str, workers: int | None) -> int | None:
    """Tasks handed to the executor at once: one per worker and one queued behind them.

    Holding the rest back lets the runner pick the next task when a worker frees up
    (renders first, then the longest ready cell), instead of the pool's first-in-first-out
    queue. A remote dask cluster has its own workers and scheduler: no limit there.
    """
    from harness.executors import default_workers

    if executor == "dask":
        return None
    return (workers or default_workers()) + 1


def _round(work: _Work, ctx: dict, executor: str, workers: int | None, scheduler: str | None) -> _Work:
    """Run ``work`` on one executor; returns what was lost with a dead worker (to retry).

    Scheduling: renders go first, largest scene first (they unblock cells); a scene's
    cells become ready when its render returns, as :func:`groups_per_scene` tasks of
    cells run together (:func:`harness.tasks.cells_task`); whenever a worker frees up,
    the longest ready task (sum of :func:`cell_cost`) is handed out, so the run does not
    end on a long task started last while the other workers idle.
    """
    from harness.executors import default_workers, open_executor

    lost = _Work(renders=[], cells=[], rendered=work.rendered, reused=work.reused,
                 render_failed=work.render_failed)
    bar = ctx["bar"]
    limit = _in_flight_limit(executor, workers)
    renders = sorted(work.renders, key=lambda k: -scene_cost(ctx["variants"][k]))
    ready: list[tuple[float, int, list[tuple[Cell, dict]]]] = []  # a heap: the longest task on top
    order = itertools.count()  # ties keep the suite's order
    scenes = {_variant_key(c.variant) for c, _ in work.cells} | set(work.renders)
    n_workers = workers or default_workers()

    def make_ready(items: list[tuple[Cell, dict]]) -> None:
        """Cells of one scene, ready to run: split into tasks and queued."""
        render = {id(c): r for c, r in items}
        n_groups = groups_per_scene(len(scenes), len(items), n_workers)
        for group in cell_groups([c for c, _ in items], n_groups):
            heapq.heappush(ready, (-sum(cell_cost(c) for c in group), next(order),
                                   [(c, render[id(c)]) for c in group]))

    by_scene: dict[str, list[tuple[Cell, dict]]] = {}
    for item in work.cells:
        by_scene.setdefault(_variant_key(item[0].variant), []).append(item)
    for items in by_scene.values():
        make_ready(items)
    with open_executor(executor, workers=workers, scheduler=scheduler) as pool:
        pending: dict[Future, tuple[str, Any]] = {}

        def fill() -> None:
            """Hand out tasks until the in-flight limit: renders first, then the longest cells."""
            while renders or ready:
                if limit is not None and len(pending) >= limit:
                    return
                if renders:
                    submit("render", renders.pop(0))
                elif ctx["kernels_ready"].is_set():
                    submit("cells", heapq.heappop(ready)[2])
                else:  # cells wait for the kernels compiled ahead (compile_ahead)
                    return

        def submit(kind: str, item: Any) -> None:
            try:
                if kind == "render":
                    v = ctx["variants"][item]
                    fut = pool.submit(render_task, item, v.spec, str(ctx["cache"]), ctx["imports"],
                                      ctx["import_paths"], _progress_file(ctx, item))
                else:
                    fut = pool.submit(cells_task, [_cell_payload(c, r, ctx) for c, r in item],
                                      _progress_file(ctx, f"cells-{item[0][0].cell_id}"))
            except RuntimeError:  # BrokenProcessPool (a RuntimeError) or a shut-down executor
                (lost.renders.append(item) if kind == "render" else lost.cells.extend(item))
                return
            pending[fut] = (kind, item)

        fill()
        while pending or ready:
            if not pending:  # only cells left, waiting for the kernels compiled ahead
                ctx["kernels_ready"].wait(PROGRESS_POLL_S)
                if ctx["progress"]:
                    bar.set_postfix_str(_render_status(pending, ctx), refresh=True)
                fill()
                continue
            # poll while there is a bar to update, or cells wait for the kernels (a free worker
            # must not idle behind a long render once they are ready)
            polling = ctx["progress"] or (ready and not ctx["kernels_ready"].is_set())
            done, _ = wait(list(pending), return_when=FIRST_COMPLETED, timeout=PROGRESS_POLL_S if polling else None)
            if ctx["progress"]:
                bar.set_postfix_str(_render_status(pending, ctx), refresh=True)
            if not done:
                fill()  # the kernels may be ready now
                continue
            for fut in done:
                kind, item = pending.pop(fut)
                try:
                    result = fut.result()
                except Exception:  # our tasks record their own failures: this is a lost worker
                    (lost.renders.append(item) if kind == "render" else lost.cells.extend(item))
                    continue
                if kind == "render":
                    bar.update(1)
                    if result["error"]:
                        lost.render_failed += 1
                    elif result["reused"]:
                        lost.reused += 1
                    else:
                        lost.rendered += 1
                    make_ready([(c, result) for c in ctx["by_scene"][item]])
                else:
                    fill()  # the next task first, then read this one's rows while the workers go on
                    bar.update(len(result))
                    for r in result:
                        if r["status"] != "ok" and ctx["progress"]:
                            bar.write(f"cell {r['cell_id']} failed: {r['error']}", file=sys.stderr)
                        if ctx["read"] is not None:
                            ctx["read"].add(r["cell_id"])
            fill()  # after a broken pool, every submit lands in ``lost`` and ``pending`` empties
    return lost
