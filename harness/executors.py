"""Where the runner's tasks run: a local process pool or a Dask cluster, one interface.

Both give a standard :class:`concurrent.futures.Executor`, so the runner has one code
path: ``submit`` returns futures that ``concurrent.futures.as_completed`` can wait on.

- ``"process"``: a :class:`~concurrent.futures.ProcessPoolExecutor` with the *spawn*
  start method (a forked child must never inherit an OpenGL context), one worker per
  core by default.
- ``"dask"``: an existing ``dask.distributed`` scheduler at ``scheduler`` (an address
  such as ``tcp://10.0.0.5:8786``), through ``Client.get_executor()``.
- ``"dask-local"``: a :class:`distributed.LocalCluster` of ``workers`` single-threaded
  worker processes on this machine (a rehearsal of the cluster path).

Dask is optional: without it the two dask kinds raise :class:`ExecutorError` saying
``pip install aerobench[dask]``.
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Iterator
from concurrent.futures import Executor, ProcessPoolExecutor
from contextlib import contextmanager

__all__ = ["EXECUTORS", "ExecutorError", "check_executor", "default_workers", "open_executor"]

EXECUTORS = ("process", "dask", "dask-local")


class ExecutorError(ValueError):
    """The executor asked for cannot be made (unknown kind, dask missing, bad address)."""


def default_workers() -> int:
    """Worker processes to use by default: the cores this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


# thread pools of the native libraries a worker uses (OpenMP, BLAS, numba, llvmpipe's renderer)
THREAD_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS", "LP_NUM_THREADS")
WORKER_THREADS_ENV = "AEROBENCH_WORKER_THREADS"


def worker_threads(workers: int) -> int:
    """Threads of OpenCV, OpenMP/BLAS, numba and llvmpipe in each worker process: one.

    OpenCV starts a thread per core in every process; with one process per core that
    oversubscribes the machine (2 workers on 2 cores ran slower than 1), and one worker
    with two threads was no faster than with one (8.7 s both, 60 % more CPU). One thread
    whatever the worker count also keeps results bit-identical across worker counts
    (OpenCV's parallel splits differ with its thread count). ``$AEROBENCH_WORKER_THREADS``
    overrides it.
    """
    env = os.environ.get(WORKER_THREADS_ENV)
    return max(1, int(env)) if env else 1


def limit_threads(threads: int) -> None:
    """Cap the native thread pools of this process at ``threads`` (a worker: see :func:`worker_setup`).

    Runs before the first task imports numpy, OpenCV or OpenGL, so the environment variables
    take effect; OpenCV is also told directly.
    """
    for var in THREAD_ENV:
        os.environ[var] = str(threads)
    os.environ[WORKER_THREADS_ENV] = str(threads)
    import cv2

    cv2.setNumThreads(threads)
    keep_freed_memory()


_PR_SET_PDEATHSIG = 1  # <sys/prctl.h>


def die_with_parent() -> bool:
    """Have the kernel kill this process (SIGKILL) when the process that started it dies.

    A pool worker otherwise outlives a runner killed by ``kill PID`` or the OOM killer:
    it waits on its task queue for ever, holding its memory (seen: two workers still
    alive 80 minutes after their runner was killed). The runner's spawn pool starts its
    workers from the thread that calls ``submit``, the runner's own, which lives as long as
    the pool. Returns False where there is no ``prctl`` (not Linux: nothing changed).
    """
    import ctypes
    import ctypes.util
    import signal

    try:
        prctl = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True).prctl
    except (OSError, AttributeError):
        return False
    if prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0) != 0:
        return False
    # the parent may have died before the call: then we were re-parented already
    if os.getppid() == 1:
        os._exit(1)
    return True


def worker_setup(threads: int) -> None:
    """Pool initializer: native thread pools capped (:func:`limit_threads`), memory kept for
    reuse, and the worker dies with its runner (:func:`die_with_parent`)."""
    limit_threads(threads)
    die_with_parent()


# glibc's mallopt parameters (<malloc.h>)
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_MMAP_THRESHOLD_MAX = 32 << 20  # the largest glibc accepts on 64-bit
_TRIM_THRESHOLD = 512 << 20


def keep_freed_memory() -> bool:
    """Have glibc's malloc keep freed memory for the next allocation instead of returning it to the kernel.

    A pipeline allocates and frees frame-sized arrays (0.3 to 5 MB at 640x480) many
    times per pair. By default glibc serves each with a fresh ``mmap`` (or trims the
    heap after the free), and every page of it then costs a page fault when first
    written: a third of the CPU time of pyramidal Lucas-Kanade (``benchmarks/pipeline_speed.py``).
    Blocks up to 32 MB now come from the heap, and the heap keeps up to 512 MB of freed
    memory; results are unchanged (only where the memory comes from). A worker's resident
    size stays near its peak instead. Returns False where there is no glibc (nothing changed).
    """
    import ctypes
    import ctypes.util

    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # not glibc (macOS, musl without mallopt)
        return False
    return bool(mallopt(_M_MMAP_THRESHOLD, _MMAP_THRESHOLD_MAX)) & bool(mallopt(_M_TRIM_THRESHOLD, _TRIM_THRESHOLD))


def _import_distributed():
    try:
        import distributed
    except ImportError:
        raise ExecutorError(
            "the dask executors need dask.distributed, which is not installed: pip install aerobench[dask]"
        ) from None
    return distributed


def check_executor(kind: str, *, workers: int | None = None, scheduler: str | None = None) -> None:
    """Raise :class:`ExecutorError` now if :func:`open_executor` would refuse these arguments.

    The runner calls this before it writes anything, so a bad request leaves no run folder.
    """
    if kind not in EXECUTORS:
        raise ExecutorError(f"unknown executor {kind!r}; valid: {', '.join(EXECUTORS)}")
    if workers is not None and workers < 1:
        raise ExecutorError(f"workers: expected a positive number, got {workers}")
    if scheduler is not None and kind != "dask":
        raise ExecutorError(f"--scheduler is for the dask executor, not {kind!r}")
    if kind == "dask" and not scheduler:
        raise ExecutorError("the dask executor needs a scheduler address (--scheduler tcp://HOST:8786)")
    if kind in ("dask", "dask-local"):
        _import_distributed()


@contextmanager
def open_executor(
    kind: str = "process", *, workers: int | None = None, scheduler: str | None = None,
    connect_timeout_s: float = 10.0,
) -> Iterator[Executor]:
    """An executor of ``kind``, shut down (and its cluster closed) on exit.

    Parameters
    ----------
    kind : {"process", "dask", "dask-local"}
    workers : int, optional
        Worker processes for ``process`` and ``dask-local``; default: one per core.
        Ignored for ``dask`` (the cluster has its own workers).
    scheduler : str, optional
        Scheduler address; required for ``dask``, refused for the others.
    connect_timeout_s : float
        How long to try reaching the ``dask`` scheduler before giving up.
    """
    check_executor(kind, workers=workers, scheduler=scheduler)
    n = workers or default_workers()

    if kind == "process":
        pool = ProcessPoolExecutor(max_workers=n, mp_context=multiprocessing.get_context("spawn"),
                                   initializer=worker_setup, initargs=(worker_threads(n),))
        try:
            yield pool
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
        return

    distributed = _import_distributed()
    if kind == "dask":
        try:
            client = distributed.Client(scheduler, timeout=f"{connect_timeout_s}s")
        except (OSError, TimeoutError) as exc:
            raise ExecutorError(f"cannot reach the dask scheduler at {scheduler}: {exc}") from None
        try:
            yield client.get_executor()
        finally:
            client.close()
        return

    # dask-local: worker processes (GL needs a process each), one thread each, no dashboard
    cluster = distributed.LocalCluster(
        n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None, silence_logs=40
    )
    client = distributed.Client(cluster)
    try:
        yield client.get_executor()
    finally:
        client.close()
        cluster.close()
