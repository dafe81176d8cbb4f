"""One BLAS thread in every process of the ``flexvib`` command, the command's own included.

OpenBLAS (numpy's and scipy's) starts one thread per core and lets them spin while they wait for
work. The blocks the tool hands to BLAS and LAPACK are small (a monodromy's (2n, 2n) eigenvalues and
n x n LU factors and products with n up to a few hundred) and many: beside any other busy process
the spinning threads oversubscribe the cores (``flexvib check --case "64 elements"`` took 26 s with
the default threads and 2.8 s with one, on the 2-core machine under load), and no block size up to
n = 800 ran faster on two threads than on one there (``benchmarks/bench_blas_threads.py``,
docs/benchmarks.md). So the command runs each process on one BLAS thread: this process through
``threadpoolctl`` (the libraries already loaded) and the environment variables (those loaded later,
and the processes it starts: pool workers pin theirs again in ``studies.process_pool``'s
initializer). A thread count the user set in one of the variables is left as it is.

The library itself (``import studies``) leaves a program's threads alone. Light to import (no numpy):
the console script (``studies._entry``) calls :func:`one_blas_thread` before its imports, so the
compile helper it may start then runs on one thread too.
"""

from __future__ import annotations

import os
import sys

__all__ = ["THREAD_VARIABLES", "one_blas_thread"]

#: Environment variables read by BLAS and OpenMP libraries when they are loaded (``studies._grid``
#: pins the pool workers with the same).
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS",
                    "VECLIB_MAXIMUM_THREADS")


def one_blas_thread() -> bool:
    """Run this process's BLAS and OpenMP libraries, and those of the processes it starts, on one
    thread each, unless the user set a thread count in :data:`THREAD_VARIABLES`; returns whether
    the limit was applied."""
    if any(os.environ.get(name) for name in THREAD_VARIABLES):
        return False  # the user's choice
    for name in THREAD_VARIABLES:
        os.environ[name] = "1"
    if "numpy" in sys.modules or "scipy" in sys.modules:  # loaded before: their pools are started
        from threadpoolctl import threadpool_limits

        threadpool_limits(limits=1)  # a call, not a context: for the process's life
    return True
