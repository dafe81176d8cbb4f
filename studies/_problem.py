"""What a study needs from a model: a linear periodic system at given parameter values.

A *problem* is any picklable object with

* ``name`` (str) and ``text`` (str, the scene description stored with the results);
* ``parameters`` (dict name -> nominal value, SI units) including ``"speed"`` (crank speed, rad/s);
* ``units`` (dict name -> unit of each parameter);
* ``resolve(values) -> dict``: the nominal parameters overridden by ``values`` (a dict of parameter
  values), checked (``StudiesError`` naming an unknown parameter);
* ``describe(values=None) -> Description``: the names of the coordinates, the observables and
  their units at ``values``, without linearising (results carry them);
* ``linearize(values, *, n_steps, context=True) -> Linear``; ``context=False`` may skip what only
  the nonlinear route needs;
* optionally ``simulate(linear, x0, v0, *, n_periods, steps_per_period) -> NonlinearRun``, the full
  nonlinear model at the parameters of ``linear`` started from its independent coordinates
  ``x0, v0`` at t = 0 (needed only by the nonlinear check).

Two kinds ship here: :class:`PeriodicProblem` (a time-periodic linear system written down directly,
optionally with a nonlinear force, integrated by scipy for the nonlinear route) and, in
``studies._mechanism``, the problem of a mechanism scene (``linearize.about``).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

import numpy as np

import periodic

from ._errors import ComputationError, StudiesError

SPEED = "speed"


@dataclass(frozen=True)
class Description:
    """What a problem's linear systems are made of, known without linearising: ``labels`` (m,) the
    names of the coordinates, ``observables`` (n_obs,) the observable specs and ``units`` (n_obs,)
    the unit of each (the same as the ``Linear`` of ``linearize`` at the same values)."""

    labels: tuple[str, ...]
    observables: tuple[str, ...]
    units: tuple[str, ...]


@dataclass(frozen=True, eq=False)
class Linear:
    """The linear periodic system of a problem at one set of parameter values.

    Attributes
    ----------
    system : periodic.PeriodicSystem
        ``M z'' + C z' + K z = f`` on ``N + 1`` samples over the period.
    crank_angle : ndarray (N+1,)
        Drive angle at the samples, rad (``speed * t`` for a constant-rate drive).
    labels : tuple[str, ...] (m,)
        Names of the coordinates ``z``.
    observables : tuple[str, ...] (n_obs,)
        Names (specs) of the observables.
    units : tuple[str, ...] (n_obs,)
        Unit of each observable.
    gains : ndarray (N+1, n_obs, m)
        ``observable_k(t_i) = gains[i, k] @ z(t_i)`` (observables are linear in ``z``).
    context : object
        What the nonlinear route and drawings need: the ``linearize`` result for mechanisms (None
        when linearised with ``context=False``), the resolved parameter dict for periodic problems.
    linear_range : callable or None
        ``linear_range(z) -> linearize.LinearRange``: the linear-range measures of a solution ``z``
        (N+1, m) per elastic link (mechanisms; None for problems without links).
    """

    system: periodic.PeriodicSystem
    crank_angle: np.ndarray
    labels: tuple[str, ...]
    observables: tuple[str, ...]
    units: tuple[str, ...]
    gains: np.ndarray
    context: Any = None
    linear_range: Callable[[np.ndarray], Any] | None = None

    def observe(self, z: np.ndarray, *, stride: int = 1) -> np.ndarray:
        """Observables of ``z`` (N/stride + 1, m) sampled every ``stride`` samples: (N/stride + 1, n_obs)."""
        return np.einsum("tkm,tm->tk", self.gains[::stride], z)


@dataclass(frozen=True)
class NonlinearRun:
    """A run of the full nonlinear model.

    ``t`` (n_t,) s; ``observables`` dict spec -> (n_t,) deviation from the nominal motion in the
    observable's unit; ``run_time`` s; ``error`` dict spec -> estimated max integration error (NaN when
    unknown); ``message`` what the integrator said.
    """

    t: np.ndarray
    observables: Mapping[str, np.ndarray]
    run_time: float
    error: Mapping[str, float] = field(default_factory=dict)
    message: str = ""


@dataclass(frozen=True)
class PeriodicCoefficients:
    """Continuous coefficients of ``M(t) x'' + C(t) x' + K(t) x = f(t)`` with period ``period`` (s):
    callables of scalar t returning (m, m) or (m,) arrays."""

    period: float
    mass: Callable[[float], np.ndarray]
    damping: Callable[[float], np.ndarray]
    stiffness: Callable[[float], np.ndarray]
    force: Callable[[float], np.ndarray]


@dataclass(frozen=True)
class PeriodicProblem:
    """A periodic linear system written down directly (no mechanism), for studies and tests.

    ``coefficients(values) -> PeriodicCoefficients`` must be a top-level function (picklable) of the
    parameter dict; ``parameters`` and ``units`` are ``((name, value), ...)`` and ``((name, unit), ...)``
    pairs and must include ``"speed"`` (rad/s, ``2 pi / period``); ``observables`` is
    ``((spec, unit, row), ...)`` with ``row`` the (m,) weights of ``observable = row @ x``;
    ``nonlinear_force(values, t, x, v) -> (m,)``, if given, is added to the left-hand side for the
    nonlinear route (``M x'' + C x' + K x + g(t, x, v) = f``), integrated by scipy's DOP853.
    """

    name: str
    coefficients: Callable[[Mapping[str, float]], PeriodicCoefficients]
    parameter_values: tuple[tuple[str, float], ...]
    parameter_units: tuple[tuple[str, str], ...]
    observable_rows: tuple[tuple[str, str, tuple[float, ...]], ...]
    labels: tuple[str, ...]
    nonlinear_force: Callable | None = None
    text: str = ""

    def __post_init__(self) -> None:
        names = [name for name, _ in self.parameter_values]
        if SPEED not in names:
            raise StudiesError(f"PeriodicProblem {self.name!r}: parameters must include {SPEED!r} "
                             f"(rad/s), got {names}")
        if sorted(names) != sorted(name for name, _ in self.parameter_units):
            raise StudiesError(f"PeriodicProblem {self.name!r}: parameter_units must name the same "
                             f"parameters as parameter_values ({names})")
        for spec, _, row in self.observable_rows:
            if len(row) != len(self.labels):
                raise StudiesError(f"PeriodicProblem {self.name!r}: observable {spec!r} has {len(row)} "
                                 f"weights for {len(self.labels)} coordinates")

    @property
    def parameters(self) -> dict[str, float]:
        return dict(self.parameter_values)

    @property
    def units(self) -> dict[str, str]:
        return dict(self.parameter_units)

    def resolve(self, values: Mapping[str, float] | None) -> dict[str, float]:
        """Nominal parameters overridden by ``values``; unknown names raise ``StudiesError``."""
        return resolve_values(self.name, self.parameters, values)

    def describe(self, values: Mapping[str, float] | None = None) -> Description:
        """The coordinate labels, observables and their units (the same at every parameter value)."""
        return Description(labels=tuple(self.labels),
                           observables=tuple(spec for spec, _, _ in self.observable_rows),
                           units=tuple(unit for _, unit, _ in self.observable_rows))

    def linearize(self, values: Mapping[str, float] | None = None, *, n_steps: int,
                  context: bool = True) -> Linear:
        """The sampled system at ``values``; its ``context`` is the resolved parameter dict (the
        ``context`` argument is accepted for the problem protocol)."""
        params = self.resolve(values)
        coefficients = self.coefficients(params)
        system = periodic.PeriodicSystem.from_functions(
            coefficients.period, coefficients.mass, coefficients.damping, coefficients.stiffness,
            coefficients.force, n_steps=n_steps)
        rows = np.array([row for _, _, row in self.observable_rows], dtype=float).reshape(
            len(self.observable_rows), len(self.labels))
        gains = np.ascontiguousarray(np.broadcast_to(rows, (n_steps + 1,) + rows.shape))
        names = self.describe()
        return Linear(system=system, crank_angle=params[SPEED] * system.t, labels=names.labels,
                      observables=names.observables, units=names.units, gains=gains, context=params)

    @property
    def supports_nonlinear(self) -> bool:
        return self.nonlinear_force is not None

    def simulate(self, linear: Linear, x0: np.ndarray, v0: np.ndarray, *, n_periods: int,
                 steps_per_period: int) -> NonlinearRun:
        """Integrate ``M x'' + C x' + K x + g = f`` at the parameters of ``linear`` from ``(x0, v0)`` at
        t = 0 with DOP853 (rtol 1e-10)."""
        from scipy.integrate import solve_ivp

        if self.nonlinear_force is None:
            raise StudiesError(f"problem {self.name!r} has no nonlinear model (nonlinear_force=None)")
        params = linear.context
        coefficients = self.coefficients(params)
        force = self.nonlinear_force
        m = len(self.labels)

        def rhs(t, state):
            x, v = state[:m], state[m:]
            load = (coefficients.force(t) - coefficients.damping(t) @ v - coefficients.stiffness(t) @ x
                    - force(params, t, x, v))
            return np.concatenate([v, np.linalg.solve(coefficients.mass(t), load)])

        start = time.perf_counter()
        t_eval = np.arange(n_periods * steps_per_period + 1) * (coefficients.period / steps_per_period)
        solution = solve_ivp(rhs, (0.0, t_eval[-1]), np.concatenate([x0, v0]), method="DOP853",
                             t_eval=t_eval, rtol=1e-10, atol=1e-12)
        if not solution.success:
            raise ComputationError(f"problem {self.name!r}: nonlinear run failed: {solution.message}")
        run_time = time.perf_counter() - start
        x = solution.y[:m].T
        observables = {spec: x @ np.asarray(row, dtype=float) for spec, _, row in self.observable_rows}
        # DOP853 at rtol 1e-10 is far more accurate than the Newmark results it is compared with.
        return NonlinearRun(t=t_eval, observables=observables, run_time=run_time,
                            error={spec: float("nan") for spec in observables},
                            message=solution.message)


def resolve_values(name: str, nominal: Mapping[str, float],
                   values: Mapping[str, float] | None) -> dict[str, float]:
    """``nominal`` with ``values`` substituted; every value a finite real number of a known name."""
    params = dict(nominal)
    for key, value in (values or {}).items():
        if key not in params:
            import difflib

            close = difflib.get_close_matches(str(key), list(params), n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise StudiesError(f"problem {name!r} has no parameter {key!r}{hint} "
                             f"(parameters: {sorted(params)})")
        if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
                or not math.isfinite(float(value)):
            raise StudiesError(f"parameter {key!r}: expected a finite number, got {value!r}")
        params[key] = float(value)
    return params


# ---------------------------------------------------------------------------------------------------
# The damped, forced Mathieu (optionally Duffing) oscillator: the numbers of every study are known
# for it in closed form or from scipy.special.mathieu_a / mathieu_b.
# ---------------------------------------------------------------------------------------------------
def _mathieu_coefficients(values: Mapping[str, float]) -> PeriodicCoefficients:
    """``x'' + 2 zeta w0 x' + w0^2 (1 + eps cos(W t)) x = F cos(W t)``, period ``2 pi / W``."""
    w0, zeta, eps = values["natural_frequency"], values["damping_ratio"], values["epsilon"]
    speed, amplitude = values[SPEED], values["force"]
    if speed <= 0.0:
        raise StudiesError(f"parameter 'speed': expected a positive number (rad/s), got {speed}")
    return PeriodicCoefficients(
        period=2.0 * math.pi / speed,
        mass=lambda t: np.eye(1),
        damping=lambda t: np.array([[2.0 * zeta * w0]]),
        stiffness=lambda t: np.array([[w0**2 * (1.0 + eps * math.cos(speed * t))]]),
        force=lambda t: np.array([amplitude * math.cos(speed * t)]))


def _cubic_force(values: Mapping[str, float], t: float, x: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Duffing hardening ``g = kappa x^3``."""
    return values["cubic"] * x**3


def mathieu_problem(*, speed: float = 1.0, natural_frequency: float = 1.0, damping_ratio: float = 0.02,
                    epsilon: float = 0.2, force: float = 1.0, cubic: float = 0.0) -> PeriodicProblem:
    """The damped, forced Mathieu oscillator ``x'' + 2 zeta w0 x' + w0^2 (1 + eps cos W t) x =
    F cos W t`` (SI: x in m, W = ``speed`` rad/s), with Duffing term ``cubic * x^3`` for the
    nonlinear route. Observable ``"x"`` (m)."""
    values = (("speed", speed), ("natural_frequency", natural_frequency),
              ("damping_ratio", damping_ratio), ("epsilon", epsilon), ("force", force),
              ("cubic", cubic))
    units = (("speed", "rad/s"), ("natural_frequency", "rad/s"), ("damping_ratio", "1"),
             ("epsilon", "1"), ("force", "m/s^2"), ("cubic", "1/(m^2 s^2)"))
    text = ("x'' + 2 zeta w0 x' + w0^2 (1 + epsilon cos(speed t)) x + cubic x^3 = force cos(speed t)\n"
            + "\n".join(f"{name} = {value!r}" for name, value in values) + "\n")
    return PeriodicProblem(name="mathieu", coefficients=_mathieu_coefficients, parameter_values=values,
                           parameter_units=units, observable_rows=(("x", "m", (1.0,)),),
                           labels=("x",), nonlinear_force=_cubic_force, text=text)
