"""Warm speed of the hot kernels, this code against a baseline, in alternate processes: a change
that makes the first run compile less (``profile_compile.py``) must not make every later run slower.

Timed (four_bar_fem4, 4 Hermite coupler elements; four_bar_ritz), each the minimum of ``--repeats``
calls after a warm-up, in a fresh process per code and round:

- ``Model.linear_terms_along`` and ``Model.inertia_residual_along`` along 256 samples;
- ``Model.constraint_terms_along`` (with gamma and Phi) along 256 samples;
- the per-sample methods the generalized-alpha step calls (mass matrix, forces, force Jacobians,
  constraint Jacobian), 200 calls each;
- ``mechanisms.nominal_motion`` (the continuation kernel) and ``periodic.steady_state`` of the
  linearised system, N = 256.

Run (the baseline a checkout, ``git archive 2b6439a | tar -x -C /tmp/base``):

    .venv/bin/python benchmarks/bench_kernels_warm.py --baseline /tmp/base [--rounds 4] [--repeats 9]

Prints each quantity's median over the rounds (ms) and the median of the rounds' ratios.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent
N_SAMPLES = 256


def best(func, repeats: int) -> float:
    """The shortest of ``repeats`` calls (s)."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        func()
        times.append(time.perf_counter() - start)
    return min(times)


def measure(repeats: int) -> dict[str, float]:
    """In this process (the code on ``sys.path``): the timings (ms)."""
    import numpy as np

    import linearize
    import mechanisms
    import periodic

    found = {}
    for scene in ("four_bar_fem4", "four_bar_ritz"):
        mechanism = mechanisms.load(scene)
        model = mechanisms.assemble(mechanism)
        motion = mechanisms.nominal_motion(mechanism, n_steps=N_SAMPLES)
        t = np.ascontiguousarray(motion.t[:N_SAMPLES])
        s, sdot, sddot = (np.ascontiguousarray(a[:N_SAMPLES]) for a in (motion.s, motion.sdot, motion.sddot))
        lam = np.ascontiguousarray(motion.lam[:N_SAMPLES])
        lin = linearize.about(mechanism, n_steps=N_SAMPLES)
        cases = {
            "linear_terms_along": lambda: model.linear_terms_along(t, s, sdot, sddot, lam),
            "inertia_residual_along": lambda: model.inertia_residual_along(t, s, sdot, sddot),
            "constraint_terms_along": lambda: model.constraint_terms_along(t, s, sdot, values=True),
            "per-sample methods x200": lambda: [
                (model.mass_matrix(s[k]), model.forces(s[k], sdot[k], t[k]),
                 model.force_jacobians(s[k], sdot[k], t[k]), model.constraint_jacobian(s[k], t[k]))
                for k in range(200)],
            "nominal_motion": lambda: mechanisms.nominal_motion(mechanism, n_steps=N_SAMPLES),
            "steady_state": lambda: periodic.steady_state(lin.system),
        }
        for name, case in cases.items():
            case()  # compile or load, and warm the caches
            found[f"{scene}: {name}"] = best(case, repeats) * 1e3
    return found


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", type=Path, help="source folder of the code to compare with")
    parser.add_argument("--rounds", type=int, default=4)
    parser.add_argument("--repeats", type=int, default=9)
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(measure(args.repeats)))
        return
    sources = {"this": HERE} | ({"baseline": args.baseline.resolve()} if args.baseline else {})
    rounds: dict[str, list[dict[str, float]]] = {name: [] for name in sources}
    print(f"load average {os.getloadavg()[0]:.1f} at the start", flush=True)
    for k in range(args.rounds):
        for name, source in sources.items():   # alternately: both see the same load
            env = dict(os.environ, PYTHONPATH=str(source), OPENBLAS_NUM_THREADS="1")
            done = subprocess.run([sys.executable, __file__, "--child", "--repeats", str(args.repeats)],
                                  env=env, capture_output=True, text=True, cwd=source, check=True)
            rounds[name].append(json.loads(done.stdout.strip().splitlines()[-1]))
        print(f"round {k + 1} done (load average {os.getloadavg()[0]:.1f})", flush=True)
    keys = list(rounds["this"][0])
    for key in keys:
        line = f"  {key:52s} this {statistics.median(r[key] for r in rounds['this']):8.2f} ms"
        if args.baseline:
            ratios = [a[key] / b[key] for a, b in zip(rounds["this"], rounds["baseline"])]
            line += (f"  baseline {statistics.median(r[key] for r in rounds['baseline']):8.2f} ms  ratio "
                     f"{statistics.median(ratios):.2f} ({', '.join(f'{r:.2f}' for r in ratios)})")
        print(line)


if __name__ == "__main__":
    main()
