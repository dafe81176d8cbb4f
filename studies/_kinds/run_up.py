"""``[studies.run_up]``: the full nonlinear model while the drive speed is ramped from ``start`` to
``stop`` (a run-up, or a run-down with ``start > stop``), started from the periodic state at
``start``; per revolution the peak-to-peak of each observable against the mean speed, beside the
steady-state curves, with an error estimate from the same run at twice the step."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

import mechanisms
import periodic

from .._kind import StudyKind, register_kind
from .._mechanism import of_coordinates
from .._numerics import solve_steady
from .._plots import Plot, axes_for, drawn, headline, label, plain
from .._result import StudyResult
from .._toolkit import (
    SPEED,
    WARM_UP_STEPS,
    Headline,
    StudiesError,
    Summary,
    boolean,
    combine,
    cost,
    integer,
    number,
    steps,
)
from ._nonlinear_model import check_modes
from ._run_up_checks import (
    AxialLoad,
    along_ramp,
    check_follows,
    error_estimate,
    growth_words,
    released,
    stability,
    tail_words,
)
from ._run_up_curve import reduced_model, resonances, steady_curve, time_step
from ._run_up_revolutions import analysed, torques

#: Start states: the nonlinear periodic state at ``start`` (shooting; the linear one where Newton does
#: not find it), the linear steady state, or the nominal rigid motion with the elastic coordinates at rest.
START_STATES = ("nonlinear", "linear", "rest")
#: How a run goes down: ``"ramp"``, the drives follow the speed ramp (a prescribed drive's angle, a
#: torque drive's speed command: braking by the motor); ``"coast"``, the drives released at t = 0
#: (the motor off), ``stop = 0``.
RUN_DOWNS = ("ramp", "coast")
#: Default steps per revolution at the fastest speed of the ramp: 16 per period of its 4th harmonic (the
#: elastic periods bound the step beside it, ``MODE_STEPS``). At 32 the four-bar's run-up through its
#: 2x resonance (benchmarks/bench_run_up.py) had an estimated error of 21 % of its largest peak to peak.
STEPS_PER_REVOLUTION = 64
#: Default steps per period of the highest elastic mode that matters (``_run_up_curve.time_step``).
MODE_STEPS = 16
#: Default highest harmonic of the speed whose resonances are marked (and whose modes bound the step).
MAX_HARMONIC = 4
#: Default Newton tolerance of the runs (``mechanisms.simulate``'s ``tol``, relative to the configuration's
#: size): on four_bar_fem4 through a ramp 100 -> 150 rad/s the deflection stays within 1.4e-5 of its peak
#: to peak of the run at 1e-10 (1e-8: 7e-7), far below the step's error, for 3.6 (at 200 steps a period
#: 2.2) instead of 4.8 (4.2) Newton iterations a step; benchmarks/bench_simulate.py found the same value.
TOL = 1e-7
#: Richardson factor of the order-2 generalized-alpha orbit's N/2 error bars.
ERROR_FACTOR = 1.0 / 3.0
#: Default speeds of the steady-state curve.
CURVE_POINTS = 25
#: A per-revolution peak-to-peak whose estimated error exceeds this fraction of the largest one is
#: ``inaccurate`` (the rule of the steady states, docs/methods.md).
MAX_RELATIVE_ERROR = periodic.MAX_RELATIVE_ERROR
#: The most steps a run-up may take (the fine run; the coarse one takes half as many).
MAX_RUN_STEPS = 5_000_000
RUN_STEPS_WHY = "steps of one run-up (its time step is set by the elastic periods)"


@dataclass(frozen=True, eq=False)
class RunUp(StudyResult):
    """A run-up or run-down of the full nonlinear model (the fields every result has:
    ``studies._result``; ``peak``, ``peak_to_peak`` and their errors are per revolution here).

    Attributes
    ----------
    problem, scene : str
        The problem's name and scene text.
    parameters : dict
        {name: value} of the scene at the start (``speed`` = ``start``).
    units : dict
        {spec: unit} of each observable.
    settings : dict
        The study's arguments.
    t : ndarray, (n_t,), s
        The run's samples (uniform step ``dt``).
    response : dict of ndarray, {spec: (n_t,)}, units[spec]
        Each observable along the run, as the linear route reports it: its change from its value on
        the rigid motion at the same crank angle (angles modulo 2 pi).
    drive_speed : ndarray, (n_t,), rad/s
        The speed of the motion (``2 pi`` per revolution: the first drive's rate over its turns per
        revolution), as the run turned it.
    drive_torque : ndarray, (n_t,), N m
        The first drive's torque (a prescribed drive's multiplier; a torque drive's law as applied).
    speed : ndarray, (n_rev,), rad/s
        The mean speed of each whole revolution (2 pi over its duration).
    peak_to_peak, peak : dict of ndarray, {spec: (n_rev,)}, units[spec]
        Each revolution's peak-to-peak and largest magnitude (extremes refined by the parabola through
        their neighbours).
    peak_to_peak_error, peak_error : dict of ndarray, {spec: (n_rev,)}, units[spec]
        Their Richardson estimates from the run at ``2 dt`` (NaN without it).
    largest, largest_error : dict, {spec: float}, units[spec]
        The largest per-revolution peak-to-peak and its error estimate.
    speed_at_largest : dict, {spec: float}, rad/s
        The mean speed of the revolution where it occurred.
    curve_speed : ndarray, (n_curve,), rad/s
        The speeds of the steady-state curves.
    curve_peak_to_peak, curve_error : dict of ndarray, {spec: (n_curve,)}, units[spec]
        The linear steady state's peak-to-peak there and its error estimate.
    curve_status : ndarray of str, (n_curve,)
        The linear steady state's status at each.
    nonlinear_curve_peak_to_peak : dict of ndarray, {spec: (n_curve,)}, units[spec]
        The nonlinear periodic state's peak-to-peak there (NaN where not computed or not found).
    resonance_speed : ndarray, (n_res,), rad/s
        Speeds in the ramp's range where ``k speed`` meets a natural frequency (frozen, mean over the
        period, at that speed); ``resonance_harmonic``, ``resonance_mode`` (n_res,) their k and 0-based
        mode.
    natural_frequencies : ndarray, (n_modes,), rad/s
        The mean frozen natural frequencies at ``start`` of the modes that bound the step.
    start_state : str
        ``"nonlinear periodic state"``, ``"linear steady state"`` or ``"rest"``: what the run started from.
    dt : float, s
        The time step, and ``dt_reason`` what bounds it.
    status, message : str
        The run's verdict (``failed``: the run did not reach the end, ``inaccurate``: an error estimate
        above a tenth of the largest peak-to-peak or none) with the start state's.
    run_time : float, s
        The whole study; ``simulation_run_time`` the fine run, ``error_run_time`` the runs at 2 dt and 4 dt,
        ``curve_run_time`` the steady-state curves.
    is_stable : bool
        Every frozen periodic state the ramp passes attracts (the linear steady states of the curve,
        Floquet with their radius's error bar) and the start's does; with ``curve_points = 0`` the
        start's only (said in the message). A run through an instability band is ``unstable``.
    range_measures : dict of ndarray, {"<link>.<measure>": (n_rev + 1,)}, 1
        The steady states' linear-range measures (``linearize.LinkRange``'s fields) over each
        revolution, the last entry over what follows the last whole revolution (NaN without one);
        ``revolution_status`` (n_rev + 1,) ``ok`` or ``outside_linear_range`` for each.
    tail_peak_to_peak, tail_peak_to_peak_error : dict, {spec: float}, units[spec]
        Each observable's peak to peak from ``tail_start`` (s), the end of the last whole revolution,
        to the run's end (a crank slowing to a stop or swinging back) and its estimate from 2 dt.
    curve_is_stable : ndarray, (n_curve,)
        1 where the curve's linear steady state is stable, 0 where not, NaN where not computed.
    reduced_modes, reduction_error : dict
        With ``modes`` other than ``"full"``: {link: modes} of the reduced links the run integrated,
        and {spec: the stated reduction error of the largest peak to peak, units[spec]} (the
        reduction check's largest ratio to a peak to peak over the ramp's ends and resonances, twice).
    """

    problem: str
    scene: str
    parameters: Mapping[str, float]
    units: Mapping[str, str]
    settings: Mapping[str, Any]
    t: np.ndarray
    response: Mapping[str, np.ndarray]
    drive_speed: np.ndarray
    drive_torque: np.ndarray
    speed: np.ndarray
    peak_to_peak: Mapping[str, np.ndarray]
    peak_to_peak_error: Mapping[str, np.ndarray]
    peak: Mapping[str, np.ndarray]
    peak_error: Mapping[str, np.ndarray]
    largest: Mapping[str, float]
    largest_error: Mapping[str, float]
    speed_at_largest: Mapping[str, float]
    curve_speed: np.ndarray
    curve_peak_to_peak: Mapping[str, np.ndarray]
    curve_error: Mapping[str, np.ndarray]
    curve_status: np.ndarray
    nonlinear_curve_peak_to_peak: Mapping[str, np.ndarray]
    resonance_speed: np.ndarray
    resonance_harmonic: np.ndarray
    resonance_mode: np.ndarray
    natural_frequencies: np.ndarray
    start_state: str
    dt: float
    dt_reason: str
    status: str
    message: str
    run_time: float
    simulation_run_time: float = float("nan")
    error_run_time: float = float("nan")
    curve_run_time: float = float("nan")
    is_stable: bool = True
    range_measures: Mapping[str, np.ndarray] = field(default_factory=dict)
    revolution_status: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=str))
    tail_peak_to_peak: Mapping[str, float] = field(default_factory=dict)
    tail_peak_to_peak_error: Mapping[str, float] = field(default_factory=dict)
    tail_start: float = float("nan")
    curve_is_stable: np.ndarray = field(default_factory=lambda: np.zeros(0))
    reduced_modes: Mapping[str, int] = field(default_factory=dict)
    reduction_error: Mapping[str, float] = field(default_factory=dict)
    extra: Mapping[str, Any] = field(default_factory=dict)

    _units = {"t": "s", "response": "@observables", "drive_speed": "rad/s", "drive_torque": "N m",
              "speed": "rad/s", "peak_to_peak": "@observables", "peak_to_peak_error": "@observables",
              "peak": "@observables", "peak_error": "@observables", "curve_speed": "rad/s",
              "curve_peak_to_peak": "@observables", "curve_error": "@observables",
              "nonlinear_curve_peak_to_peak": "@observables", "resonance_speed": "rad/s",
              "natural_frequencies": "rad/s", "range_measures": "1"}

    @property
    def direction(self) -> str:
        """``"run-up"`` or ``"run-down"``."""
        return "run-up" if self.settings.get("stop", 0.0) > self.settings.get("start", 0.0) else "run-down"

    def plot(self, *, axes: Any = None) -> Plot:
        """Per revolution the peak-to-peak against the mean speed, over the steady-state curves
        (linear, and nonlinear where computed), resonances marked, the largest response named."""
        specs = list(self.units)
        axes = axes_for(len(specs), axes, height=3.2)
        artists: dict[str, list] = {}
        for ax, spec in zip(axes, specs):
            lines = []
            ptp = np.asarray(self.peak_to_peak.get(spec, []), dtype=float)
            if ptp.size:
                lines += ax.plot(self.speed, ptp, color="C0", lw=1.0, label=f"{self.direction}, per revolution")
                error = np.asarray(self.peak_to_peak_error.get(spec, np.full(ptp.size, np.nan)), dtype=float)
                if np.isfinite(error).any():
                    ax.fill_between(self.speed, ptp - error, ptp + error, color="C0", alpha=0.25, lw=0)
                outside = np.asarray(self.revolution_status[:ptp.size]) != "ok" if np.size(
                    self.revolution_status) > ptp.size else np.zeros(ptp.size, dtype=bool)
                if outside.any():   # the checks along the ramp, revolution by revolution
                    lines += ax.plot(self.speed[outside], ptp[outside], "x", ms=3, color="C3",
                                     label="outside the linear range")
            if np.size(self.curve_speed):
                lines += ax.plot(self.curve_speed, self.curve_peak_to_peak[spec], "--", color="C1",
                                 label="steady state, linear")
                nonlinear = np.asarray(self.nonlinear_curve_peak_to_peak.get(spec, []), dtype=float)
                if nonlinear.size and np.isfinite(nonlinear).any():
                    lines += ax.plot(self.curve_speed, nonlinear, "o", ms=3, color="C2",
                                     label="steady state, nonlinear")
            for speed, k, mode in zip(self.resonance_speed, self.resonance_harmonic, self.resonance_mode):
                lines.append(ax.axvline(speed, color="0.5", ls=":", lw=0.8))
                ax.annotate(f"{int(k)}x: mode {int(mode) + 1}", (speed, 1.0), xycoords=("data", "axes fraction"),
                            fontsize="x-small", rotation=90, va="top", ha="right", color="0.4")
            largest = self.largest.get(spec, float("nan"))
            if np.isfinite(largest):
                lines += ax.plot([self.speed_at_largest[spec]], [largest], "v", color="C3",
                                 label=f"largest {plain(largest)} at {plain(self.speed_at_largest[spec], 3)} rad/s")
            ax.set_xlabel("mean speed of the revolution (rad/s)")
            ax.set_ylabel(f"peak to peak, {label(spec, self.units[spec])}")
            ax.set_title(f"{spec}: {self.direction} {plain(self.settings.get('start', np.nan), 3)} -> "
                         f"{plain(self.settings.get('stop', np.nan), 3)} rad/s in "
                         f"{plain(self.settings.get('duration', np.nan), 3)} s: {headline(self.status)}\n"
                         f"largest {plain(largest)} +- {plain(self.largest_error.get(spec, float('nan')))}; "
                         f"from the {self.start_state}; run time {plain(self.run_time)} s", fontsize="small")
            ax.legend(fontsize="x-small")
            artists[spec] = lines
        return drawn(axes, artists)

    def plot_time(self, *, axes: Any = None) -> Plot:
        """The observables, the speed and the drive torque against time."""
        specs = list(self.units)
        axes = axes_for(len(specs) + 2, axes, height=2.2)
        artists: dict[str, list] = {}
        for ax, spec in zip(axes, specs):
            artists[spec] = ax.plot(self.t, self.response[spec], lw=0.5, color="C0")
            ax.set_ylabel(label(spec, self.units[spec]))
        artists["speed"] = axes[-2].plot(self.t, self.drive_speed, color="C1")
        axes[-2].set_ylabel("speed (rad/s)")
        artists["torque"] = axes[-1].plot(self.t, self.drive_torque, lw=0.5, color="C2")
        axes[-1].set_ylabel("drive torque (N m)")
        axes[-1].set_xlabel("time (s)")
        axes[0].set_title(f"{self.direction}: {headline(self.status)}", fontsize="small")
        return drawn(axes, artists)


# ---------------------------------------------------------------------------------------------------
# the pieces
# ---------------------------------------------------------------------------------------------------
def _check_arguments(problem, start, stop, duration, profile, start_state, run_down="ramp"):
    import mechanisms

    if not (getattr(problem, "supports_nonlinear", False) and hasattr(problem, "mechanism")):
        raise StudiesError(f"problem {getattr(problem, 'name', problem)!r}: a run-up needs the full "
                           "nonlinear model of a mechanism (studies.MechanismProblem); expected one")
    for name, value, least in (("start", start, "positive"), ("stop", stop, "nonnegative")):
        if not (isinstance(value, (int, float)) and math.isfinite(value)
                and (value > 0 if least == "positive" else value >= 0)):
            raise StudiesError(f"{name}: expected a {least} speed (rad/s), got {value!r}"
                               + ("; a run from standstill starts at a small speed with start_state = 'rest'"
                                  if name == "start" else ""))
    if stop == start:
        raise StudiesError(f"stop: expected a speed other than start ({start!r} rad/s): a run at one speed "
                           "is a nonlinear_check")
    if not (isinstance(duration, (int, float)) and math.isfinite(duration) and duration > 0):
        raise StudiesError(f"duration: expected a positive time (s), got {duration!r}")
    if profile not in mechanisms.RAMP_SHAPES:
        raise StudiesError(f"profile: expected one of {sorted(mechanisms.RAMP_SHAPES)}, got {profile!r}")
    if start_state not in START_STATES:
        raise StudiesError(f"start_state: expected one of {START_STATES}, got {start_state!r}")
    _check_run_down("run_down", run_down, stop, profile)


def _check_run_down(where, run_down, stop, profile):
    if run_down not in RUN_DOWNS:
        raise StudiesError(f"{where}: expected one of {RUN_DOWNS}, got {run_down!r}")
    if run_down == "coast" and stop != 0:
        raise StudiesError(f"{where} = 'coast' releases the drives (the motor off): expected stop = 0, "
                           f"got stop = {stop!r}; a run to another speed follows a ramp (run_down = 'ramp')")
    if run_down == "coast" and profile != "linear":
        raise StudiesError(f"{where} = 'coast' follows no ramp: profile has no meaning there (got "
                           f"{profile!r}); leave it out")


def _as_start(status: str, message: str) -> tuple[str, str]:
    """A start state's verdict as the run-up's: an untrusted error estimate of the start (the state
    is a start only: what it misses is a transient of the run, which the run's own error estimate
    covers from the same start) is said, not made the run-up's status; its stability and the rest are."""
    if status == "inaccurate":
        return "ok", f"{message} (the start's own error estimate only: the run's numbers carry theirs)"
    return status, message


def _start(problem, values, start, steps_at_start, start_state):
    """(linear at the start speed, s0, sdot0, lag0, words, [(status, message)]). The nonlinear start is
    the shooting of ``nonlinear_steady_state`` (its orbit on N steps, its stability's error bars from
    N/2) without what that study adds for a result (the N/2 error estimates of its observables, the
    mesh term of its budget): the run's numbers carry their own estimates from the same start."""
    import mechanisms

    from .nonlinear_steady_state import MAX_ITERATIONS, shooting_setup
    from .nonlinear_steady_state import TOL as ORBIT_TOL

    point = dict(values, **{SPEED: start})
    if start_state != "nonlinear":
        linear = problem.linearize(point, n_steps=steps_at_start)
        lin = linear.context
        if start_state == "rest":
            return linear, lin.nominal.s[0], lin.nominal.sdot[0], None, "rest", []
        steady, verdicts = solve_steady(linear), []
    else:
        # on the model the run integrates (reduced or full): a state of another model is not a
        # state of the run's (other coordinates)
        setup = shooting_setup(problem, point, steps_at_start)
        linear, steady, fine = setup.linear, setup.steady, setup.fine
        lin = linear.context
        fine.warm_up()
        orbit = periodic.find_orbit(fine, setup.guess, start, tol=ORBIT_TOL, max_iterations=MAX_ITERATIONS,
                                    estimate=setup.coarse, error_factor=ERROR_FACTOR)
        if orbit.converged:
            s0, sdot0 = fine.start_state(orbit.state)
            lag0 = fine.lag_states_of(orbit.state) if fine.n_lags else None
            return linear, s0, sdot0, lag0, "nonlinear periodic state", [
                _as_start(orbit.status, f"start: nonlinear periodic state {orbit.status}: {orbit.message}")]
        verdicts = [("ok", f"the nonlinear periodic state at {start:g} rad/s was not found "
                           f"({orbit.message}); started from the linear steady state instead")]
    n_lags = len(getattr(mechanisms.integrated_model(lin.mechanism, lin.nominal), "lag_names", ()))
    x0, v0 = steady.state.x[0], steady.state.v[0]
    s0, sdot0 = lin.start_state(x0, v0)
    lag0 = np.asarray(x0, dtype=float)[-n_lags:] if n_lags else None
    verdicts.append(_as_start(steady.status, f"start: linear steady state {steady.status}"
                              + (f" ({steady.message})" if steady.message else "")))
    return linear, s0, sdot0, lag0, "linear steady state", verdicts


def run_up(problem: Any, values: Mapping[str, float] | None = None, *, start: float, stop: float,
           duration: float, profile: str = "linear", n_steps: int = STEPS_PER_REVOLUTION,
           mode_steps: int = MODE_STEPS, max_harmonic: int = MAX_HARMONIC, start_state: str = "nonlinear",
           curve_points: int = CURVE_POINTS, curve_steps: int = 128, nonlinear_curve: bool = False,
           estimate_error: bool = True, rho_inf: float = 0.8, tol: float = TOL, run_down: str = "ramp",
           modes: Any = "auto") -> RunUp:
    """The full nonlinear model (``mechanisms.simulate``) while the speed goes from ``start`` to
    ``stop`` (rad/s, ``start > stop`` runs it down, ``stop = 0`` to a standstill) over ``duration``
    (s) along ``profile`` (a ramp shape of ``mechanisms.RAMP_SHAPES``: ``"linear"``, ``"smooth"``),
    from the periodic state at ``start`` (``start_state``: ``"nonlinear"`` the nonlinear periodic state
    by shooting, the linear steady state where Newton does not find it; ``"linear"``; ``"rest"`` the
    rigid motion with the elastic coordinates at rest). Prescribed drives follow the ramp; a torque
    drive's reference (angle, rate: its motor's speed command) follows it, its feedforward read at the
    reference's crank angle (``mechanisms.Model.with_drive_profiles``): with ``stop = 0`` the motor
    brakes the machine to a standstill. ``run_down = "coast"`` (``stop = 0``) releases the drives at
    t = 0 instead, the motor off (every drive a torque-free crank, its rotor's and flywheel's inertia
    kept, the controllers off) for ``duration`` s; a torque drive without feedback (no kp, kd, motor
    or controller) cannot follow a ramp and is refused.

    Along the run each revolution gets the steady states' linear-range measures (``range_measures``,
    ``revolution_status``: deflection over length and section height, slope, stress, compression
    over the Euler load, an unstiffened link's model form), and the frozen periodic states of the
    curve their stability (``is_stable``; a band of unstable ones makes the run ``unstable``). What
    follows the last whole revolution (a crank slowing to a stop or swinging back) is
    ``tail_peak_to_peak``.

    The step ``dt`` is uniform, the largest that takes ``n_steps`` per revolution at the fastest speed
    and ``mode_steps`` per period of the highest natural frequency up to ``max_harmonic`` times it.
    ``tol`` is the runs' Newton tolerance (``mechanisms.simulate``). With ``estimate_error`` the same
    run at ``2 dt`` gives each per-revolution number its Richardson error estimate, and one at ``4 dt``
    checks that it is in the asymptotic range (else ``inaccurate``). ``curve_points`` linear steady
    states (``curve_steps`` steps each) between the speeds give the steady curve
    (``nonlinear_curve``: the nonlinear periodic states too).

    By default (``modes = "auto"``) the run and its start are on the reduced model
    ``nonlinear_steady_state`` chooses at ``start`` (``studies._kinds._nonlinear_model``: the fewest
    modes its reduction check accepts, else the full element models), its reduction check repeated at
    the ramp's other end and at each resonance in its range, the largest twice as the stated
    reduction error (``reduction_error``, in each headline's error beside the time step's; above a
    tenth of a peak to peak ``inaccurate``); ``modes = "full"`` runs the scene's element models, a
    count reduces to that many modes. The nonlinear curve stays on the full models.

    Observables are those of the problem that are functions of the coordinates (deflections, strains,
    moments, angles); the drive torque is reported as its own time series. A run that fails gives
    status ``failed`` with what was computed up to the failure, not an exception."""
    import mechanisms

    _check_arguments(problem, start, stop, duration, profile, start_state, run_down)
    modes = check_modes(modes)
    n_steps = steps("run_up", {"n_steps": n_steps}, n_steps, minimum=8)
    for name, value, least in (("mode_steps", mode_steps, 4), ("max_harmonic", max_harmonic, 1),
                               ("curve_points", curve_points, 0)):
        if not (isinstance(value, int) and value >= least):
            raise StudiesError(f"{name}: expected an integer >= {least}, got {value!r}")
    clock = time.perf_counter()
    values = {k: v for k, v in (values or {}).items() if k != SPEED}
    parameters = problem.resolve(dict(values, **{SPEED: start}))
    dt, dt_reason, frequencies = time_step(problem, values, start, stop, n_steps, mode_steps, max_harmonic)
    n_run = 4 * int(math.ceil(duration / (4.0 * dt)))   # the runs at 2 dt and 4 dt on every other sample
    if n_run > MAX_RUN_STEPS:
        raise StudiesError(f"duration: {duration:g} s at dt = {dt:.3g} s ({dt_reason}) is {n_run} steps; "
                           f"at most {MAX_RUN_STEPS} ({RUN_STEPS_WHY}): shorten the ramp or lower "
                           f"mode_steps / n_steps")
    dt = duration / n_run
    # the start orbit on at least 128 steps: its N/4 check of the error estimate needs 32
    steps_at_start = max(128, 4 * int(math.ceil(2.0 * math.pi / start / dt / 4.0)))
    low, high = min(start, stop), max(start, stop)
    res_speed, res_k, res_mode = resonances(problem, values, low, high, len(frequencies), max_harmonic)
    model_problem, model_values, reduction = problem, values, None
    if modes != "full":
        model_problem, model_values, reduction = reduced_model(
            problem, values, [start, stop] + list(res_speed), modes)
    linear, s0, sdot0, lag0, start_words, verdicts = _start(model_problem, model_values, start, steps_at_start,
                                                            start_state)
    lin = linear.context
    drives = lin.mechanism.drives
    if any(drive.rate == 0.0 for drive in drives):
        raise StudiesError(f"problem {problem.name!r}: a run-up ramps turning drives; the drive at "
                           f"{next(d.joint for d in drives if d.rate == 0.0)!r} has rate 0 (an oscillating "
                           "drive has no speed to ramp)")
    check_follows(lin.mechanism, run_down)
    drive_words = ""
    if run_down == "coast":
        free, drive_words = released(lin.mechanism)
        ramped, lag0 = mechanisms.integrated_model(free, lin.nominal), None
    else:
        model = mechanisms.integrated_model(lin.mechanism, lin.nominal)
        ramped = model.with_drive_profiles(
            lambda drive: mechanisms.SpeedRamp(drive.rate, drive.rate * stop / start, duration, profile))
    # the nominal axial loads at a second speed on the start's grid: the compression at any speed
    other = stop if stop > 0 else 0.5 * start
    axial = AxialLoad(lin.range_probes, start,
                      model_problem.linearize(dict(model_values, **{SPEED: other}),
                                              n_steps=steps_at_start).context.range_probes,
                      other)
    specs = [spec for spec in linear.observables if of_coordinates(ramped.observable(spec))]
    left_out = [spec for spec in linear.observables if spec not in specs]
    units = {spec: ramped.observable(spec).unit for spec in specs}
    options = dict(t_end=duration, s0=s0, sdot0=sdot0, observables=specs, estimate_error=False,
                   lag0=lag0, rho_inf=rho_inf, tol=tol, throw=False)
    setup_time = time.perf_counter() - clock
    fine = analysed(ramped, linear, drives[0], start, specs, dt, options)
    run, speed, ptp, peak = fine.run, fine.speed, fine.peak_to_peak, fine.peak
    torque = torques(ramped, run, drives[0].joint)
    n_rev = speed.size
    ptp_error = {spec: np.full(n_rev, np.nan) for spec in specs}
    peak_error = {spec: np.full(n_rev, np.nan) for spec in specs}
    tail_error = {spec: float("nan") for spec in specs}
    error_time = float("nan")
    reasons = []
    if run.success and estimate_error:
        error_time, check_words = error_estimate(ramped, linear, drives[0], start, specs, dt, options, fine,
                                                  ptp_error, peak_error, tail_error, reasons)
    elif run.success:
        reasons.append("no error estimate (estimate_error = false)")
        check_words = ""
    else:
        check_words = ""
    largest, largest_error, at = {}, {}, {}
    for spec in specs:
        k = int(np.nanargmax(ptp[spec])) if n_rev else -1
        largest[spec] = float(ptp[spec][k]) if n_rev else float("nan")
        largest_error[spec] = float(ptp_error[spec][k]) if n_rev else float("nan")
        at[spec] = float(speed[k]) if n_rev else float("nan")
        worst = float(np.nanmax(ptp_error[spec])) if n_rev and np.isfinite(ptp_error[spec]).any() else math.nan
        if np.isfinite(worst) and worst > MAX_RELATIVE_ERROR * largest[spec]:
            reasons.append(f"{spec}: an estimated error of {worst:.3g} is {worst / largest[spec]:.3g} of the "
                           f"largest peak to peak (> {MAX_RELATIVE_ERROR:g}): raise n_steps or mode_steps")
    curve_clock = time.perf_counter()
    curve_speed = (np.linspace(max(low, 0.02 * high), high, curve_points) if curve_points
                   else np.zeros(0))
    curve_ptp, curve_error, curve_status, nl_ptp, curve_stable = steady_curve(
        problem, values, curve_speed, specs, curve_steps, nonlinear_curve)
    curve_time = time.perf_counter() - curve_clock
    if reduction is not None and reduction.relative > MAX_RELATIVE_ERROR:
        reasons.append(f"the stated reduction error is {reduction.relative:.3g} of a peak to peak (> "
                       f"{MAX_RELATIVE_ERROR:g}): raise modes, or modes = 'full'")
    if not run.success:
        run_verdict = ("failed", f"the run failed: {run.message}; the results end there. Raise n_steps or "
                                 "mode_steps, or ramp more slowly")
    elif reasons:
        run_verdict = ("inaccurate", "; ".join(reasons))
    else:
        run_verdict = ("ok", "")
    measures, revolution_status, range_verdicts, range_note = along_ramp(lin, axial, fine)
    start_stable = all(status != "unstable" for status, _ in verdicts)
    is_stable, stability_verdicts, stability_words = stability(curve_speed, curve_stable, verdicts)
    status, message = combine([run_verdict] + verdicts + range_verdicts + stability_verdicts)
    what = (f"coast from {start:g} rad/s for {duration:g} s" if run_down == "coast" else
            f"{'run-up' if stop > start else 'run-down'} {start:g} -> {stop:g} rad/s in {duration:g} s")
    words = (f"{what}, {n_rev} revolutions, dt = {dt:.3g} s ({dt_reason}), from the {start_words}; "
             + (reduction.words if reduction is not None else
                "on the full element models (modes = 'full', the start and the nonlinear curve too)"))
    words = "; ".join(part for part in (words, drive_words, check_words, tail_words(fine, run, specs),
                                        growth_words(fine, specs, run.success), range_note,
                                        stability_words) if part)
    if left_out:
        words += f"; left out (not functions of the coordinates): {', '.join(left_out)}"
    return RunUp(
        problem=problem.name, scene=problem.text, parameters=parameters, units=units,
        settings={"start": float(start), "stop": float(stop), "duration": float(duration), "profile": profile,
                  "n_steps": n_steps, "mode_steps": mode_steps, "max_harmonic": max_harmonic,
                  "start_state": start_state, "curve_points": curve_points, "curve_steps": curve_steps,
                  "nonlinear_curve": nonlinear_curve, "estimate_error": estimate_error, "rho_inf": rho_inf,
                  "tol": tol, "run_down": run_down, "modes": modes},
        t=run.t, response=fine.response, drive_speed=fine.phase.speed, drive_torque=torque, speed=speed,
        peak_to_peak=ptp, peak_to_peak_error=ptp_error, peak=peak, peak_error=peak_error, largest=largest,
        largest_error=largest_error, speed_at_largest=at, curve_speed=curve_speed,
        curve_peak_to_peak=curve_ptp, curve_error=curve_error, curve_status=curve_status,
        nonlinear_curve_peak_to_peak=nl_ptp, resonance_speed=res_speed, resonance_harmonic=res_k,
        resonance_mode=res_mode, natural_frequencies=np.asarray(frequencies, dtype=float),
        start_state=start_words, dt=float(dt), dt_reason=dt_reason, status=status,
        message=f"{message}; {words}" if message else words,
        run_time=time.perf_counter() - clock, simulation_run_time=run.run_time, error_run_time=error_time,
        curve_run_time=curve_time, is_stable=bool(is_stable and start_stable), range_measures=measures,
        revolution_status=revolution_status, tail_peak_to_peak=fine.tail_peak_to_peak,
        tail_peak_to_peak_error=tail_error, tail_start=fine.tail_start, curve_is_stable=curve_stable,
        reduced_modes=dict(reduction.modes) if reduction is not None else {},
        reduction_error={spec: reduction.relative * largest[spec] for spec in specs} if reduction is not None
        else {},
        extra={"setup_run_time": setup_time, "n_rejected": run.n_rejected})


# ---------------------------------------------------------------------------------------------------
# the kind
# ---------------------------------------------------------------------------------------------------
def _check(where: str, table: Mapping[str, Any], n_steps: int) -> dict[str, Any]:
    for key in ("start", "stop", "duration"):
        if key not in table:
            raise StudiesError(f"[{where}] {key}: required (start and stop speeds in rad/s, duration in s)")
    start = number(where, "start", table["start"], positive=True)
    stop = number(where, "stop", table["stop"])
    if stop < 0:
        raise StudiesError(f"[{where}] stop: expected a speed >= 0 (rad/s; 0 runs down to a standstill), "
                           f"got {stop!r}")
    if stop == start:
        raise StudiesError(f"[{where}] stop: expected a speed other than start ({start!r} rad/s)")
    profile = table.get("profile", "linear")
    import mechanisms

    if profile not in mechanisms.RAMP_SHAPES:
        raise StudiesError(f"[{where}] profile: expected one of {sorted(mechanisms.RAMP_SHAPES)}, got {profile!r}")
    start_state = table.get("start_state", "nonlinear")
    if start_state not in START_STATES:
        raise StudiesError(f"[{where}] start_state: expected one of {START_STATES}, got {start_state!r}")
    run_down = table.get("run_down", "ramp")
    _check_run_down(f"[{where}] run_down", run_down, stop, profile)
    return {"start": start, "stop": stop,
            "duration": number(where, "duration", table["duration"], positive=True),
            "profile": profile, "start_state": start_state, "run_down": run_down,
            "modes": _modes_option(where, table),
            "n_steps": integer(where, "n_steps", table.get("n_steps", STEPS_PER_REVOLUTION), 8,
                               maximum=65536, why="steps per revolution at the fastest speed"),
            "mode_steps": integer(where, "mode_steps", table.get("mode_steps", MODE_STEPS), 4, maximum=1024,
                                  why="steps per period of the highest mode that matters"),
            "max_harmonic": integer(where, "max_harmonic", table.get("max_harmonic", MAX_HARMONIC), 1,
                                    maximum=100, why="harmonics of the speed"),
            "curve_points": integer(where, "curve_points", table.get("curve_points", CURVE_POINTS), 0,
                                    maximum=10_000, why="steady states on the curve"),
            "curve_steps": _curve_steps(where, table.get("curve_steps", max(32, n_steps))),
            "nonlinear_curve": boolean(where, "nonlinear_curve", table.get("nonlinear_curve", False)),
            "estimate_error": boolean(where, "estimate_error", table.get("estimate_error", True))}


def _modes_option(where: str, table: Mapping[str, Any]) -> Any:
    """The table's ``modes`` (default "auto", as ``nonlinear_steady_state``'s)."""
    try:
        return check_modes(table.get("modes", "auto"))
    except StudiesError as error:
        raise StudiesError(f"[{where}] {error}") from None


def _curve_steps(where: str, value: Any) -> int:
    """The steady curve's steps per period: a multiple of 4, at least 32 (its N/4 check)."""
    value = integer(where, "curve_steps", value, 32, maximum=65536, why="steps per period of a steady state")
    if value % 4:
        raise StudiesError(f"[{where}] curve_steps: expected a multiple of 4 (the steady states' N/2 and N/4 "
                           f"runs), got {value!r}")
    return value


def _run(problem: Any, options: Mapping[str, Any], **_: Any) -> RunUp:
    return run_up(problem, **options)


def _summary(result: RunUp) -> str:
    rows = ", ".join(f"{spec} {plain(value)} +- {plain(result.largest_error[spec])} {result.units[spec]} at "
                     f"{plain(result.speed_at_largest[spec], 3)} rad/s" for spec, value in result.largest.items())
    return f"{result.status.upper()}: {result.message}\n    largest peak to peak per revolution: {rows}"


def _headlines(result: RunUp) -> Summary:
    rows = []
    for spec, value in result.largest.items():
        # the error: the time step's estimate, plus the stated reduction error on a reduced model
        reduction = result.reduction_error.get(spec, 0.0)
        words = f"at {plain(result.speed_at_largest[spec], 3)} rad/s"
        if reduction:
            words += (f"; error: time step {plain(result.largest_error[spec])} + reduction "
                      f"{plain(reduction)}")
        rows.append(Headline(f"{spec} largest peak to peak ({result.direction})", value, result.units[spec],
                             result.largest_error[spec] + reduction, words))
    return Summary(status=headline(result.status), run_time=result.run_time, rows=rows)


def _figures(result: RunUp) -> dict[str, Any]:
    return {"": result.plot, "_time": result.plot_time}


def run_up_cost(name, problem, options, workers):
    """The start (a shooting at the start speed, or a linear solve), the run and its coarse twin on
    the step the elastic periods set, and the steady-state curve."""
    values = {SPEED: options["start"]}
    sizes = cost.sizes_at(problem, values)
    dt, _, _ = time_step(problem, {}, options["start"], options["stop"], options["n_steps"],
                          options["mode_steps"], options["max_harmonic"])
    run_steps = options["duration"] / dt * (1.75 if options["estimate_error"] else 1.0)   # dt, 2 dt, 4 dt
    start_steps = max(32, int(2.0 * math.pi / options["start"] / dt))
    seconds = cost.STUDY_SECONDS + cost.nonlinear_period_seconds(int(run_steps), sizes)
    if options["start_state"] == "nonlinear":
        seconds += cost.SHOOTING_PERIODS * cost.nonlinear_period_seconds(start_steps, sizes)
    build_bytes, build_seconds = cost.linearisation(options["curve_steps"], sizes)
    curve = options["curve_points"] * (build_seconds + cost.solve_seconds(options["curve_steps"], sizes))
    if options["nonlinear_curve"]:
        curve += options["curve_points"] * cost.SHOOTING_PERIODS * cost.nonlinear_period_seconds(
            options["curve_steps"], sizes)
    # a run keeps s, s', s'' and lam (r < n) at every step, and an observable or two: about 6 n doubles
    memory = max(build_bytes, 8.0 * 6.0 * run_steps * sizes.n)
    return cost.Estimate(name, memory, seconds + curve,
                         f"{int(run_steps)} steps of dt = {dt:.3g} s x {sizes.n} coordinates, "
                         f"{options['curve_points']} steady states")


def _warm_up(problem: Any) -> None:
    """Two revolutions of a run-up on the warm-up's coarse steps (the ramped drive law's path), by the
    fused step (``mechanisms.fused_step``: a run-up's many steps repay its compile), on the full
    element models: a reduced model runs the same kernels, and its reduction check is a linear
    study's."""
    if getattr(problem, "supports_nonlinear", False) and hasattr(problem, "mechanism"):
        speed = problem.parameters[SPEED]
        with mechanisms.fused_step(True):
            run_up(problem, start=speed, stop=1.1 * speed, duration=4.0 * math.pi / speed, n_steps=WARM_UP_STEPS,
                   mode_steps=8, start_state="linear", curve_points=0, estimate_error=False, modes="full")


KIND = register_kind(StudyKind(
    name="run_up", result=RunUp,
    keys=("start", "stop", "duration", "profile", "start_state", "n_steps", "mode_steps", "max_harmonic",
          "curve_points", "curve_steps", "nonlinear_curve", "estimate_error", "run_down", "modes"),
    check=_check, run=_run, summary=_summary, headlines=_headlines, figures=_figures, cost=run_up_cost,
    warm_up=_warm_up))
