"""The worker processes of ``studies.process_pool`` run BLAS and OpenMP on one thread each (the
processes are the parallelism); the in-process path keeps the caller's threads."""

from __future__ import annotations

import importlib
import subprocess
import sys

import threadpoolctl

import studies

#: threadpoolctl's kinds of thread pool that the workers pin.
PINNED_APIS = ("blas", "openmp")


def _thread_pools() -> list[dict]:
    """The thread pools of this process, once scipy's own BLAS is loaded too (a grid point loads it)."""
    importlib.import_module("scipy.linalg")  # loads scipy's own OpenBLAS beside numpy's

    return threadpoolctl.threadpool_info()


def test_each_worker_of_a_process_pool_runs_its_blas_on_one_thread():
    before = _thread_pools()
    pool = studies.process_pool(2)
    try:
        reports = [future.result(timeout=60) for future in [pool.submit(_thread_pools) for _ in range(4)]]
    finally:
        pool.shutdown()
    for pools in reports:
        pinned = [entry for entry in pools if entry["user_api"] in PINNED_APIS]
        assert pinned, pools  # numpy's BLAS at least
        assert all(entry["num_threads"] == 1 for entry in pinned), pinned
    # the parent (and so the serial path, executor=None) keeps its own thread counts
    assert [entry["num_threads"] for entry in _thread_pools()] == [entry["num_threads"] for entry in before]


def test_a_library_loaded_after_the_pinning_starts_on_one_thread_too():
    # a worker started by spawn or forkserver (the default from Python 3.14) loads numpy and scipy
    # after its initializer: the environment variables pin those
    # the workers' initializer, run in a fresh process (internal: no public face)
    script = ("from studies import _grid\n"
              "_grid.single_threaded_libraries()\n"
              "import numpy, scipy.linalg, threadpoolctl\n"
              "print(sorted({e['num_threads'] for e in threadpoolctl.threadpool_info()\n"
              "              if e['user_api'] in ('blas', 'openmp')}))\n")
    env_path = {"PYTHONPATH": ":".join(p for p in sys.path if p)}
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120,
                          env=env_path, check=True)
    assert done.stdout.strip() == "[1]", done.stderr
