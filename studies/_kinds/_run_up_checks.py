"""The run-up's verdicts along the ramp (``studies.run_up``): the linear-range measures of the steady
states (``linearize.LinkRange``: deflection over length and over section height, slope, bending
stress, compression over the Euler load, and an unstiffened link's model form) per revolution of
the run, the stability of the frozen periodic states the ramp passes, and the released drives of a
coast."""

from __future__ import annotations

from typing import Any

import numpy as np

import linearize
import mechanisms
import periodic

from .._toolkit import StudiesError
from ._run_up_revolutions import analysed

#: Richardson factor of the order-2 generalized-alpha run: error ~ (o_h - o_2h) / 3.
ERROR_FACTOR = 1.0 / 3.0
#: A per-revolution peak-to-peak whose estimated error exceeds this fraction of the largest one is
#: ``inaccurate`` (the rule of the steady states, docs/methods.md).
MAX_RELATIVE_ERROR = periodic.MAX_RELATIVE_ERROR
#: Below this error estimate, as a fraction of the largest peak to peak (a tenth of the
#: ``inaccurate`` threshold), the run at 4 dt that checks the estimate's asymptotic range is left
#: out: an estimate out of its range was seen 4x below the true error (docs/methods.md), and even 10x
#: below would leave the error under the threshold.
SKIP_CHECK_BELOW = 0.1 * MAX_RELATIVE_ERROR
#: The measures per elastic link and revolution (the fields of ``linearize.LinkRange``).
MEASURES = ("peak_deflection_over_length", "peak_deflection_over_height", "peak_slope",
            "peak_compression_over_euler", "peak_stress_over_yield")
#: Above this ratio of a revolution's angular acceleration to its squared speed, the axial load of
#: the constant-speed nominal motion (which the compression measure reads) misses a share of that
#: order: said in the message.
ACCELERATION_SHARE = 0.1


class AxialLoad:
    """The nominal compression of each elastic link at any constant speed ``w``: the rigid inverse
    dynamics of a motion that is a function of the crank angle is ``N = N0 + w^2 N2`` at each crank
    angle (gravity and the static multipliers in ``N0``, the velocity-squared terms in ``N2``), fixed
    here from the linearisations at two speeds on the same grid of crank angles."""

    def __init__(self, probes_a, speed_a, probes_b, speed_b):
        self.parts = {}
        for a, b in zip(probes_a, probes_b):
            if a.axial is None or b.axial is None:
                self.parts[a.link.name] = None
                continue
            quadratic = (b.axial - a.axial) / (speed_b**2 - speed_a**2)
            self.parts[a.link.name] = (a.axial - speed_a**2 * quadratic, quadratic)

    def compression_over_euler(self, link, speeds) -> np.ndarray:
        """(n,) the peak compression over ``link``'s Euler load at each of ``speeds`` (n,) rad/s (NaN
        where the load cannot be computed)."""
        parts = self.parts.get(link.name)
        speeds = np.asarray(speeds, dtype=float)
        if parts is None:
            return np.full(speeds.shape, np.nan)
        static, quadratic = parts
        least = np.array([float((static + w * w * quadratic).min()) for w in speeds.ravel()])
        return np.maximum(0.0, -least).reshape(speeds.shape) / link.euler_load


def _revolution_maxima(series: np.ndarray, t: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """(n_parts,) the largest of ``series`` (n_t,) over each of the parts ``bounds[k] <= t <=
    bounds[k + 1]`` (s); the samples at a part's ends count for both neighbours."""
    first = np.searchsorted(t, bounds[:-1], side="left")
    last = np.searchsorted(t, bounds[1:], side="right")
    return np.array([series[max(i - 1, 0):max(j + 1, i + 1)].max() for i, j in zip(first, last)])


def along_ramp(lin, axial: AxialLoad, analysis) -> tuple[dict[str, np.ndarray], np.ndarray, list, str]:
    """The linear-range measures of the run per revolution and of what follows the last one:
    ``({"<link>.<measure>": (n_rev + 1,)}, status (n_rev + 1,), [(status, message)], note)``; the
    last entry is the tail after the last whole revolution (NaN without one). Deflection, slope and
    stress from the run's elastic coordinates over the revolution; the compression from the
    nominal axial load at the slowest and the fastest speed of the revolution (the larger: the load
    is convex in the squared speed), which leaves out the ramp's angular acceleration (said in
    ``note`` where it passes ``ACCELERATION_SHARE`` of the squared speed)."""
    run, phase = analysis.run, analysis.phase
    t = run.t
    bounds = np.append(analysis.times, t[-1]) if analysis.speed.size else np.array([t[0], t[-1]])
    if not analysis.speed.size:
        bounds = np.array([t[0], t[0], t[-1]])   # no revolution: the tail is the whole run
    edge_speed = np.interp(bounds, t, phase.speed)
    n_parts = bounds.size - 1
    # the load is convex in the squared speed: its largest over a part at its slowest or fastest
    fastest = _revolution_maxima(np.abs(phase.speed), t, bounds)
    slowest = -_revolution_maxima(-np.abs(phase.speed), t, bounds)
    measures: dict[str, np.ndarray] = {}
    texts: list[list[str]] = [[] for _ in range(n_parts)]
    independent = lin.coefficients.independent
    for probe in lin.range_probes:
        if not hasattr(probe, "w"):
            continue        # a drive's saturation: the nonlinear run applies its limits itself
        link = probe.link
        q = run.s[:, independent[probe.columns]]                 # (n_t, n_e)
        deflection = _revolution_maxima(np.abs(q @ probe.w.T).max(axis=1), t, bounds)
        slope = _revolution_maxima(np.abs(q @ probe.dw.T).max(axis=1), t, bounds)
        if link.yield_strength is None:
            stress = np.full(n_parts, np.nan)
        else:
            curvature = _revolution_maxima(np.abs(q @ probe.ddw.T).max(axis=1), t, bounds)
            stress = link.youngs_modulus * link.section_height / 2.0 * curvature / link.yield_strength
        compression = np.maximum(axial.compression_over_euler(link, slowest),
                                 axial.compression_over_euler(link, fastest))
        values = dict(zip(MEASURES, (deflection / link.length, deflection / link.section_height, slope,
                                     compression, stress)))
        for name, value in values.items():
            measures[f"{link.name}.{name}"] = np.asarray(value, dtype=float)
        for k in range(n_parts):
            if k < n_parts - 1 and bounds[k + 1] <= bounds[k]:
                continue
            record = linearize.LinkRange(link.name, *(float(values[name][k]) for name in MEASURES),
                                         stiffened=probe.stiffened)
            texts[k] += record.exceeded()
    if not analysis.speed.size:
        for values in measures.values():
            values[0] = np.nan
    status = np.array(["outside_linear_range" if found else "ok" for found in texts], dtype=object)
    verdicts = []
    outside = [k for k, found in enumerate(texts) if found]
    if outside:
        worst = max(outside, key=lambda k: len(texts[k]))
        revolutions = [k for k in outside if k < n_parts - 1]
        where = (f"in {len(revolutions)} of {n_parts - 1} revolutions (mean speeds "
                 f"{analysis.speed[revolutions].min():.4g}-{analysis.speed[revolutions].max():.4g} rad/s)"
                 if revolutions else "")
        if outside[-1] == n_parts - 1:
            where += (" and " if where else "in ") + "what follows the last whole revolution"
        at = (f"revolution {worst + 1} at {analysis.speed[worst]:.4g} rad/s" if worst < n_parts - 1
              else "after the last whole revolution")
        verdicts.append(("outside_linear_range", f"along the ramp: outside the linear range {where}; "
                                                 f"at {at}: " + "; ".join(texts[worst])))
    note = ""
    if analysis.speed.size > 1:
        duration = np.diff(analysis.times)
        acceleration = np.abs(np.diff(edge_speed[:-1])) / duration
        share = acceleration / np.maximum(np.minimum(np.abs(edge_speed[:-2]), np.abs(edge_speed[1:-1])),
                                          1e-300) ** 2
        if any(p is not None for p in axial.parts.values()) and share.max() > ACCELERATION_SHARE:
            note = (f"the compression per revolution is the constant-speed nominal load's, which leaves "
                    f"out the ramp's angular acceleration: |alpha| / omega^2 up to {share.max():.3g} "
                    f"(> {ACCELERATION_SHARE:g} in {int((share > ACCELERATION_SHARE).sum())} revolutions)")
    return measures, status.astype(str), verdicts, note


def stability(curve_speed, curve_stable, start_verdicts) -> tuple[bool, list, str]:
    """``(is_stable, [(status, message)], words)``: a run-up's ``is_stable`` is that every frozen
    periodic state it passes (the linear steady states of its curve, Floquet with the error bar of
    their radius) attracts; a band of unstable ones is an ``unstable`` verdict (the run's numbers are
    a transient through it and stand; there is no steady limit to approach)."""
    if not np.size(curve_speed):
        return (True, [], "stability of the periodic states along the ramp not checked "
                          "(curve_points = 0: is_stable says the start's only)")
    unstable = np.asarray(curve_stable) == 0
    if not unstable.any():
        return True, [], ""
    speeds = np.asarray(curve_speed)[unstable]
    return False, [("unstable", f"along the ramp: the periodic states at {speeds.min():.4g}-"
                                f"{speeds.max():.4g} rad/s ({int(unstable.sum())} of {unstable.size} "
                                "curve points) are unstable (linear Floquet): the run passes an "
                                "instability band, its response there is a transient with no steady "
                                "limit")], ""


def released(mechanism) -> tuple[Any, str]:
    """(mechanism, words): ``mechanism`` with its motor off, every drive a crank free of torque at
    its joint (a prescribed drive's rheonomic row dropped; a torque drive's law, motor and torque
    limit gone, its rotor's and flywheel's inertia kept) and its controllers dropped; the nominal
    motion (the reference of the observables) stays the drives' laws."""
    drives, words = [], []
    for drive in mechanism.drives:
        inertia = float(drive.inertia)
        drives.append(mechanisms.TorqueDrive(drive.joint, rate=drive.rate, offset=drive.offset,
                                             harmonics=drive.harmonics, feedforward=False,
                                             flywheel=inertia))
        words.append(f"{drive.joint!r} with {inertia:g} kg m^2 of rotor and flywheel")
    free = mechanism.replace(drives=tuple(drives), controllers=())
    dropped = f", {len(mechanism.controllers)} controllers off" if mechanism.controllers else ""
    return free, "coasting: the drives released at t = 0 (" + ", ".join(words) + dropped + ")"


def check_follows(mechanism, run_down: str) -> None:
    """Refuse a ramp a drive cannot follow: a torque drive with no feedback on its speed (no kp, kd,
    motor or controller) gets no torque from a ramped reference."""
    if run_down == "coast":
        return
    controlled = {controller.joint for controller in mechanism.controllers}
    for drive in mechanism.drives:
        gains = (getattr(drive, "kp", None), getattr(drive, "kd", None), getattr(drive, "motor", None))
        if gains[0] is None:
            continue      # prescribed: its angle is the ramp's
        if not (gains[0] > 0 or gains[1] > 0 or gains[2] is not None or drive.joint in controlled):
            raise StudiesError(f"run_down / stop: the torque drive at {drive.joint!r} has no feedback "
                               "(kp = kd = 0, no motor, no controller), so its torque does not follow a "
                               "ramped speed command; give it drive.kp / drive.kd or a motor, or run it "
                               "down with run_down = 'coast' (the motor off)")


def error_estimate(model, linear, drive, start, specs, dt, options, fine, ptp_error, peak_error, tail_error,
                    reasons) -> tuple[float, str]:
    """The runs at 2 dt (the Richardson estimate, written into ``ptp_error``, ``peak_error``,
    ``tail_error``) and, unless the estimate is below ``SKIP_CHECK_BELOW`` of the largest peak to
    peak, at 4 dt (its asymptotic range, the steady states' rule): (their run time s, words)."""
    coarse = analysed(model, linear, drive, start, specs, 2.0 * dt, options)
    if not coarse.run.success:
        reasons.append(f"no error estimate: the run at 2 dt failed ({coarse.run.message})")
        return coarse.run.run_time, ""
    n_rev, small = fine.speed.size, True
    for spec in specs:
        count = min(n_rev, coarse.peak_to_peak[spec].size)
        difference = np.abs(fine.peak_to_peak[spec][:count] - coarse.peak_to_peak[spec][:count])
        ptp_error[spec][:count] = ERROR_FACTOR * difference
        peak_error[spec][:count] = ERROR_FACTOR * np.abs(fine.peak[spec][:count] - coarse.peak[spec][:count])
        if count == n_rev:
            tail_error[spec] = ERROR_FACTOR * abs(fine.tail_peak_to_peak[spec] - coarse.tail_peak_to_peak[spec])
        scale = float(np.max(fine.peak_to_peak[spec])) if n_rev else 0.0
        small = small and count == n_rev and count > 0 and bool(
            ERROR_FACTOR * difference.max() <= SKIP_CHECK_BELOW * scale)
    if small:
        return coarse.run.run_time, (f"the run at 4 dt that checks the error estimate's range left out: every "
                                     f"estimate below {SKIP_CHECK_BELOW:g} of the largest peak to peak")
    quarter = analysed(model, linear, drive, start, specs, 4.0 * dt, options)
    if not quarter.run.success:
        reasons.append(f"error estimate not checked: the run at 4 dt failed ({quarter.run.message}); raise "
                       "mode_steps or n_steps")
        return coarse.run.run_time + quarter.run.run_time, ""
    for spec in specs:
        count = min(n_rev, coarse.peak_to_peak[spec].size, quarter.peak_to_peak[spec].size)
        if not count:
            continue
        fine_ptp, coarse_ptp = fine.peak_to_peak[spec][:count], coarse.peak_to_peak[spec][:count]
        check = periodic.error_verdict(
            float(np.max(np.abs(fine_ptp - coarse_ptp))),
            float(np.max(np.abs(coarse_ptp - quarter.peak_to_peak[spec][:count]))), 2,
            scale=float(np.max(fine.peak_to_peak[spec])), quantity="p2p")
        if check.status != "ok":
            words = check.message.replace("refine n_steps", "raise mode_steps or n_steps")
            reasons.append(f"{spec}: {words} (p2p: the peak to peak per revolution; N, N/2, N/4: "
                           "the runs at dt, 2 dt, 4 dt)")
    return coarse.run.run_time + quarter.run.run_time, ""


def tail_words(fine, run, specs) -> str:
    """What follows the last whole revolution, in words (empty when the run ends on one)."""
    if run.t[-1] - fine.tail_start <= 2.0 * (run.t[1] - run.t[0]):
        return ""
    reversal = fine.phase.reversal()
    turned = float(np.interp(run.t[-1], run.t, fine.phase.phase)
                   - np.interp(fine.tail_start, run.t, fine.phase.phase))
    how = (f"the crank turned back at t = {run.t[reversal]:.4g} s" if reversal < run.t.size - 1
           else f"the crank turned {turned:.3g} rad of a revolution")
    rows = ", ".join(f"{spec} {fine.tail_peak_to_peak[spec]:.4g}" for spec in specs)
    return (f"from t = {fine.tail_start:.4g} s to the end no whole revolution ({how}, final speed "
            f"{fine.phase.speed[-1]:.3g} rad/s): not in the per-revolution arrays; its peak to peak in "
            f"tail_peak_to_peak ({rows})")


def growth_words(fine, specs, success) -> str:
    """A response still growing at the end of the run, said: the largest may lie beyond it."""
    growing = [spec for spec in specs if fine.speed.size > 2 and success
               and int(np.argmax(fine.peak_to_peak[spec])) == fine.speed.size - 1]
    if not growing:
        return ""
    return (f"{', '.join(growing)}: still growing at the end (largest in the last whole revolution): the "
            "largest response of this machine may lie beyond the ramp")
