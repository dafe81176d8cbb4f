"""When do more BLAS threads help? The dense blocks the tool hands to BLAS and LAPACK, timed with one
thread and with one per core (threadpoolctl), alternately in this process, medians of repeats.

The blocks, each at sizes n from the models' range upward:

- ``dgemm``: the Newmark LAPACK path's product of the inverse effective matrix with the 2n + 1 columns
  of the monodromy march, (n, n) @ (n, 2n + 1), once per step (``periodic._newmark``);
- ``lu``: LAPACK's dgetrf + dgetri of an (n, n) matrix (the same path, once per step);
- ``eig``: the eigenvalues of a (2n, 2n) monodromy matrix (``periodic.floquet``, once per point).

``flexvib`` runs every process with one BLAS thread (``studies.cli``, ``studies.process_pool``): more
threads would pay only from the size where the ``threads/1`` ratio drops below 1 on the machine at hand,
and on a machine shared with other work (every core busy) the extra threads spin and wait. Run:

    .venv/bin/python benchmarks/bench_blas_threads.py [--sizes 50 100 200 400 800] [--repeats 5]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np
import scipy.linalg
from threadpoolctl import ThreadpoolController


def _block(kind: str, n: int, rng: np.random.Generator):
    """A callable running one block of ``kind`` at size n, and its inputs made once."""
    if kind == "dgemm":
        a, b = rng.standard_normal((n, n)), rng.standard_normal((n, 2 * n + 1))
        out = np.empty((n, 2 * n + 1))
        return lambda: np.dot(a, b, out)
    if kind == "lu":
        a = rng.standard_normal((n, n)) + n * np.eye(n)
        return lambda: scipy.linalg.inv(a, overwrite_a=False, check_finite=False)
    a = rng.standard_normal((2 * n, 2 * n))
    return lambda: scipy.linalg.eigvals(a, check_finite=False)


def _median_time(run, repeats: int, budget: float = 0.2) -> float:
    """Median over ``repeats`` of the time of one call (s), each sample averaging enough calls to
    last about ``budget`` s."""
    start = time.perf_counter()
    run()
    once = max(time.perf_counter() - start, 1e-6)
    calls = max(1, int(budget / once))
    samples = []
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(calls):
            run()
        samples.append((time.perf_counter() - start) / calls)
    return statistics.median(samples)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[25, 50, 100, 200, 400, 800])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=os.cpu_count() or 2)
    args = parser.parse_args()
    controller = ThreadpoolController()
    rng = np.random.default_rng(1)
    print(f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}; 1 thread against {args.threads}")
    print(f"{'block':6s} {'n':>5s} {'1 thread (ms)':>14s} {f'{args.threads} threads (ms)':>15s} "
          f"{'ratio':>6s}")
    for kind in ("dgemm", "lu", "eig"):
        for n in args.sizes:
            run = _block(kind, n, rng)
            times = {1: [], args.threads: []}
            for _ in range(3):  # alternately: both see the same load
                for threads in times:
                    with controller.limit(limits=threads, user_api="blas"):
                        times[threads].append(_median_time(run, args.repeats))
            one, many = statistics.median(times[1]), statistics.median(times[args.threads])
            print(f"{kind:6s} {n:5d} {1e3 * one:14.3f} {1e3 * many:15.3f} {many / one:6.2f}", flush=True)


if __name__ == "__main__":
    main()
