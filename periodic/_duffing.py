"""A reference nonlinear system and its period map: the forced, parametrically pumped Duffing oscillator

    x'' + c x' + (k + e cos(Omega t)) x + k3 x^3 = F cos(Omega t),   T = 2 pi / Omega,

integrated over one period by Newmark's average-acceleration rule (the trapezoidal scheme of
``periodic``, order 2) with a Newton iteration per step, and its monodromy: the exact derivative of
the discrete step map by the implicit function theorem, multiplied over the N steps.  That is the
structure of a mechanism's period map (a fixed-step implicit integrator on nonlinear equations), in
one degree of freedom.  With ``k = w0^2`` and ``c = 2 zeta w0`` it is the textbook Duffing oscillator;
with ``F = 0`` and ``e != 0`` the damped Mathieu-Duffing equation, whose trivial orbit loses stability
by period doubling on the principal tongue ``k ~ (Omega / 2)^2``.

The step (``h = T / N``, state ``(x, v)``, acceleration from the equation of motion):
``x1 = x0 + h v0 + h^2/4 (a0 + a1)``, ``v1 = v0 + h/2 (a0 + a1)``, so ``v1 = 2 (x1 - x0) / h - v0`` and
``a1 = 4 (x1 - x0 - h v0) / h^2 - a0``, and ``x1`` solves the scalar equation
``R(x1) = a1 + c v1 + k(t1) x1 + k3 x1^3 - F cos(Omega t1) = 0``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

import numpy as np

from ._system import PeriodicError, ShootingError, check_real

#: Newton on each step's scalar equation stops when the correction is below this fraction of the
#: state's size (plus 1e-300): the map is then exact to rounding, so its monodromy is the derivative.
_STEP_TOL = 1e-14
_STEP_ITERATIONS = 30


@dataclass(frozen=True)
class Duffing:
    """``x'' + damping x' + (stiffness + pump cos(omega t)) x + cubic x^3 = force cos(omega t)``.

    Attributes (SI: x in m, t in s, per unit mass)
    ----------
    stiffness : float
        ``k = w0^2``, 1/s^2.
    damping : float
        ``c = 2 zeta w0``, 1/s.
    cubic : float
        ``k3``, 1/(m^2 s^2): > 0 hardening, < 0 softening.
    force : float
        ``F``, m/s^2.
    omega : float
        ``Omega``, rad/s: forcing and pump frequency, period ``2 pi / omega``.
    pump : float
        ``e``, 1/s^2: amplitude of the stiffness's ``cos(omega t)`` part (0: no parametric excitation).
    """

    stiffness: float = 1.0
    damping: float = 0.02
    cubic: float = 0.1
    force: float = 0.02
    omega: float = 1.0
    pump: float = 0.0

    def __post_init__(self):
        for field in fields(self):
            object.__setattr__(self, field.name, check_real(field.name, getattr(self, field.name)))
        if not self.omega > 0.0:
            raise PeriodicError(f"omega: expected a frequency > 0 rad/s, got {self.omega}")

    @property
    def period(self) -> float:
        """``2 pi / omega``, s."""
        return 2.0 * math.pi / self.omega

    def acceleration(self, t, x, v):
        """``x''`` from the equation of motion at time ``t`` (s), works on scalars and arrays."""
        linear = self.stiffness + self.pump * np.cos(self.omega * t)
        return self.force * np.cos(self.omega * t) - self.damping * v - linear * x - self.cubic * x**3


class DuffingPeriodMap:
    """The period map of :class:`Duffing` on ``n_steps`` Newmark steps, with ``parameter`` (a field
    name of :class:`Duffing`) as the continuation parameter: ``period_map(state, value)`` ->
    ``(end_state (2,), monodromy (2, 2))`` for ``state = (x, v)`` at t = 0 (m, m/s).  Built by
    :func:`duffing_period_map`."""

    def __init__(self, system: Duffing, parameter: str, n_steps: int):
        self.system = system
        self.parameter = parameter
        self.n_steps = n_steps
        self.calls = 0

    def __repr__(self):
        return f"DuffingPeriodMap({self.system!r}, parameter={self.parameter!r}, n_steps={self.n_steps})"

    def at(self, value: float) -> Duffing:
        """The system with the parameter set to ``value``."""
        return replace(self.system, **{self.parameter: float(value)})

    def coarsened(self) -> "DuffingPeriodMap":
        """The same map on ``n_steps // 2`` steps (the N/2 run of an error estimate)."""
        if self.n_steps % 2 or self.n_steps < 4:
            raise PeriodicError(f"n_steps: expected an even number >= 4 to coarsen, got {self.n_steps}")
        return DuffingPeriodMap(self.system, self.parameter, self.n_steps // 2)

    def __call__(self, state, value):
        end, monodromy, _ = self._march(state, value, record=False)
        return end, monodromy

    def trajectory(self, state, value):
        """``t (N+1,)`` s and ``states (N+1, 2)``: the motion over one period from ``state``."""
        _, _, states = self._march(state, value, record=True)
        system = self.at(value)
        return np.arange(self.n_steps + 1) * (system.period / self.n_steps), states

    def _march(self, state, value, record):
        state = np.asarray(state, dtype=float)
        if state.shape != (2,):
            raise PeriodicError(f"state: expected shape (2,) (x, v), got {state.shape}")
        self.calls += 1
        system = self.at(value)
        c, k, e, k3, force, omega = (system.damping, system.stiffness, system.pump, system.cubic,
                                     system.force, system.omega)
        n = self.n_steps
        h = system.period / n
        x0, v0 = float(state[0]), float(state[1])
        # tangent of (x, v) with respect to the initial state, as plain floats (2 x 2)
        dx_dx, dx_dv, dv_dx, dv_dv = 1.0, 0.0, 0.0, 1.0
        states = np.empty((n + 1, 2)) if record else None
        if record:
            states[0] = x0, v0
        cosine0 = 1.0  # cos(omega t0), t0 = 0
        for step in range(1, n + 1):
            cosine1 = math.cos(2.0 * math.pi * step / n)  # cos(omega t1) with t1 = step h
            stiff0, stiff1 = k + e * cosine0, k + e * cosine1
            a0 = force * cosine0 - c * v0 - stiff0 * x0 - k3 * x0**3
            # Newton on R(x1) = 4 (x1 - x0 - h v0)/h^2 - a0 + c (2 (x1 - x0)/h - v0) + k(t1) x1 + k3 x1^3 - F cos
            x1 = x0 + h * v0 + 0.5 * h * h * a0  # explicit predictor
            for _ in range(_STEP_ITERATIONS):
                slope = 4.0 / (h * h) + 2.0 * c / h + stiff1 + 3.0 * k3 * x1 * x1
                residual = (4.0 * (x1 - x0 - h * v0) / (h * h) - a0 + c * (2.0 * (x1 - x0) / h - v0)
                            + stiff1 * x1 + k3 * x1**3 - force * cosine1)
                correction = residual / slope
                x1 -= correction
                if abs(correction) <= _STEP_TOL * (abs(x1) + h * abs(v0)) + 1e-300:
                    break
            else:
                raise ShootingError(f"Duffing step {step} of {n}: Newton did not converge (x = {x1:.6g})")
            if not math.isfinite(x1):
                raise ShootingError(f"Duffing step {step} of {n}: the state is not finite")
            slope = 4.0 / (h * h) + 2.0 * c / h + stiff1 + 3.0 * k3 * x1 * x1
            # implicit function theorem: dR/dx1 dx1 = -(dR/dx0 + dR/da0 da0/dx0) dx0 - (...) dv0 with
            # dR/dx0 = -4/h^2 - 2c/h, dR/dv0 = -4/h - c, dR/da0 = -1, da0/dx0 = -(k(t0) + 3 k3 x0^2), da0/dv0 = -c
            step_xx = (4.0 / (h * h) + 2.0 * c / h - stiff0 - 3.0 * k3 * x0 * x0) / slope
            step_xv = (4.0 / h) / slope
            new_dx_dx = step_xx * dx_dx + step_xv * dv_dx
            new_dx_dv = step_xx * dx_dv + step_xv * dv_dv
            # v1 = 2 (x1 - x0)/h - v0
            dv_dx = 2.0 * (new_dx_dx - dx_dx) / h - dv_dx
            dv_dv = 2.0 * (new_dx_dv - dx_dv) / h - dv_dv
            dx_dx, dx_dv = new_dx_dx, new_dx_dv
            v0 = 2.0 * (x1 - x0) / h - v0
            x0 = x1
            cosine0 = cosine1
            if record:
                states[step] = x0, v0
        return np.array([x0, v0]), np.array([[dx_dx, dx_dv], [dv_dx, dv_dv]]), states


def duffing_period_map(parameter: str = "omega", *, n_steps: int = 256, **values) -> DuffingPeriodMap:
    """The period map of the Duffing oscillator (see :class:`Duffing`: ``stiffness``, ``damping``,
    ``cubic``, ``force``, ``omega``, ``pump`` as keyword ``values``, defaults otherwise) on ``n_steps``
    Newmark steps per period, with ``parameter`` (one of those names) as its second argument:

    >>> period_map = duffing_period_map("omega", n_steps=128, damping=0.01, cubic=0.2, force=0.005)
    >>> end_state, monodromy = period_map(np.zeros(2), 1.02)    # (2,), (2, 2)

    A :data:`PeriodMap` for :func:`periodic.find_orbit` and :func:`periodic.continue_orbits`;
    ``.coarsened()`` is the same map on N/2 steps (for ``find_orbit(..., estimate=...)``),
    ``.trajectory(state, value)`` the motion over one period."""
    names = [field.name for field in fields(Duffing)]
    if parameter not in names:
        raise PeriodicError(f"parameter: expected one of {', '.join(names)}, got {parameter!r}")
    unknown = sorted(set(values) - set(names))
    if unknown:
        raise TypeError(f"duffing_period_map: unknown values {', '.join(unknown)}; expected {', '.join(names)}")
    if isinstance(n_steps, bool) or not isinstance(n_steps, (int, np.integer)) or n_steps < 2:
        raise PeriodicError(f"n_steps: expected an integer >= 2, got {n_steps!r}")
    return DuffingPeriodMap(Duffing(**values), parameter, int(n_steps))
