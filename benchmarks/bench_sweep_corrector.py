"""The 50-speed nonlinear sweep's corrector (issue 24): CPU time and the exact period counts.

``studies.nonlinear_sweep`` of six_bar (8 elements per elastic link, 75 -> 125 rad/s, ``step = 1``,
N = 128, ``modes = "auto"``), after a warm-up sweep (75 -> 76 rad/s), as
``bench_nonlinear_exudyn.py --sweep --quick``. Prints the CPU (``time.process_time``) and wall time
of each sweep, and the periods run by ``mechanisms.PeriodMap`` per level (N and N/2 integrations,
and their tangents: a period "with its monodromy" is one of each) counted by wrapping the module's
kernels (exact, not load-dependent). ``--save FILE.npz`` writes the branch (speeds, statuses,
states, spectral radii, peak-to-peaks and their error bars) for ``--compare A.npz B.npz``, which
compares two runs at the speeds both visit.

Run it against another commit in alternating processes, e.g. with ``git archive <commit> | tar -x
-C /tmp/base`` and ``PYTHONPATH=/tmp/base``: the script imports whichever ``studies`` comes first.

Usage: ``OMP_NUM_THREADS=1 .venv/bin/python benchmarks/bench_sweep_corrector.py [--repeats 1]
[--save out/sweep.npz]`` or ``... --compare A.npz B.npz``
"""

from __future__ import annotations

import argparse
import collections
import statistics
import time

import numpy as np

SCENE = "six_bar"
PATHS = tuple(f"links.{name}.discretisation.n_elements" for name in ("link2", "link4"))
SPECS = ("link2.deflection@0.5", "link4.deflection@0.5")


class _Counts:
    """Wraps ``mechanisms._orbit._integrate`` and ``_propagate_tangent``: periods and tangents run, by
    the number of steps of the period (N and N/2)."""

    def __init__(self):
        import mechanisms._orbit as orbit_module

        self.periods, self.tangents = collections.Counter(), collections.Counter()
        integrate, propagate = orbit_module._integrate, orbit_module._propagate_tangent

        def counted_integrate(model, s0, sdot0, t0, h, n_steps, *args, **kwargs):
            self.periods[int(n_steps)] += 1
            return integrate(model, s0, sdot0, t0, h, n_steps, *args, **kwargs)

        def counted_propagate(model, raw, *args, **kwargs):
            self.tangents[int(raw["s"].shape[0] - 1)] += 1
            return propagate(model, raw, *args, **kwargs)

        orbit_module._integrate, orbit_module._propagate_tangent = counted_integrate, counted_propagate

    def reset(self):
        self.periods.clear()
        self.tangents.clear()


def _sweep(repeats: int, save: str | None) -> None:
    import periodic
    import studies

    counts = _Counts()
    branches = []
    follow = periodic.continue_orbits

    def kept_branch(*args, **kwargs):
        branches.append(follow(*args, **kwargs))
        return branches[-1]

    periodic.continue_orbits = kept_branch    # the study calls it by the module's attribute
    problem = studies.MechanismProblem.from_scene(SCENE, parameter_paths=PATHS)
    values = {"speed": 100.0, **{path: 8 for path in PATHS}}
    options = {"start": 75.0, "stop": 125.0, "values": values, "n_steps": 128, "step": 1.0}
    studies.nonlinear_sweep(problem, **dict(options, stop=76.0))    # warm-up
    cpus, walls = [], []
    for _ in range(repeats):
        counts.reset()
        started, cpu = time.perf_counter(), time.process_time()
        result = studies.nonlinear_sweep(problem, **options)
        walls.append(time.perf_counter() - started)
        cpus.append(time.process_time() - cpu)
        orbits = result.values.size
        words = ", ".join(f"N = {n}: {counts.periods[n]} periods, {counts.tangents[n]} tangents"
                          for n in (128, 64))
        print(f"sweep: {result.status}, {orbits} orbits, CPU {cpus[-1]:.2f} s, wall {walls[-1]:.2f} s; {words}; "
              f"per orbit N {counts.periods[128] / orbits:.2f} / {counts.tangents[128] / orbits:.2f}, "
              f"N/2 {counts.periods[64] / orbits:.2f} / {counts.tangents[64] / orbits:.2f}", flush=True)
    print(f"CPU median {statistics.median(cpus):.2f} s, wall median {statistics.median(walls):.2f} s "
          f"(of {repeats})")
    if save:
        branch = branches[-1]
        np.savez(save, speeds=result.values, statuses=np.array(result.point_status),
                 states=branch.states, radii=np.array([orbit.spectral_radius for orbit in branch.orbits]),
                 errors=np.array([orbit.state_error for orbit in branch.orbits]),
                 stable=branch.stable,
                 **{f"p2p_{k}": np.asarray(result.peak_to_peak[spec]) for k, spec in enumerate(SPECS)},
                 **{f"p2p_error_{k}": np.asarray(result.peak_to_peak_error[spec]) for k, spec in enumerate(SPECS)})


def _compare(first: str, second: str) -> None:
    a, b = np.load(first), np.load(second)
    shared = np.intersect1d(a["speeds"], b["speeds"])
    ia = np.searchsorted(a["speeds"], shared)
    ib = np.searchsorted(b["speeds"], shared)
    print(f"{a['speeds'].size} and {b['speeds'].size} orbits, {shared.size} shared speeds")
    print(f"statuses equal: {bool(np.all(a['statuses'][ia] == b['statuses'][ib]))} "
          f"({sorted(set(a['statuses'][ia]))}); stable equal: {bool(np.all(a['stable'][ia] == b['stable'][ib]))}")
    radius = np.abs(a["radii"][ia] - b["radii"][ib]).max()
    print(f"spectral radii: max difference {radius:.2g}")
    state = np.abs(a["states"][ia] - b["states"][ib]).max(axis=1)
    print(f"states: max difference {state.max():.2g}, against the smaller error estimate "
          f"{(state / np.minimum(a['errors'][ia], b['errors'][ib])).max():.2g} of it")
    print(f"error estimates: max relative difference {np.abs(a['errors'][ia] / b['errors'][ib] - 1).max():.2g}")
    for k, spec in enumerate(SPECS):
        difference = np.abs(a[f"p2p_{k}"][ia] - b[f"p2p_{k}"][ib])
        bars = np.minimum(a[f"p2p_error_{k}"][ia], b[f"p2p_error_{k}"][ib])
        relative = np.abs(a[f"p2p_error_{k}"][ia] / b[f"p2p_error_{k}"][ib] - 1).max()
        print(f"{spec}: peak-to-peak max difference {difference.max() * 1e3:.2g} mm, at most "
              f"{(difference / bars).max():.2g} of the smaller error bar ({bars.min() * 1e3:.2g}-"
              f"{bars.max() * 1e3:.2g} mm); error bars within {relative:.2g} of each other")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--save", default=None)
    parser.add_argument("--compare", nargs=2, default=None)
    args = parser.parse_args()
    if args.compare:
        _compare(*args.compare)
    else:
        _sweep(args.repeats, args.save)


if __name__ == "__main__":
    main()
