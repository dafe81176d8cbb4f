"""``linearize.linearisation_error``: how far the linear periodic answer is from the periodic state of
the full nonlinear equations, by chord steps of the nonlinear periodic problem.

The full equations reduced to the independent coordinates ``z`` along a motion ``s(z)`` are

    g(z) = V(s)^T (M(s) s'' - Q(s, s', t)) = 0,      V(s) = [I; -Phi_d(s)^-1 Phi_i(s)],

(``V(s)^T Phi_s(s)^T = 0`` removes the multipliers, so none has to be guessed), where ``s(z)`` is the
nominal motion plus ``V0 z`` with the second-order axial shortening of stiffened links and the
dependent coordinates solved from the position constraints ``Phi(s, t) = 0`` (the linear answer
breaks them at second order: this projection puts it back on them). Its linearisation about the
nominal motion is the linear system ``L z - f = M z'' + C z' + K z - f``. Both are evaluated with
the same spectral derivatives of the sampled periodic ``z``, so their difference

    N(z) = g(z) - (M z'' + C z' + K z - f)

holds no time-step error (the integrator's own residual cancels) and, but for the geometric
stiffness (which the linear system takes from the nominal axial force and the full model from the
axial coordinates), only terms of second and higher order. The nonlinear periodic state solves
``L z = f - N(z)``: the chord (fixed-point) iteration ``z_(k+1) = z_lin - L^-1 N(z_k)`` from the
linear answer ``z_lin``. Its first step is the estimate where it moves every observable by less than
``SECOND_STEP_ABOVE`` of its peak-to-peak; elsewhere further steps, Anderson-accelerated (depth
one), run until one moves the observables by at most ``SETTLED`` of the correction (or of that
floor), at most ``MAX_STEPS``; a last step above ``MAX_CONTRACTION`` of it means the iteration does
not settle (near an instability or an exact resonance, or far outside the linear range), and the
term is unknown. ``N`` is evaluated on every stride-th sample (at least ``COARSEST_STEPS``) and
interpolated spectrally; ``L^-1`` is two single-column marches with the steady state's monodromy.
Checked against ``studies.nonlinear_steady_state`` in tests/test_budget.py.
"""

from __future__ import annotations

import copy
import time
import warnings
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

import mechanisms
import periodic

from ._about import _model_with_feedforward
from ._core import LinearizationError, interpolate_periodic, spectral_derivatives

__all__ = ["LinearisationError", "linearisation_error", "nonlinear_residual", "periodic_solve",
           "MAX_CONTRACTION", "SECOND_STEP_ABOVE"]

#: A chord iteration whose last step moves the observables by more than this fraction of the
#: correction has not settled: its estimate is not trusted (the term is unknown).
MAX_CONTRACTION = 0.25
#: The iteration stops once a step changes the observables by at most this fraction of the
#: correction so far.
SETTLED = 0.05
#: The fewest samples per period the residual is evaluated on (``_stride``; it is interpolated
#: spectrally to the N samples the chord steps solve on: the residual is smooth, and its evaluation
#: is the chord step's main cost).
COARSEST_STEPS = 64
#: Chord steps at most (each a residual and a periodic solve).
MAX_STEPS = 5
#: A second chord step is taken where the first changes an observable by more than this fraction
#: of its peak-to-peak (a quarter of the default error tolerance, 2 %): there the estimate's trust
#: can decide a status; below it the quadratic term is too small to matter.
SECOND_STEP_ABOVE = 0.005
#: Newton steps of the constraint projection (quadratic convergence from a second-order violation).
PROJECTION_STEPS = 6
#: Largest constraint violation (m, rad) left by the projection: far below any deflection.
PROJECTION_TOL = 1e-11
#: A violation below which one more Newton step is the last (it leaves about its square).
PROJECTION_LAST = 1e-6


@dataclass(frozen=True)
class LinearisationError:
    """The chord estimate of the linearisation error of a linear periodic state ``z`` (N+1, m).

    ``correction`` (N+1, m): the estimated nonlinear periodic state minus ``z`` (NaN where not
    trusted); ``change`` (N+1, n_obs): the observables' change through ``observe`` (NaN where not
    trusted); ``steps``: chord steps taken (1 or 2); ``contraction``: ``|z_2 - z_1| / |z_1 - z|``
    (NaN after one step); ``trusted``: the estimate can be used (``reason`` says why not);
    ``constraint_violation``: max |Phi| of ``nominal + V z`` before the projection (the linear
    answer's second-order violation, in the constraints' units); ``residual``: max |N(z)| (the
    reduced equations' units); ``method`` words; ``run_time`` s."""

    correction: np.ndarray
    change: np.ndarray
    steps: int
    contraction: float
    trusted: bool
    reason: str
    constraint_violation: float
    residual: float
    method: str
    run_time: float


def _model_of(lin: Any) -> Any:
    """The model whose equations the linearisation linearised: the nominal motion's (for a speed
    family's member the base speed's: the equations of a mechanism with prescribed drives depend
    on the speed only through the motion), or with torque drives the one with the nominal
    feedforward (``linearize._about``)."""
    return _model_with_feedforward(lin.mechanism, lin.nominal)


@dataclass(frozen=True)
class _Grid:
    """What the residual needs, on every ``stride``-th sample of the linearisation's grid: the
    model, the nominal motion ``t`` (K+1,), ``s0, sdot0, sddot0`` (K+1, n), the basis ``V``
    (K+1, n, m - L), the coordinates' partition, the periodic system (on the same samples), the
    constraint values along the nominal motion (``offset``) and the stiffened links' shortening."""

    model: Any
    t: np.ndarray
    s0: np.ndarray
    sdot0: np.ndarray
    sddot0: np.ndarray
    V: np.ndarray
    independent: np.ndarray
    dependent: np.ndarray
    system: Any
    offset: np.ndarray
    shortening: tuple


def _grid(lin: Any, system: Any, stride: int, model: Any = None) -> _Grid:
    model = _model_of(lin) if model is None else model
    nominal, c = lin.nominal, lin.coefficients
    pick = slice(None, None, stride)
    t = nominal.t[pick]
    s0 = nominal.s[pick]
    if stride > 1:
        system = periodic.PeriodicSystem(system.period, system.M[pick], system.C[pick],
                                         system.K[pick], system.f[pick])
    shortening = []
    for layout in model.layouts.values():
        if layout.shapes is None or not layout.stiffening or layout.membrane is None:
            continue
        slopes = layout.shapes.evaluate(layout.shapes.quadrature[0]).dw  # (n_gauss, n_e)
        shortening.append((layout.elastic, slopes.T, layout.membrane.T))
    # Phi(s, t) - Phi(s0, t) is the violation: the drive rows are linear in s and t and the others
    # free of t, so it holds whatever speed the model's drive law has (a speed family's member)
    offset = mechanisms.constraint_terms_along(model, t, s0, values=True).values
    return _Grid(model=model, t=t, s0=s0, sdot0=nominal.sdot[pick], sddot0=nominal.sddot[pick],
                 V=c.V[pick], independent=np.asarray(c.independent),
                 dependent=np.setdiff1d(np.arange(model.n_coords), c.independent), system=system,
                 offset=offset, shortening=tuple(shortening))


def _motion(grid: _Grid, z: np.ndarray) -> tuple[np.ndarray, ...]:
    """The full motion ``s, s', s''`` (K+1, n) of the independent coordinates ``z`` (K+1, m), on the
    constraints, the constraint Jacobian (K+1, r, n) there, and the largest violation of
    ``nominal + V z`` that the projection removed."""
    s = grid.s0 + np.einsum("kni,ki->kn", grid.V, z[:, :grid.V.shape[2]])
    for elastic, slopes, membrane in grid.shortening:
        # a bent stiffened link shortens its chord (``LinearizedMechanism.start_state``)
        q = s[:, elastic]
        s[:, elastic] = q - (0.5 * (q @ slopes) ** 2) @ membrane
    violation = 0.0
    dependent = grid.dependent
    for step in range(PROJECTION_STEPS):
        terms = mechanisms.constraint_terms_along(grid.model, grid.t, s, values=True)
        phi = terms.values - grid.offset
        worst = float(np.abs(phi).max())
        if step == 0:
            violation = worst
        if worst < PROJECTION_TOL:
            break
        s[:, dependent] -= np.linalg.solve(terms.jacobian[:, :, dependent], phi[:, :, None])[..., 0]
        if worst < PROJECTION_LAST:
            # Newton converges quadratically: this step leaves ~worst^2, far below PROJECTION_TOL
            break
    # the Jacobian of the last evaluation: the step after it moved s by at most PROJECTION_LAST
    deviation = s - grid.s0
    ddev, dddev, _ = spectral_derivatives(deviation, grid.system.period)
    return s, grid.sdot0 + ddev, grid.sddot0 + dddev, terms.jacobian, violation


def _residual(grid: _Grid, z: np.ndarray) -> tuple[np.ndarray, float]:
    s, sdot, sddot, jacobian, violation = _motion(grid, z)
    forces = mechanisms.inertia_residual_along(grid.model, grid.t, s, sdot, sddot)
    independent, dependent = grid.independent, grid.dependent
    # V(s)^T F = F_i - Phi_i^T Phi_d^-T F_d (the multipliers that make the dependent rows vanish)
    mu = np.linalg.solve(np.swapaxes(jacobian[:, :, dependent], 1, 2), forces[:, dependent, None])
    reduced = forces[:, independent] - np.einsum("kri,kr->ki", jacobian[:, :, independent], mu[..., 0])
    system = grid.system
    zdot, zddot, _ = spectral_derivatives(z, system.period)
    linear = (np.einsum("kij,kj->ki", system.M, zddot) + np.einsum("kij,kj->ki", system.C, zdot)
              + np.einsum("kij,kj->ki", system.K, z) - system.f)
    out = np.zeros_like(z)
    out[:, :reduced.shape[1]] = reduced - linear[:, :reduced.shape[1]]
    out[-1] = out[0]
    return out, violation


def nonlinear_residual(lin: Any, z: np.ndarray, *, system: Any = None) -> tuple[np.ndarray, float]:
    """``N(z)`` (N+1, m): the full equations' residual reduced to the independent coordinates along
    ``s(z)`` minus the linear system's residual of ``z`` (module docstring): zero to first order in
    ``z`` but for the geometric stiffness, which the linear system takes from the nominal axial
    force and the full model from the axial coordinates. ``system``: the periodic system ``z``
    solves (default ``lin.system``); the rows of lagged controllers' states are zero (their law is
    linear in the states). Returns ``(N(z), the constraint violation the projection removed)``."""
    system = lin.system if system is None else system
    z = _checked(z, system)
    return _residual(_grid(lin, system, 1), z)


def _checked(z: Any, system: Any) -> np.ndarray:
    z = np.asarray(z, dtype=float)
    if z.shape != system.f.shape:
        raise LinearizationError(f"z must have shape {system.f.shape} (samples, independent "
                                 f"coordinates); received shape {z.shape}")
    return z


def monodromy_of(system: Any, scheme: Any) -> np.ndarray:
    """The monodromy (s, s) of ``system``'s state ``[x; v[massive]]`` with ``scheme``: one march
    of the identity's columns (``periodic.Scheme.march``)."""
    n, n_state, massive = system.n_dof, system.n_state, system.massive
    x, v = np.zeros((n, n_state)), np.zeros((n, n_state))
    x[:, :n] = np.eye(n)
    v[massive, n + np.arange(massive.size)] = 1.0
    a = np.empty((n, n_state))
    empty = np.empty((0, n, n_state))
    _raise_on_singular(scheme.march(system, np.zeros(n_state), x, v, a, empty, empty, empty))
    return np.vstack((x[:, :n_state], v[massive, :n_state]))


def periodic_solve(system: Any, scheme: Any, monodromy: np.ndarray | None = None) -> np.ndarray:
    """The periodic solution ``x`` (N+1, n) of ``system`` with ``scheme``: with its ``monodromy``
    (the state transition over the period, ``periodic.SteadyState.monodromy`` of the same system and
    scheme, whose coefficients do not depend on the forcing) two single-column marches, the forced one
    from rest and the periodic one; without it ``periodic.steady_state`` (no error runs)."""
    if monodromy is None:
        with warnings.catch_warnings():
            # the steady state this corrects has said whatever there is to say about a resonance
            warnings.simplefilter("ignore", periodic.NearResonanceWarning)
            return periodic.steady_state(system, scheme=scheme, estimate_error=False).x
    n, massive = system.n_dof, system.massive
    x, v, a = np.zeros((n, 1)), np.zeros((n, 1)), np.empty((n, 1))
    empty = np.empty((0, n, 1))
    _raise_on_singular(scheme.march(system, np.ones(1), x, v, a, empty, empty, empty))
    end = np.concatenate((x[:, 0], v[massive, 0]))
    start = np.linalg.solve(np.eye(end.size) - monodromy, end)
    x = np.ascontiguousarray(start[:n, None])
    v = np.zeros((n, 1))
    v[massive, 0] = start[n:]
    samples = system.n_steps + 1
    xs, vs, as_ = np.empty((samples, n, 1)), np.empty((samples, n, 1)), np.empty((samples, n, 1))
    _raise_on_singular(scheme.march(system, np.ones(1), x, v, a, xs, vs, as_))
    return xs[:, :, 0]


def _forced(system: Any, force: np.ndarray) -> Any:
    """``system`` with the forcing ``force`` (N+1, n): a copy sharing its checked M, C, K (building a
    ``PeriodicSystem`` checks every mass sample again, which cost more than the chord step's march)."""
    forced = copy.copy(system)
    force = np.array(force, dtype=float)
    force[-1] = force[0]
    force.flags.writeable = False
    object.__setattr__(forced, "f", force)
    return forced


def _raise_on_singular(status: int) -> None:
    if status >= 0:
        raise periodic.ShootingError(f"a step matrix of the chord step is singular at sample {status}")


def _stride(n_steps: int) -> int:
    """The coarsest sampling of the chord steps: every other sample while at least
    ``COARSEST_STEPS`` steps per period remain (the correction is a small, smooth part of the
    response: the time-step error of a coarser grid is a small part of a small quantity)."""
    stride = 1
    while n_steps % (2 * stride) == 0 and n_steps // (2 * stride) >= COARSEST_STEPS:
        stride *= 2
    return stride


def linearisation_error(lin: Any, z: np.ndarray, *, system: Any = None,
                        observe: Callable[[np.ndarray], np.ndarray] | None = None,
                        scheme: Any = "trapezoidal", monodromy: np.ndarray | None = None,
                        second_step_above: float = SECOND_STEP_ABOVE,
                        max_steps: int = MAX_STEPS, stride: int | None = None) -> LinearisationError:
    """The linearisation error of the linear periodic state ``z`` (N+1, m) of ``lin`` (a
    ``LinearizedMechanism``, e.g. ``speed_family(...).at_speed(rate)``): one chord step of the full
    nonlinear periodic problem from ``z``; where it changes an observable by more than
    ``second_step_above`` of its peak-to-peak, further steps (Anderson-accelerated, at most
    ``max_steps`` in all) until the last changes the observables by at most ``SETTLED`` of the
    correction; trusted where the last step is at most ``MAX_CONTRACTION`` of it (module docstring).
    ``system``: the periodic system ``z`` solves (default ``lin.system``); ``observe(z) -> (N+1,
    n_obs)``: the observables (default ``lin.observe``); ``scheme``: the periodic scheme ``z`` was
    solved with; ``stride``: the residual is evaluated on every ``stride``-th sample (default: the
    coarsest power of two leaving ``COARSEST_STEPS`` samples) and interpolated spectrally to the N
    samples the chord steps solve on; ``monodromy``: the monodromy of ``system`` with ``scheme`` if
    known (else one march computes it). Raises ``LinearizationError`` for a ``z`` of the
    wrong shape."""
    started = time.perf_counter()
    system = lin.system if system is None else system
    observe = lin.observe if observe is None else observe
    scheme = periodic.get_scheme(scheme)
    z = _checked(z, system)
    n_steps = system.n_steps
    stride = _stride(n_steps) if stride is None else int(stride)
    if stride < 1 or n_steps % stride:
        raise LinearizationError(f"stride must be a whole divisor of n_steps ({n_steps}); received "
                                 f"{stride}")
    grid = _grid(lin, system, stride)
    if monodromy is None:
        monodromy = monodromy_of(system, scheme)

    def residual_at(x: np.ndarray) -> tuple[np.ndarray, float]:
        """N(x) (N+1, m), evaluated on every stride-th sample and interpolated spectrally."""
        r, found = _residual(grid, x[::stride])
        return (interpolate_periodic(r, n_steps) if stride > 1 else r), found

    residual, violation = residual_at(z)
    base = observe(z)
    scale = np.maximum(np.ptp(base, axis=0), 1e-300)
    weight = 1.0 / np.maximum(np.abs(z).max(axis=0), 1e-300)   # each coordinate on its own scale

    def chord(x: np.ndarray, r: np.ndarray | None = None) -> np.ndarray:
        """G(x) = z - L^-1 N(x): one chord step from the linear state with the residual at x."""
        if r is None:
            r, _ = residual_at(x)
        return z + periodic_solve(_forced(system, -r), scheme, monodromy)

    def observed(x: np.ndarray) -> np.ndarray:
        """The observables' change from the linear state."""
        return observe(x) - base

    estimate = chord(z, residual)
    change = observed(estimate)
    steps, contraction, reason = 1, float("nan"), ""
    if np.any(np.abs(change).max(axis=0) > second_step_above * scale):
        x_prev, g_prev, x = z, estimate, estimate
        first = np.abs(change).max(axis=0)
        previous = change
        try:
            while steps < max_steps:
                g = chord(x)
                steps += 1
                change = observed(g)
                last = np.abs(change - previous).max(axis=0)
                previous = change
                # the correction so far, or the size below which an estimate cannot matter
                total = np.maximum(np.abs(change).max(axis=0), second_step_above * scale)
                contraction = float(np.max(last / np.maximum(first, 1e-300)))
                estimate = g
                if np.all(last <= SETTLED * total) or (steps >= 3 and np.any(last > first)):
                    break   # settled, or still growing: then it will not settle (reason below)
                # Anderson acceleration of depth one on the residuals f = G(x) - x
                f, f_prev = (g - x) * weight, (g_prev - x_prev) * weight
                df = f - f_prev
                gamma = float(np.sum(f * df) / max(float(np.sum(df * df)), 1e-300))
                x_prev, g_prev, x = x, g, g - gamma * (g - g_prev)
            worst = float(np.max(last / total))
            if worst > MAX_CONTRACTION:
                reason = (f"the chord iteration does not settle in {steps} steps (the last one "
                          f"changes the response by {worst:.2g} of the correction): near an "
                          f"instability, an exact resonance or far outside the linear range; run "
                          f"the nonlinear state")
        except (mechanisms.ConvergenceError, np.linalg.LinAlgError, periodic.ShootingError) as error:
            reason = f"a chord step failed ({error})"
    trusted = not reason
    correction = estimate - z
    if not trusted:
        correction = np.full_like(z, np.nan)
        change = np.full_like(change, np.nan)
    method = (f"chord step{'s' if steps > 1 else ''} of the nonlinear periodic problem from the linear "
              f"state ({steps}" + (f", Anderson-accelerated, last step {contraction:.2g} of the first)"
                                   if steps > 1 else ")") + f", the residual on {n_steps // stride} samples")
    return LinearisationError(correction=correction, change=change, steps=steps,
                              contraction=contraction, trusted=trusted, reason=reason,
                              constraint_violation=violation, residual=float(np.abs(residual).max()),
                              method=method, run_time=time.perf_counter() - started)
