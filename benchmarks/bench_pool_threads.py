"""BLAS threads in the workers of a process pool: ``studies._grid.process_pool`` (each worker's BLAS
and OpenMP on one thread) against the same pool without the pinning (each worker's OpenBLAS
starting one thread per core), side by side in this process on the same grid.

The grid: a speed sweep of four_bar_fem4 with a finer coupler (``n_elements`` elements, m
independent coordinates), where the periodic solve's steps go through LAPACK and dgemm
(``periodic._newmark``'s LAPACK path, n >= 20), on 2 worker processes. With 2 cores, two unpinned
workers run 4 BLAS threads; on a machine loaded by other work the oversubscription costs more.
Medians of alternating runs, and their ratio (2026-11-30, 2 cores, load about 1.8: 18.7 s unpinned,
0.91 s pinned, 20x; --quick 7.4 s against 0.37 s). Run:
    .venv/bin/python benchmarks/bench_pool_threads.py [--quick]
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
from concurrent.futures import ProcessPoolExecutor

import numpy as np
from bench_linearize import median_time  # this folder is the script's path: the same timer

import studies
from studies import _grid

WORKERS = 2
ELEMENTS = "links.coupler.discretisation.n_elements"


def unpinned_pool(workers: int) -> ProcessPoolExecutor:
    """The pool as it was: workers that die with this process, BLAS threads left as the library
    chose them."""
    return ProcessPoolExecutor(workers, initializer=_grid.die_with_parent, initargs=(os.getpid(),))


def blas_threads(pool) -> list[int]:
    """The BLAS thread counts one worker of ``pool`` reports."""
    return pool.submit(_worker_threads).result()


def _worker_threads() -> list[int]:
    import threadpoolctl

    importlib.import_module("scipy.linalg")  # scipy's own OpenBLAS, the one the LAPACK path calls

    return [entry["num_threads"] for entry in threadpoolctl.threadpool_info()
            if entry["user_api"] == "blas"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="a smaller grid, fewer repeats")
    parser.add_argument("--elements", type=int, default=24, help="coupler elements (default 24)")
    args = parser.parse_args()
    logging.disable(logging.WARNING)
    count, n_steps, repeats = (8, 64, 3) if args.quick else (16, 128, 5)
    mechanism = studies.MechanismProblem.from_scene("four_bar_fem4").mechanism({})
    problem = studies.MechanismProblem.from_mechanism(mechanism.with_parameters({ELEMENTS: args.elements}))
    speeds = np.linspace(50.0, 150.0, count)
    m = len(problem.describe({}).labels)
    print(f"speed sweep of four_bar_fem4, coupler {args.elements} elements ({m} coordinates), {count} "
          f"speeds x {n_steps} steps, {WORKERS} workers, {os.cpu_count()} cores, load "
          f"{os.getloadavg()[0]:.1f}; medians of {repeats}")
    pools = {"unpinned": unpinned_pool(WORKERS), "pinned (process_pool)": _grid.process_pool(WORKERS)}
    try:
        for name, pool in pools.items():  # warm every worker's imports and JIT cache
            studies.sweep(problem, "speed", speeds[:WORKERS], n_steps=n_steps, executor=pool)
            print(f"   {name:22s} worker BLAS threads {blas_threads(pool)}")
        times = {name: [] for name in pools}
        for _ in range(repeats):  # alternate, so that a change of the machine's load hits both
            for name, pool in pools.items():
                times[name].append(median_time(
                    lambda: studies.sweep(problem, "speed", speeds, n_steps=n_steps, executor=pool), 1))
    finally:
        for pool in pools.values():
            pool.shutdown()
    medians = {name: float(np.median(values)) for name, values in times.items()}
    for name, seconds in medians.items():
        print(f"   {name:22s} {seconds:7.3f} s")
    print(f"   unpinned / pinned: {medians['unpinned'] / medians['pinned (process_pool)']:.2f}x")


if __name__ == "__main__":
    main()
