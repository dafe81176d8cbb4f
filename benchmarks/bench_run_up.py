"""Speed of a run-up (``studies.run_up``): 500 revolutions of the thesis four-bar (``four_bar_fem4``)
from 50 to 150 rad/s, through the 4x, 3x and 2x resonances of the coupler's first mode (296 rad/s),
started from the nonlinear periodic state at 50 rad/s, with its error estimate (the run at 2 dt) and
the linear steady-state curve: the study's whole wall time, against the target of 15 s.

Baseline, side by side in the same process: ``mechanisms.simulate`` at a constant 100 rad/s (the
ramp's mean speed) over the same number of steps of the same ``dt``, with its own error estimate
(also a run at 2 dt): the ratio says what the ramp, the start orbit, the per-revolution analysis and
the steady curve add to the integration itself. Medians of ``--repeats`` rounds.

Usage: ``python benchmarks/bench_run_up.py [--revolutions 500] [--repeats 1] [--modes auto|full|N]``
(``--modes auto``, the run-up's default: the run-up on the reduced model, its reduction checks included
in its time; the baseline stays the full model's ``simulate``.) Wall and CPU times (``time.process_time``,
this process) are printed with the load average: on a shared machine the CPU time is the steadier.
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import time

import mechanisms
import studies

SPEC = "coupler.deflection@0.5"
TARGET_SECONDS = 15.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--revolutions", type=int, default=500)
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--start", type=float, default=50.0)
    parser.add_argument("--stop", type=float, default=150.0)
    parser.add_argument("--modes", default="auto", help="the run-up's model: auto (default), full or a mode count")
    args = parser.parse_args()
    modes = int(args.modes) if args.modes.isdigit() else args.modes
    problem = studies.MechanismProblem.from_scene("four_bar_fem4")
    # the mean speed of a linear ramp is the mean of its ends: 2 pi n revolutions take this long
    duration = 2.0 * math.pi * args.revolutions / (0.5 * (args.start + args.stop))
    # JIT warm-up outside the clocks: a short run-up on the same path
    studies.run_up(problem, start=args.start, stop=1.05 * args.start, duration=0.1, curve_points=2)
    mechanism = mechanisms.load("four_bar_fem4")
    model = mechanisms.integrated_model(mechanism)
    study_times, baseline_times, study_cpu, baseline_cpu, loads = [], [], [], [], []
    result = None
    for _ in range(args.repeats):
        loads.append(os.getloadavg()[0])
        started, cpu = time.perf_counter(), time.process_time()
        result = studies.run_up(problem, start=args.start, stop=args.stop, duration=duration, modes=modes)
        study_times.append(time.perf_counter() - started)
        study_cpu.append(time.process_time() - cpu)
        started, cpu = time.perf_counter(), time.process_time()
        mechanisms.simulate(model, t_end=duration, dt=result.dt, observables=[SPEC], estimate_error=True)
        baseline_times.append(time.perf_counter() - started)
        baseline_cpu.append(time.process_time() - cpu)
    loads.append(os.getloadavg()[0])
    study, baseline = statistics.median(study_times), statistics.median(baseline_times)
    n_steps = int(round(duration / result.dt))
    print(f"run-up four_bar_fem4 {args.start:g} -> {args.stop:g} rad/s, {result.speed.size} revolutions in "
          f"{duration:.4g} s, dt = {result.dt:.3g} s ({result.dt_reason}), {n_steps} steps + {n_steps // 2} "
          f"for the error estimate")
    print(f"status {result.status}: largest peak to peak {result.largest[SPEC]:.4g} +- "
          f"{result.largest_error[SPEC]:.2g} m at {result.speed_at_largest[SPEC]:.4g} rad/s; start "
          f"{result.start_state}")
    print(f"message: {result.message}")
    if result.reduced_modes:
        print(f"reduced model {result.reduced_modes}: stated reduction error "
              f"{ {k: float(f'{v:.3g}') for k, v in result.reduction_error.items()} }")
    print(f"study (median of {args.repeats}): {study:.2f} s (runs {result.simulation_run_time:.2f} + "
          f"{result.error_run_time:.2f} s, curve {result.curve_run_time:.2f} s, start and setup "
          f"{result.extra['setup_run_time']:.2f} s); target {TARGET_SECONDS:g} s: "
          f"{'met' if study <= TARGET_SECONDS else 'NOT met'}")
    table = {"start": args.start, "stop": args.stop, "duration": duration}
    options = studies.kinds()["run_up"].check("studies.run_up", table, 128)
    guess = studies.estimate(problem, "run_up", options)
    print(f"the resource guard's estimate: {guess.time:.3g} s, {guess.memory / 1e6:.3g} MB ({guess.sizes}); "
          f"measured / estimated = {study / guess.time:.2f}")
    print(f"baseline mechanisms.simulate at constant speed, same steps and error estimate: {baseline:.2f} s; "
          f"study / baseline = {study / baseline:.2f}")
    cpu, cpu_baseline = statistics.median(study_cpu), statistics.median(baseline_cpu)
    print(f"CPU (median of {args.repeats}): study {cpu:.2f} s, baseline {cpu_baseline:.2f} s, study / baseline = "
          f"{cpu / cpu_baseline:.2f}; load average (1 min) {min(loads):.2f}-{max(loads):.2f}")


if __name__ == "__main__":
    main()
