"""Executors: spawned local processes, Dask optional with a clear message, same numbers on both."""

from __future__ import annotations

import copy
import os
import sys

import pytest
from conftest import TINY_SUITE

from harness.executors import ExecutorError, open_executor


def _pid_and_start_method():
    import multiprocessing

    return os.getpid(), multiprocessing.get_start_method()


def test_process_pool_spawns():
    with open_executor("process", workers=1) as pool:
        pid, method = pool.submit(_pid_and_start_method).result(timeout=60)
    assert pid != os.getpid()
    assert method == "spawn"  # a forked child could inherit a GL context


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


def _accuracy(table):
    from test_runner import accuracy_table

    return accuracy_table(table)


@pytest.mark.gl
@pytest.mark.slow
def test_dask_local_cluster_gives_the_process_pool_numbers(tmp_path, render_cache):
    pytest.importorskip("distributed", reason="dask.distributed is not installed (pip install aerobench[dask])")
    from harness.runner import run_suite
    from harness.suites import parse_suite

    suite = parse_suite(copy.deepcopy(TINY_SUITE))
    a = run_suite(suite, tmp_path / "process", workers=2, cache_dir=render_cache, progress=False)
    b = run_suite(suite, tmp_path / "dask", workers=2, executor="dask-local", cache_dir=render_cache,
                  progress=False)
    assert a.ok and b.ok, (a.failed_cells, b.failed_cells)
    acc_a, acc_b = _accuracy(a.table), _accuracy(b.table)
    assert len(acc_a) > 0
    import pandas as pd

    pd.testing.assert_frame_equal(acc_a, acc_b)
