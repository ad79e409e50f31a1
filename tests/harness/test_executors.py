"""Executors: spawned local processes, Dask optional with a clear message, same numbers on both."""

from __future__ import annotations

import copy
import os
import sys

import pandas as pd
import pytest
from tests.harness.harness_testdata import TINY_SUITE, accuracy_table

from harness.executors import ExecutorError, open_executor


def _pid_and_start_method():
    import multiprocessing

    return os.getpid(), multiprocessing.get_start_method()


def test_process_pool_spawns():
    with open_executor("process", workers=1) as pool:
        pid, method = pool.submit(_pid_and_start_method).result(timeout=60)
    assert pid != os.getpid()
    assert method == "spawn"  # a forked child could inherit a GL context


def _page_faults_per_flow_call() -> float:
    import resource

    import numpy as np

    from algorithms.lucas_kanade_flow import lucas_kanade

    f0 = np.random.default_rng(0).random((240, 320)).astype(np.float32) * 255
    f1 = np.roll(f0, 1, axis=1)
    lucas_kanade(f0, f1, window=11, levels=3, iterations=2)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(5):
        lucas_kanade(f0, f1, window=11, levels=3, iterations=2)
    return (resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before) / 5


_ORPHAN_PARENT = """
import os, sys, time
from harness.executors import open_executor
with open_executor("process", workers=1) as pool:
    print(pool.submit(os.getpid).result(), flush=True)
    time.sleep(60)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="prctl(PR_SET_PDEATHSIG)")
def test_a_worker_dies_with_its_runner():
    """A runner killed with SIGKILL leaves no worker waiting on its queue for ever."""
    import signal
    import subprocess
    import time
    from pathlib import Path

    proc = subprocess.Popen([sys.executable, "-c", _ORPHAN_PARENT], stdout=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    try:
        worker = int(proc.stdout.readline())
        os.kill(worker, 0)  # alive while its runner is
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            try:
                os.kill(worker, 0)
            except ProcessLookupError:
                break
            if Path(f"/proc/{worker}/stat").read_text().split()[2] == "Z":  # a zombie: dead, not yet reaped
                break
            time.sleep(0.05)
        else:
            os.kill(worker, signal.SIGKILL)
            raise AssertionError(f"worker {worker} outlived its runner by 10 s")
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
        proc.stdout.close()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's malloc")
def test_workers_reuse_freed_memory_instead_of_faulting_fresh_pages():
    # glibc's default hands a pyramidal LK call of 320x240 about 1000 fresh pages (each a page
    # fault) every time; a worker keeps freed memory (harness.executors.keep_freed_memory)
    with open_executor("process", workers=1) as pool:
        faults = pool.submit(_page_faults_per_flow_call).result(timeout=120)
    assert faults < 50


@pytest.mark.parametrize("kwargs, match", [
    ({"kind": "threads"}, r"unknown executor 'threads'; valid: process, dask, dask-local"),
    ({"kind": "process", "workers": 0}, r"workers: expected a positive number, got 0"),
    ({"kind": "process", "scheduler": "tcp://x:1"}, r"--scheduler is for the dask executor"),
    ({"kind": "dask"}, r"needs a scheduler address"),
])
def test_bad_executor_requests_are_refused(kwargs, match):
    pytest.importorskip("distributed") if kwargs.get("kind") == "dask" else None
    kind = kwargs.pop("kind")
    with pytest.raises(ExecutorError, match=match):
        with open_executor(kind, **kwargs):
            pass


@pytest.mark.parametrize("kind", ["dask", "dask-local"])
def test_missing_dask_names_the_extra(monkeypatch, kind):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed -> ImportError
    with pytest.raises(ExecutorError, match=r"pip install aerobench\[dask\]"):
        with open_executor(kind, scheduler="tcp://127.0.0.1:1" if kind == "dask" else None):
            pass


@pytest.mark.gl
@pytest.mark.slow
def test_dask_local_cluster_gives_the_process_pool_numbers(tmp_path, render_cache, reference_run):
    pytest.importorskip("distributed", reason="dask.distributed is not installed (pip install aerobench[dask])")
    from harness.runner import run_suite
    from harness.suites import parse_suite

    dask = run_suite(parse_suite(copy.deepcopy(TINY_SUITE)), tmp_path / "dask", workers=2, executor="dask-local",
                     cache_dir=render_cache, progress=False)
    assert dask.ok, dask.failed_cells
    # TINY_SUITE's cells are cells of the reference run (same ids): compare them there
    cells = set(dask.table["cell_id"])
    assert cells < set(reference_run.table["cell_id"])
    process = reference_run.table[reference_run.table["cell_id"].isin(cells)]
    acc = accuracy_table(dask.table)
    assert len(acc) > 0
    pd.testing.assert_frame_equal(acc, accuracy_table(process))


@pytest.mark.gl
@pytest.mark.slow
def test_an_existing_dask_scheduler_runs_the_cells(tmp_path, render_cache, reference_run):
    distributed = pytest.importorskip("distributed", reason="dask.distributed is not installed")
    from harness.runner import run_suite
    from harness.suites import parse_suite

    one_cell = {**copy.deepcopy(TINY_SUITE), "pipelines": ["dis"]}
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None,
                                  silence_logs=40) as cluster:
        result = run_suite(parse_suite(one_cell), tmp_path / "run", executor="dask",
                           scheduler=cluster.scheduler_address, cache_dir=render_cache, progress=False)
    assert result.ok, result.failed_cells
    process = reference_run.table[reference_run.table["cell_id"].isin(set(result.table["cell_id"]))]
    pd.testing.assert_frame_equal(accuracy_table(result.table), accuracy_table(process))


def test_an_unreachable_scheduler_is_a_clear_error():
    pytest.importorskip("distributed")
    with pytest.raises(ExecutorError, match=r"cannot reach the dask scheduler at tcp://127.0.0.1:9"):
        with open_executor("dask", scheduler="tcp://127.0.0.1:9", connect_timeout_s=0.5):
            pass
