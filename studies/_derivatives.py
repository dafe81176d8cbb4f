"""Derivatives of a steady state's headlines with respect to a problem's parameters at one point:
what ``studies.sensitivity`` reports and ``studies.optimize``'s local method follows.

For each parameter p the coefficients' derivative is analytic where a part of the mechanism carries it
(``linearize.analytic_derivative``: a link's damping and Young's modulus, a controller's gains, with no
second linearisation, and an elastic link's section on prescribed drives, exact by the coefficients'
affinity in its mass from one linearisation on the point's kinematics; the maps they move differentiated
on the point's motion, ``linearize.map_derivatives``),
else it comes from
linearisations at nearby values (``linearize.coefficient_derivative``: a forward difference where the
nominal configuration does not move, else a central one; the speed's central difference on a speed
family is exact, its coefficients being polynomials in the speed), and the response's from
``periodic.response_derivative`` (the periodic system with the forcing of those derivatives, on the
shooting's monodromy).  An observable ``o_p(z)`` depends on p through its map too, so its derivative is
``(o_{p+h}(z + h dz) - o_{p-h}(z - h dz)) / 2h`` (or the forward form), a difference of the maps only
(the response's derivative enters exactly).  The headlines' derivatives follow by the envelope rule:
a peak's is the observable's derivative at the instant of the extreme (the parabola through the
sampled extreme and its neighbours, as ``studies._numerics.extremes`` refines the value); the
peak-to-peak's the difference of those at the maximum and the minimum; the RMS's
``mean(o do) / rms``.  Each is computed on the N- and the N/2-step solution: ``error_factor`` times the
difference is its error estimate.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np

import linearize
import periodic

from ._errors import StudiesError
from ._numerics import Steady, solve_steady, study_scheme
from ._problem import SPEED

#: The headlines differentiated, in the order the tables and figures show them.
HEADLINES = ("peak_to_peak", "peak", "rms")


@dataclass(frozen=True, eq=False)
class PointDerivatives:
    """The derivatives at one point.

    ``linear`` and ``steady``: the point's linear system and steady state; ``names`` (P,) the parameters;
    ``values`` {name: value}; ``response`` (N+1, n_obs) the observables; ``derivative`` (P, N+1, n_obs) and
    ``coarse_derivative`` (P, N/2+1, n_obs) their derivatives (N and N/2 steps); ``coarse_response``
    (N/2+1, n_obs); ``radius``, ``radius_error`` (P,) d|mu|/dp of the critical multiplier; ``repeated``:
    the multiplier is repeated (radius NaN); ``methods`` {name: "analytic" | "forward" | "central"};
    ``steps`` {name: absolute step, 0 for an analytic derivative}; ``error_factor``; ``run_time`` of the
    derivatives (s, without the point's own steady state: ``steady.run_time`` and ``linear_run_time``)."""

    linear: object
    steady: Steady
    names: tuple[str, ...]
    values: dict
    response: np.ndarray
    coarse_response: np.ndarray
    derivative: np.ndarray
    coarse_derivative: np.ndarray
    radius: np.ndarray
    radius_error: np.ndarray
    repeated: bool
    radius_message: str
    methods: dict
    steps: dict
    error_factor: float
    linear_run_time: float
    run_time: float


def _keeps_configuration(problem, params, name, linear) -> bool:
    """Whether a forward step of parameter ``name`` leaves the point's nominal configuration alone
    (``linearize.keeps_configuration`` on the mechanism at the step); a problem without a mechanism has
    no nominal motion whose Newton tolerance would enter the difference (its coefficients are closed
    forms): True."""
    if not callable(getattr(problem, "mechanism", None)):
        return True
    nominal = getattr(linear.context, "nominal", None)
    if nominal is None:
        return False
    step = linearize.parameter_step(params[name], linearize.FORWARD_STEP)
    changed = {key: value for key, value in params.items() if value != problem.parameters.get(key)}
    changed[name] = params[name] + step
    return linearize.keeps_configuration(problem.mechanism(changed), nominal)


@dataclass(frozen=True, eq=False)
class _Maps:
    """The derivatives {spec: ``linearize.ObservableMap``} of the observable maps an analytic parameter
    moves (``linearize.map_derivatives``, per unit of it); ``plus(linear, h)`` and ``minus(linear, h)``
    the point's ``linear`` with its maps at p + h and p - h (they are affine in the parameter)."""

    derivatives: dict

    def plus(self, linear, h):
        return self._at(linear, h)

    def minus(self, linear, h):
        return self._at(linear, -h)

    def _at(self, linear, offset):
        if not self.derivatives:
            return linear
        moved = []
        for spec, here in zip(linear.observables, linear.maps):
            slope = self.derivatives.get(spec)
            mine = here.arrays()
            changes = {} if slope is None else slope.arrays()
            moved.append(here.with_arrays({key: mine.get(key, 0.0) + offset * change
                                           for key, change in changes.items()}) if changes else here)
        return replace(linear, maps=tuple(moved))


def _analytic_maps(problem, params, name, linear) -> _Maps:
    """The derivatives of the maps ``name`` moves (``linearize.map_derivatives``; none for a damping key,
    or without a force, torque or stress observed: no mechanism built), for ``E`` from the mechanism at
    a step ``CENTRAL_STEP``."""
    if not linearize.moves_maps(linear.context, name):
        return _Maps({})
    step = linearize.parameter_step(params[name], linearize.CENTRAL_STEP)
    changed = {key: value for key, value in params.items() if value != problem.parameters.get(key)}
    changed[name] = params[name] + step
    return _Maps(linearize.map_derivatives(linear.context, name, problem.mechanism(changed), step))


def _neighbour(problem, values, n_steps, linear):
    """The linearisation at ``values``, a forward step of a parameter that leaves the linkage alone:
    on the point's own kinematics where the problem reuses them (only the inverse dynamics and the
    coefficients recomputed), else the problem's own."""
    nominal = getattr(linear.context, "nominal", None)
    if nominal is not None and getattr(problem, "reuses_kinematics", False):
        return problem.linearize(values, n_steps=n_steps, kinematics=nominal)
    return problem.linearize(values, n_steps=n_steps)


def _forward(known: dict | None, name: str, decide) -> bool:
    """Whether ``name`` takes a forward difference: ``known[name]``, else ``decide()`` (remembered)."""
    if known is not None and name in known:
        return known[name]
    found = decide()
    if known is not None:
        known[name] = found
    return found


def point_derivatives(problem, values, names, *, n_steps: int, scheme: str, linear=None,
                      steady: Steady | None = None, estimate_error: bool = True,
                      multiplier: bool = True, forward: dict | None = None) -> PointDerivatives:
    """The derivatives of the steady state of ``problem`` at ``values`` with respect to ``names``
    (parameters of the problem), on ``n_steps`` steps with the scheme named ``scheme``; ``linear`` and
    ``steady`` when already computed at that point; ``estimate_error=False`` skips the N/2 derivatives
    (``coarse_*`` None, errors NaN), ``multiplier=False`` the radius's (NaN); ``forward`` {name: bool}
    whether a parameter's forward difference is accurate (it leaves the kinematics alone), known from an
    earlier point (filled in here for the others)."""
    started = time.perf_counter()
    params = problem.resolve(values)
    base_values = dict(values or {})
    derivatives, neighbours, methods, steps = [], [], {}, {}
    names = tuple(names)
    # the speed first: its neighbours build the speed family (prescribed drives), whose base is then the
    # point's own linearisation (not a second one)
    order = sorted(range(len(names)), key=lambda j: names[j] != SPEED)
    pending = {}
    for j in order:
        name = names[j]
        if name != SPEED:
            continue
        step = linearize.parameter_step(params[name], linearize.CENTRAL_STEP)
        pending[name] = (problem.linearize(dict(base_values, **{name: params[name] + step}), n_steps=n_steps),
                         problem.linearize(dict(base_values, **{name: params[name] - step}), n_steps=n_steps),
                         step, "central")
    if linear is None:
        linear = problem.linearize(base_values, n_steps=n_steps)
    linear_run_time = time.perf_counter() - started
    if steady is None:
        steady = solve_steady(linear, scheme)
    started = time.perf_counter()
    system = linear.system
    for name in names:
        closed = None if name in pending else linearize.analytic_derivative(linear.context, name)
        if closed is not None:
            # a part carries the derivative: no linearisation at a neighbouring value; the maps it moves
            # (a drive torque, a stress) are differentiated on the point's motion
            methods[name], steps[name] = "analytic", 0.0
            derivatives.append(closed)
            neighbours.append(_analytic_maps(problem, params, name, linear))
            continue
        if name in pending:
            plus, minus, step, methods[name] = pending[name]
            divisor = 2.0 * step
        elif _forward(forward, name, lambda name=name: _keeps_configuration(problem, params, name, linear)):
            step = linearize.parameter_step(params[name], linearize.FORWARD_STEP)
            plus = _neighbour(problem, dict(base_values, **{name: params[name] + step}), n_steps, linear)
            minus, methods[name], divisor = linear, "forward", step
        else:
            step = linearize.parameter_step(params[name], linearize.CENTRAL_STEP)
            plus = problem.linearize(dict(base_values, **{name: params[name] + step}), n_steps=n_steps)
            minus = problem.linearize(dict(base_values, **{name: params[name] - step}), n_steps=n_steps)
            methods[name], divisor = "central", 2.0 * step
        if plus.system.n_dof != system.n_dof or tuple(plus.labels) != tuple(linear.labels):
            raise StudiesError(f"parameter {name!r}: a change of {step:g} changes the coordinates "
                               f"({len(linear.labels)} -> {len(plus.labels)}): not a continuous parameter")
        steps[name] = step
        derivatives.append(linearize.coefficient_derivative(plus.system, minus.system, divisor))
        neighbours.append((plus, minus, divisor, minus is linear))
    found = periodic.response_derivative(system, steady.state, derivatives, scheme=study_scheme(scheme),
                                         estimate_error=estimate_error, multiplier=multiplier)
    state = steady.state
    response = steady.response
    dz, dz_coarse = found.x, found.x_coarse
    derivative = np.empty((len(names),) + response.shape)
    coarse_response = coarse_derivative = None
    levels = [(derivative, state.x, dz, 1)]
    if estimate_error:
        coarse_response = linear.observe(state.x_coarse, stride=2)
        coarse_derivative = np.empty((len(names),) + coarse_response.shape)
        levels.append((coarse_derivative, state.x_coarse, dz_coarse, 2))
    for j, neighbour in enumerate(neighbours):
        if methods[names[j]] == "analytic":
            # the maps are the point's or, where the parameter moves them, theirs at p +- h (affine in
            # it, exactly); a central difference along dz (a force's magnitude is not linear in z; the
            # step's truncation is (h/p)^2 = 1e-8 of the derivative)
            h = linearize.parameter_step(params[names[j]], linearize.CENTRAL_STEP)
            upper, lower = neighbour.plus(linear, h), neighbour.minus(linear, h)
            for out, z, dz_level, stride in levels:
                out[j] = (upper.observe(z + h * dz_level[j], stride=stride)
                          - lower.observe(z - h * dz_level[j], stride=stride)) / (2.0 * h)
            continue
        plus, minus, divisor, forward = neighbour
        # h dz moves z to first order as the parameter's step does; the maps' own change is differenced
        h = steps[names[j]]
        for out, z, dz_level, stride in levels:
            dzj = dz_level[j]
            upper = plus.observe(z + h * dzj, stride=stride)
            lower = minus.observe(z, stride=stride) if forward else minus.observe(z - h * dzj, stride=stride)
            out[j] = (upper - lower) / divisor
    return PointDerivatives(linear=linear, steady=steady, names=tuple(names), values=params, response=response,
                            coarse_response=coarse_response, derivative=derivative,
                            coarse_derivative=coarse_derivative, radius=found.radius,
                            radius_error=found.radius_error, repeated=found.repeated,
                            radius_message=found.message, methods=methods, steps=steps,
                            error_factor=state.error_factor, linear_run_time=linear_run_time,
                            run_time=time.perf_counter() - started)


# ---------------------------------------------------------------------------------------------------
# headlines by the envelope rule
# ---------------------------------------------------------------------------------------------------
def _extreme(samples: np.ndarray, sign: float) -> tuple[int, float]:
    """Index of the sampled maximum of ``sign * samples[:-1]`` and the parabola's offset (samples) of the
    refined extreme (``studies._numerics.extremes``)."""
    values = samples[:-1]
    n = values.size
    i = int(np.argmax(sign * values))
    left, centre, right = values[(i - 1) % n], values[i], values[(i + 1) % n]
    curvature = left - 2.0 * centre + right
    return i, 0.0 if curvature == 0.0 else 0.5 * (left - right) / curvature


def _at(samples: np.ndarray, i: int, offset: float) -> np.ndarray:
    """``samples[..., i + offset]`` (last axis periodic, t_N repeating t_0) by the parabola through
    samples i - 1, i, i + 1."""
    values = samples[..., :-1]
    n = values.shape[-1]
    left, centre, right = values[..., (i - 1) % n], values[..., i], values[..., (i + 1) % n]
    return centre + 0.5 * offset * (right - left) + 0.5 * offset**2 * (right - 2.0 * centre + left)


def _second_extreme(samples: np.ndarray, sign: float, i: int) -> float:
    """The largest of ``sign * samples`` over local maxima other than the one at ``i`` (-inf if none)."""
    values = sign * samples[:-1]
    before, after = np.roll(values, 1), np.roll(values, -1)
    peaks = np.flatnonzero((values >= before) & (values >= after))
    n = values.size
    far = [k for k in peaks if min(abs(k - i), n - abs(k - i)) > 1]
    return float(values[far].max()) if far else -math.inf


def headline_derivatives(response: np.ndarray, derivative: np.ndarray,
                         response_error: np.ndarray | None = None) -> tuple[dict, list]:
    """``({headline: (P, n_obs)}, switches)`` of a periodic ``response`` (N+1, n_obs) and its
    derivatives (P, N+1, n_obs) for each of :data:`HEADLINES`; ``switches``: (headline, k, instants) for
    each observable k whose extreme has a rival, another local extreme within twice the response's
    error ``response_error`` (n_obs,) or 1e-9 of the range: which instant holds the extreme is then
    not known, and the derivative is one-sided there (the extreme switches instant)."""
    n_p, _, n_obs = derivative.shape
    out = {name: np.empty((n_p, n_obs)) for name in HEADLINES}
    switches = []
    for k in range(n_obs):
        y, dy = response[:, k], derivative[:, :, k]
        (i_hi, o_hi), (i_lo, o_lo) = _extreme(y, 1.0), _extreme(y, -1.0)
        d_hi, d_lo = _at(dy, i_hi, o_hi), _at(dy, i_lo, o_lo)
        high, low = _at(y, i_hi, o_hi), _at(y, i_lo, o_lo)
        out["peak_to_peak"][:, k] = d_hi - d_lo
        out["peak"][:, k] = d_hi if abs(high) >= abs(low) else -d_lo
        rms = math.sqrt(float(np.mean(y[:-1] ** 2)))
        out["rms"][:, k] = (dy[:, :-1] @ y[:-1]) / (y.size - 1) / rms if rms > 0.0 else np.nan
        width = max(high - low, 1e-300)
        tol = max(1e-9 * width, 0.0 if response_error is None else 2.0 * float(response_error[k]))
        for name, sign, i, value in (("peak_to_peak", 1.0, i_hi, high), ("peak_to_peak", -1.0, i_lo, -low)):
            if value - _second_extreme(y, sign, i) <= tol:
                switches.append((name, k, "two maxima" if sign > 0 else "two minima"))
        if abs(abs(high) - abs(low)) <= tol:
            switches.append(("peak", k, "the maximum and the minimum"))
    return out, switches


def headline_errors(point: PointDerivatives) -> tuple[dict, dict, list]:
    """``(values, errors, switches)``: each headline's derivative {headline: (P, n_obs)} on N steps, its
    error estimate ``error_factor * |D_N - D_{N/2}|`` and the extremes that switch instant."""
    fine, switches = headline_derivatives(point.response, point.derivative, point.steady.response_error)
    coarse, _ = headline_derivatives(point.coarse_response, point.coarse_derivative)
    errors = {name: point.error_factor * np.abs(fine[name] - coarse[name]) for name in HEADLINES}
    return fine, errors, switches
