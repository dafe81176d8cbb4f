"""``python -m periodic [--n-steps N] [--extrapolate]``: steady state and Floquet multipliers of the demo
system (``periodic.demo_system``), printed; writes no files (``flexvib demo`` writes them)."""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from ._demo import demo_system
from ._shooting import steady_state


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m periodic", description=__doc__.splitlines()[0])
    parser.add_argument("--n-steps", type=int, default=512, help="Newmark steps per period (even, default 512)")
    parser.add_argument("--extrapolate", action="store_true", help="Richardson-extrapolate N and N/2 (order 4)")
    args = parser.parse_args(argv)
    if args.n_steps < 4 or args.n_steps % 2:
        parser.error(f"--n-steps: expected an even integer >= 4, got {args.n_steps}")
    start = time.perf_counter()
    system = demo_system(args.n_steps)
    result = steady_state(system, extrapolate=args.extrapolate)
    elapsed = time.perf_counter() - start
    print(f"periodic demo: 2-DOF Mathieu-type system, T = {system.period:g} s, N = {args.n_steps} steps")
    print(f"  max |x| = {np.abs(result.x).max(axis=0)} m, error estimate {result.error_estimate:.2e} m")
    print(f"  Floquet multipliers |mu| = {np.abs(result.multipliers).round(6)}, stable: {result.is_stable}")
    print(f"  status: {result.status}; solve {result.run_time * 1e3:.1f} ms, total {elapsed:.2f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
