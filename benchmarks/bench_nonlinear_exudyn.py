"""Nonlinear periodic state of the six-bar (8 elements per elastic link, 100 rad/s): flexvib's shooting
against the Exudyn transient at matched accuracy (issue 24), side by side in one process.

- flexvib: ``studies.nonlinear_steady_state`` with its defaults (256 steps, the links reduced by the
  reduction check, ``modes="auto"``), and the full element models (``modes="full"``); the wall time of
  the call (the reduction check, the linear start, the shooting on N, N/2, N/4 with the multipliers
  and the error estimates; JIT compiled before, by a warm-up call).
- Exudyn (``pip install exudyn``, not a flexvib dependency): the same mechanism, the crank, the plate
  and the output rocker as ``ObjectRigidBody2D``, links 2 and 4 as 8 ``ObjectANCFCable2D`` elements each
  (axial and bending strain, stiffness-proportional damping, the scene's Rayleigh beta), revolute
  joints, the crank speed imposed at velocity level; generalised-alpha (spectral radius 0.8) with
  ``--exudyn-steps`` (720) steps per revolution from the nominal rigid motion. Its periodic answer is
  the last revolution of a ``--long`` (60) revolution run; the timed run stops at the fewest
  revolutions whose last one is within ``--accuracy`` (0.05 %) of that answer's peak-to-peak, for
  every observable.
- Without Exudyn the baseline is flexvib's own transient (``mechanisms.simulate`` from the rigid
  start, 256 steps per revolution, the same stopping rule against flexvib's orbit), and the issue's
  Exudyn figure (3.2 s) is printed as given.

The machine is shared: medians of ``--repeats`` interleaved runs; compare ratios, not seconds.
``--modes auto`` times the default route only (the full element models take most of a run).

``--sweep``: the issue's second target instead, ``studies.nonlinear_sweep`` of the same six-bar over
75 -> 125 rad/s (``step = 1``, N = 128, ``modes = "auto"``), after a warm-up sweep: wall and CPU time,
orbits, status, and the same sweep's orbits against single ``nonlinear_steady_state`` orbits at three
speeds (the branch's peak-to-peak within both error estimates).

Usage: ``.venv/bin/python benchmarks/bench_nonlinear_exudyn.py [--repeats 3] [--quick] [--sweep]``
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import numpy as np

import mechanisms
import studies

SCENE = "six_bar"
ELEMENTS = 8
LINKS = ("link2", "link4")
SPECS = tuple(f"{name}.deflection@0.5" for name in LINKS)
PATHS = tuple(f"links.{name}.discretisation.n_elements" for name in LINKS)
#: The issue's figure of the Exudyn run (one run on this machine, session 6).
ISSUE_EXUDYN_SECONDS = 3.2


def problem_and_values():
    problem = studies.MechanismProblem.from_scene(SCENE, parameter_paths=PATHS)
    return problem, {"speed": 100.0, **{path: ELEMENTS for path in PATHS}}


def flexvib(problem, values, modes):
    """(wall s, result) of the nonlinear periodic state; ``modes`` "auto", "full", "auto@tol": the
    default model with the error levels converged to ``tol`` (``LEVEL_ACCURACY = None``, the shooting
    of session 7: the baseline of session 8's levels, side by side), or "auto@s8": the shooting of
    session 8 (Newton throughout on N, the error levels' orbits their settled iterate plus its
    correction, evaluated once more, the mesh term's base level solved again:
    ``REUSE_FIRST_MONODROMY = SETTLE_ON_ITERATE = REUSE_LINEAR_STATE = False``), the baseline of
    session 9's."""
    from studies._kinds import nonlinear_steady_state as steady_module

    # (getattr with a default: the script also times an older checkout's "auto", which lacks them)
    saved = {name: getattr(steady_module, name, None)
             for name in ("LEVEL_ACCURACY", "REUSE_FIRST_MONODROMY", "SETTLE_ON_ITERATE", "REUSE_LINEAR_STATE")}
    modes, _, before = modes.partition("@")
    if before == "tol":
        steady_module.LEVEL_ACCURACY = None
    if before in ("tol", "s8"):
        steady_module.REUSE_FIRST_MONODROMY = steady_module.SETTLE_ON_ITERATE = False
        steady_module.REUSE_LINEAR_STATE = False
    try:
        started = time.perf_counter()
        result = studies.nonlinear_steady_state(problem, values, modes=modes)
        return time.perf_counter() - started, result
    finally:
        for name, value in saved.items():
            if value is not None:
                setattr(steady_module, name, value)


def exudyn_run(mechanism, n_revolutions: int, steps: int):
    """Exudyn from the nominal rigid motion: (midspan deflections {spec: (k,)} relative to each link's
    chord, sampled at every step, m; run time s, its CPU time s)."""
    import exudyn as exu
    from exudyn.itemInterface import (
        MarkerBodyPosition,
        MarkerNodeCoordinate,
        NodePoint2DSlope1,
        NodePointGround,
        NodeRigidBody2D,
        ObjectANCFCable2D,
        ObjectConnectorCoordinate,
        ObjectGround,
        ObjectJointRevolute2D,
        ObjectRigidBody2D,
        SensorNode,
    )

    nominal = mechanisms.nominal_motion(mechanism, n_steps=64)
    labels = list(nominal.model.coord_labels)
    s0, v0 = nominal.s[0], nominal.sdot[0]

    def frame(name):
        i = labels.index(f"{name}.x")
        return s0[i:i + 3], v0[i:i + 3]

    SC = exu.SystemContainer()
    mbs = SC.AddSystem()
    ground = mbs.AddObject(ObjectGround(referencePosition=[0, 0, 0]))
    markers = {}     # (link, point name) -> marker

    def rotate(theta, p):
        c, s = math.cos(theta), math.sin(theta)
        return np.array([c * p[0] - s * p[1], s * p[0] + c * p[1]])

    def rigid(link, named):
        (x, y, theta), (vx, vy, omega) = frame(link.name)
        centroid = np.array(link.centroid if link.centroid is not None else (0.5 * link.length, 0.0))
        arm = rotate(theta, centroid)
        node = mbs.AddNode(NodeRigidBody2D(referenceCoordinates=[x + arm[0], y + arm[1], theta],
                                           initialVelocities=[vx - omega * arm[1], vy + omega * arm[0], omega]))
        body = mbs.AddObject(ObjectRigidBody2D(nodeNumber=node, mass=link.mass, inertia=link.inertia))
        points = {"start": (0.0, 0.0), "end": (link.length, 0.0), **dict(link.points or {})}
        for name in named:
            local = np.array(points[name]) - centroid
            markers[link.name, name] = mbs.AddMarker(MarkerBodyPosition(bodyNumber=body,
                                                                        localPosition=[*local, 0.0]))
        return node

    sensors = {}

    def elastic(link):
        (x, y, theta), (vx, vy, omega) = frame(link.name)
        e = np.array([math.cos(theta), math.sin(theta)])
        normal = np.array([-e[1], e[0]])
        element = link.length / ELEMENTS
        nodes = []
        for k in range(ELEMENTS + 1):
            xi = k * element
            position = np.array([x, y]) + xi * e
            velocity = np.array([vx, vy]) + omega * xi * normal
            nodes.append(mbs.AddNode(NodePoint2DSlope1(referenceCoordinates=[*position, *e],
                                                       initialVelocities=[*velocity, *(omega * normal)])))
        EA, EI = link.youngs_modulus * link.area, link.youngs_modulus * link.second_moment
        beta = link.damping.beta
        cables = [mbs.AddObject(ObjectANCFCable2D(
            nodeNumbers=[nodes[k], nodes[k + 1]], length=element, massPerLength=link.density * link.area,
            bendingStiffness=EI, axialStiffness=EA, bendingDamping=beta * EI, axialDamping=beta * EA))
            for k in range(ELEMENTS)]
        markers[link.name, "start"] = mbs.AddMarker(MarkerBodyPosition(bodyNumber=cables[0],
                                                                       localPosition=[0, 0, 0]))
        markers[link.name, "end"] = mbs.AddMarker(MarkerBodyPosition(bodyNumber=cables[-1],
                                                                     localPosition=[element, 0, 0]))
        sensors[link.name] = [mbs.AddSensor(SensorNode(nodeNumber=nodes[k], storeInternal=True,
                                                       outputVariableType=exu.OutputVariableType.Position))
                              for k in (0, ELEMENTS // 2, ELEMENTS)]

    link = mechanism.link
    crank = rigid(link("crank"), ("start", "end"))
    rigid(link("plate"), ("start", "end", "C"))
    rigid(link("output"), ("start", "end"))
    for name in LINKS:
        elastic(link(name))

    def ground_point(x, y):
        return mbs.AddMarker(MarkerBodyPosition(bodyNumber=ground, localPosition=[x, y, 0]))

    pairs = [(ground_point(0.0, 0.0), markers["crank", "start"]),
             (markers["crank", "end"], markers["link2", "start"]),
             (markers["link2", "end"], markers["plate", "end"]),
             (ground_point(0.30, 0.0), markers["plate", "start"]),
             (markers["plate", "C"], markers["link4", "start"]),
             (markers["link4", "end"], markers["output", "end"]),
             (ground_point(0.60, 0.0), markers["output", "start"])]
    for a, b in pairs:
        mbs.AddObject(ObjectJointRevolute2D(markerNumbers=[a, b]))
    speed = mechanism.drives[0].rate
    fixed = mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=mbs.AddNode(NodePointGround()), coordinate=0))
    crank_angle = mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=crank, coordinate=2))
    mbs.AddObject(ObjectConnectorCoordinate(markerNumbers=[fixed, crank_angle], offset=speed, velocityLevel=True))
    mbs.Assemble()

    period = 2.0 * math.pi / abs(speed)
    settings = exu.SimulationSettings()
    settings.timeIntegration.numberOfSteps = n_revolutions * steps
    settings.timeIntegration.endTime = n_revolutions * period
    settings.timeIntegration.generalizedAlpha.spectralRadius = 0.8
    settings.timeIntegration.verboseMode = 0
    settings.solutionSettings.writeSolutionToFile = False
    settings.solutionSettings.sensorsWritePeriod = period / steps
    started, cpu = time.perf_counter(), time.process_time()
    mbs.SolveDynamic(settings)
    run_time, cpu = time.perf_counter() - started, time.process_time() - cpu
    deflections = {}
    for name, spec in zip(LINKS, SPECS):
        a, m, b = (mbs.GetSensorStoredData(s) for s in sensors[name])
        chord = b[:, 1:3] - a[:, 1:3]
        chord /= np.linalg.norm(chord, axis=1)[:, None]
        offset = m[:, 1:3] - a[:, 1:3]
        deflections[spec] = chord[:, 0] * offset[:, 1] - chord[:, 1] * offset[:, 0]
    return deflections, run_time, cpu


def revolutions_to(series: dict, steps: int, limit: dict, accuracy: float) -> int | None:
    """The fewest revolutions k whose k-th is within ``accuracy`` of ``limit``'s peak-to-peak for every
    spec (``series`` sampled ``steps`` per revolution from t = 0, ``limit`` one revolution)."""
    n_revolutions = (min(v.size for v in series.values()) - 1) // steps
    for k in range(1, n_revolutions + 1):
        if all(np.abs(series[spec][(k - 1) * steps:k * steps + 1][:limit[spec].size] - limit[spec]).max()
               <= accuracy * np.ptp(limit[spec]) for spec in limit):
            return k
    return None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--accuracy", type=float, default=5e-4)
    parser.add_argument("--exudyn-steps", type=int, default=720)
    parser.add_argument("--long", type=int, default=60, help="revolutions of the runs giving the limits")
    parser.add_argument("--quick", action="store_true", help="one repeat")
    parser.add_argument("--modes", nargs="+", default=["auto", "auto@tol", "full"],
                        choices=["auto", "auto@s8", "auto@tol", "full"])
    parser.add_argument("--sweep", action="store_true", help="time the 50-speed nonlinear sweep instead")
    args = parser.parse_args()
    repeats = 1 if args.quick else args.repeats
    problem, values = problem_and_values()
    mechanism = problem.mechanism({path: ELEMENTS for path in PATHS})
    # JIT compilation (the fused step too, as the studies' warm-up compiles it) and the model caches
    with mechanisms.fused_step(True):
        for modes in {modes.split("@")[0] for modes in args.modes}:
            studies.nonlinear_steady_state(problem, values, n_steps=32, max_iterations=1, modes=modes)
    if args.sweep:
        return sweep(problem, values, repeats)
    try:
        import exudyn  # noqa: F401
        have_exudyn = True
    except ImportError:
        have_exudyn = False

    _, orbit = flexvib(problem, values, "full" if "full" in args.modes else "auto")
    if have_exudyn:
        steps = args.exudyn_steps
        long_run, _, _ = exudyn_run(mechanism, args.long, steps)
        limit = {spec: v[-steps - 1:] for spec, v in long_run.items()}
        baseline = "Exudyn"
    else:
        steps = orbit.n_steps
        run = mechanisms.simulate(mechanism, n_periods=args.long, steps_per_period=steps, estimate_error=False,
                                  observables=list(SPECS))
        long_run = {spec: np.asarray(run.observables[spec]) for spec in SPECS}
        limit = {spec: np.asarray(orbit.response[spec]) for spec in SPECS}
        baseline = "flexvib transient"
    revolutions = revolutions_to(long_run, steps, limit, args.accuracy)
    if revolutions is None:
        raise SystemExit(f"{baseline} did not settle within {args.accuracy:g} in {args.long} revolutions")

    # wall and CPU time (``time.process_time``: less sensitive to the shared machine's load; every
    # route here runs on one thread)
    times: dict[str, list[float]] = {**{modes: [] for modes in args.modes}, "baseline": []}
    cpus: dict[str, list[float]] = {key: [] for key in times}
    results = {}
    for repeat in range(repeats):
        # the routes' order alternates between repeats (no route always runs after another)
        for modes in (args.modes if repeat % 2 == 0 else args.modes[::-1]):
            cpu = time.process_time()
            seconds, results[modes] = flexvib(problem, values, modes)
            times[modes].append(seconds)
            cpus[modes].append(time.process_time() - cpu)
        if have_exudyn:
            _, seconds, cpu = exudyn_run(mechanism, revolutions, steps)
            times["baseline"].append(seconds)
            cpus["baseline"].append(cpu)
        else:
            started, cpu = time.perf_counter(), time.process_time()
            mechanisms.simulate(mechanism, n_periods=revolutions, steps_per_period=steps, estimate_error=False,
                                observables=list(SPECS))
            times["baseline"].append(time.perf_counter() - started)
            cpus["baseline"].append(time.process_time() - cpu)
    median = {key: statistics.median(value) for key, value in times.items()}
    cpu_median = {key: statistics.median(value) for key, value in cpus.items()}
    print(f"{SCENE}, {ELEMENTS} elements per elastic link, 100 rad/s; accuracy {args.accuracy:g} of the "
          f"peak-to-peak; medians of {repeats} interleaved runs (shared machine)")
    print(f"{baseline}: {steps} steps per revolution x {revolutions} revolutions: {median['baseline']:.3f} s "
          f"(CPU {cpu_median['baseline']:.3f} s)"
          + ("" if have_exudyn else f" (Exudyn not installed; the issue's Exudyn figure: {ISSUE_EXUDYN_SECONDS} s)"))
    for modes in args.modes:
        result = results[modes]
        words = ", ".join(
            f"{spec} p2p {result.peak_to_peak[spec] * 1e3:.4f} mm +- {result.response_error[spec] * 1e3:.2g} "
            f"(time step) +- {result.reduction_error.get(spec, 0.0) * 1e3:.2g} (reduction) mm"
            for spec in SPECS)
        print(f"flexvib nonlinear_steady_state modes={modes} {result.reduced_modes or ''}: "
              f"{median[modes]:.3f} s (CPU {cpu_median[modes]:.3f} s), {result.status}, {result.map_calls} "
              f"period maps; {words}; ratio {baseline} / flexvib {median['baseline'] / median[modes]:.1f} "
              f"(CPU {cpu_median['baseline'] / cpu_median[modes]:.1f})")
    for spec in SPECS:
        words = ", ".join(f"flexvib {modes} / {baseline} {results[modes].peak_to_peak[spec] / np.ptp(limit[spec]):.4f}"
                          for modes in args.modes)
        print(f"{spec}: {baseline} limit p2p {np.ptp(limit[spec]) * 1e3:.4f} mm, {words}")


def sweep(problem, values, repeats: int) -> None:
    """The 50-speed nonlinear sweep (75 -> 125 rad/s, step 1, N = 128), after a warm-up sweep."""
    options = {"start": 75.0, "stop": 125.0, "values": values, "n_steps": 128, "step": 1.0}
    studies.nonlinear_sweep(problem, **dict(options, stop=76.0))
    walls, cpus = [], []
    for _ in range(repeats):
        started, cpu = time.perf_counter(), time.process_time()
        result = studies.nonlinear_sweep(problem, **options)
        walls.append(time.perf_counter() - started)
        cpus.append(time.process_time() - cpu)
    print(f"nonlinear_sweep {SCENE} 75 -> 125 rad/s, step 1, N = 128, modes auto: {result.status}, "
          f"{result.values.size} orbits, wall {statistics.median(walls):.2f} s, CPU {statistics.median(cpus):.2f} s "
          f"(median of {repeats}; {statistics.median(walls) / result.values.size:.3f} s per orbit)")
    print(f"  {result.message[:240]}")
    # the branch against single orbits at three of its speeds
    for k in (0, result.values.size // 2, result.values.size - 1):
        speed = float(result.values[k])
        single = studies.nonlinear_steady_state(problem, dict(values, speed=speed), n_steps=128)
        for spec in SPECS:
            difference = abs(result.peak_to_peak[spec][k] - single.peak_to_peak[spec])
            bar = result.peak_to_peak_error[spec][k] + single.peak_to_peak_error[spec]
            print(f"  {speed:.4f} rad/s {spec}: branch {result.peak_to_peak[spec][k] * 1e3:.4f} mm, single orbit "
                  f"{single.peak_to_peak[spec] * 1e3:.4f} mm, difference {difference * 1e3:.2g} mm "
                  f"(error bars {bar * 1e3:.2g} mm)")


if __name__ == "__main__":
    main()
