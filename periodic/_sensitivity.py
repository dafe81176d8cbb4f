"""Parameter derivatives of a periodic steady state and of its critical Floquet multiplier.

Direct differentiation of the discrete periodic boundary-value problem.  Let the coefficients depend
on a parameter p at fixed phase ``t / T`` (the samples ``t_k = k T / N``) and the period on p too,
``lam = d ln T / dp``.  In the phase time ``s = t / T`` the system reads
``M x_ss + T C x_s + T^2 K x = T^2 f`` with period 1, and Newmark's scheme on it is exactly Newmark's
scheme on the original system (the scheme is invariant under a change of time scale).  Differentiating
the scheme's equations (N0)-(N3) of ``periodic._newmark`` at fixed step in s, the derivative
``dx = dx/dp`` at the samples satisfies the *same* discrete periodic system with the forcing

    g = df + 2 lam f - dM a - (dC + lam C) v - (dK + 2 lam K) x                     (S1)

(x, v, a the periodic solution), and the rates it marches are ``dv + lam v`` and ``da + 2 lam a``
(those of the phase time divided by T, T^2).  So the derivative is the periodic solution of the
system with forcing g: one run from rest gives its end state e, ``(I - Phi) z0 = e`` with the
shooting's monodromy (not recomputed), and one run from z0 the history.  All parameters march as
columns of one kernel call that factorises each step's matrix once (:func:`march_forcings`).  The
derivative is that of the N-step solution exactly (to rounding); the N/2 solution's derivative,
computed the same way on its own grid, gives its error estimate, ``error_factor * |dx_N - dx_{N/2}|``.

Multiplier.  For a simple eigenvalue ``mu`` of ``Phi`` with right and left eigenvectors ``r``, ``w``,
``dmu = w^H dPhi r / (w^H r)``.  ``dPhi r`` is the derivative of the end state of the homogeneous
solution from ``r``: the run from rest with the forcing (S1) built from that solution (no f terms);
in phase-time coordinates ``Phi_s = D Phi D^-1`` with ``D = diag(I, T I)`` and the ``D`` cancel, so
``dmu = w^H [dx(T); dv_marched(T)] / (w^H r)``.  ``d|mu| = Re(conj(mu) dmu) / |mu|``.  A repeated
multiplier has no such derivative (its eigenvectors are ill-conditioned): ``repeated`` says so.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from ._floquet import raise_on_singular
from ._scheme import DEFAULT_SCHEME, Scheme, get_scheme
from ._system import PeriodicError, PeriodicSystem, _set, check_coarsenable, check_system, every_other_sample

__all__ = ["SystemDerivative", "ResponseDerivative", "response_derivative"]

#: Two multipliers closer than this (relative to max(1, |mu|)) count as repeated: their eigenvector
#: pair is then too ill-conditioned for the first-order perturbation formula.
REPEATED_TOL = 1e-6


@dataclass(frozen=True)
class SystemDerivative:
    """The derivative of a :class:`PeriodicSystem` with respect to one parameter p.

    ``M, C, K`` (N+1, n, n) and ``f`` (N+1, n): d/dp of the samples at fixed phase ``t_k / T``
    (None where zero), per unit of p; ``log_period``: ``d ln T / dp`` (e.g. ``-1 / Omega`` for the
    speed ``Omega = 2 pi / T``)."""

    M: np.ndarray | None = None
    C: np.ndarray | None = None
    K: np.ndarray | None = None
    f: np.ndarray | None = None
    log_period: float = 0.0

    def every_other_sample(self) -> "SystemDerivative":
        """The same on the N/2 grid."""
        pick = {name: None if getattr(self, name) is None else np.ascontiguousarray(getattr(self, name)[::2])
                for name in "MCKf"}
        return SystemDerivative(**pick, log_period=self.log_period)


@dataclass(frozen=True)
class ResponseDerivative:
    """Derivatives of a periodic steady state with respect to P parameters.

    Attributes
    ----------
    x, v, a : ndarray (P, N+1, n)
        d/dp of the periodic solution, its rate and acceleration at fixed phase (units of x per unit
        of p, ...).
    x_coarse : ndarray (P, N/2+1, n) or None
        The same of the N/2-step solution at ``t[::2]`` (None without ``estimate_error``): the error of
        any quantity linear in dx is ``error_factor * |o(x[:, ::2]) - o(x_coarse)|``.
    error_factor : float
        The scheme's ``error_factor`` (NaN without the estimate).
    error_estimate : ndarray (P,)
        ``error_factor * max |dx_N - dx_{N/2}|`` per parameter (NaN without the estimate).
    radius : ndarray (P,)
        d|mu|/dp of the critical multiplier ``mu`` (the ``critical_multiplier`` of the steady state).
    radius_error : ndarray (P,)
        Its error estimate from the N/2 run (NaN without it).
    multiplier : ndarray (P,) complex
        dmu/dp.
    repeated : bool
        The critical multiplier is repeated (within ``REPEATED_TOL``) or its eigenvector pair is
        ill-conditioned: ``radius`` is then not a derivative (NaN).
    message : str
        What was computed, or why the radius derivative is missing.
    run_time : float
        s.
    """

    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    x_coarse: np.ndarray | None
    error_factor: float
    error_estimate: np.ndarray
    radius: np.ndarray
    radius_error: np.ndarray
    multiplier: np.ndarray
    repeated: bool
    message: str
    run_time: float


# ---------------------------------------------------------------------------------------------------
# Marching one forcing per column (Newmark's kernel: periodic._forcings)
# ---------------------------------------------------------------------------------------------------
def march_forcings(system: PeriodicSystem, scheme: Scheme, forcings: np.ndarray, x: np.ndarray,
                   v: np.ndarray, *, history: bool):
    """March the columns of ``x, v`` (n, m) over one period of ``system`` (its own ``f`` unused), column j
    driven by ``forcings[:, :, j]`` (N+1, n, m), with ``scheme``.  A scheme that offers
    ``march_forcings(system, forcings, x, v, a, x_hist, v_hist, a_hist)`` (Newmark's) marches all columns
    with one factorisation per step; any other :class:`Scheme` marches each column as the system with that
    forcing.  Returns ``(x, v, a)`` at t_N (n, m) and, with ``history``, the samples (N+1, n, m) each
    (else None)."""
    n, m = x.shape
    x, v = np.array(x, dtype=float), np.array(v, dtype=float)
    a = np.empty((n, m))
    shape = (system.n_steps + 1, n, m) if history else (0, n, m)
    x_hist, v_hist, a_hist = np.empty(shape), np.empty(shape), np.empty(shape)
    forcings = np.ascontiguousarray(forcings, dtype=float)
    own = getattr(scheme, "march_forcings", None)
    if own is not None:
        raise_on_singular(system, own(system, forcings, x, v, a, x_hist, v_hist, a_hist))
    else:
        for j in range(m):
            # the forcing of a homogeneous solution's derivative is not periodic: the system is the
            # validated one with another force history, not re-validated
            column = object.__new__(PeriodicSystem)
            force = np.ascontiguousarray(forcings[:, :, j])
            force.flags.writeable = False
            _set(column, system.period, system.M, system.C, system.K, force)
            xj, vj, aj = x[:, j:j + 1].copy(), v[:, j:j + 1].copy(), np.empty((n, 1))
            hist = [np.empty(shape[:2] + (1,)) for _ in range(3)]
            raise_on_singular(system, scheme.march(column, np.ones(1), xj, vj, aj, *hist))
            x[:, j], v[:, j], a[:, j] = xj[:, 0], vj[:, 0], aj[:, 0]
            if history:
                x_hist[:, :, j], v_hist[:, :, j], a_hist[:, :, j] = (h[:, :, 0] for h in hist)
    if not history:
        return (x, v, a), None
    return (x, v, a), (x_hist, v_hist, a_hist)


# ---------------------------------------------------------------------------------------------------
# The response and the multiplier
# ---------------------------------------------------------------------------------------------------
def _product(array: np.ndarray | None, state: np.ndarray) -> np.ndarray:
    """``array[k] @ state[k]`` for (N+1, n, n) and (N+1, n, m) -> (N+1, n, m); 0 for None."""
    if array is None:
        return 0.0
    return np.matmul(array, state)


def _forcings(system: PeriodicSystem, derivatives, x, v, a, *, forced: bool) -> np.ndarray:
    """The forcing (S1) of each derivative on each column of the solution ``x, v, a`` (N+1, n, c):
    (N+1, n, P c), parameter-major; ``forced=False`` leaves out the f terms (homogeneous solutions)."""
    columns = []
    for d in derivatives:
        lam = d.log_period
        g = -(_product(d.M, a) + _product(d.C, v) + lam * np.matmul(system.C, v)
              + _product(d.K, x) + 2.0 * lam * np.matmul(system.K, x))
        g = np.broadcast_to(g, x.shape).copy()
        if forced:
            if d.f is not None:
                g += d.f[:, :, None]
            g += 2.0 * lam * system.f[:, :, None]
        columns.append(g)
    return np.concatenate(columns, axis=2)


def _state(system: PeriodicSystem, x: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The shooting's state ``[x; v[massive]]`` of columns (n, m) -> (s, m)."""
    return np.vstack((x, v[system.massive]))


def _response(system, scheme, phi, x, v, a, derivatives):
    """dx, dv, da (P, N+1, n) of the periodic solution ``x, v, a`` (N+1, n) on ``system``'s grid."""
    n, n_p = system.n_dof, len(derivatives)
    forcing = _forcings(system, derivatives, x[:, :, None], v[:, :, None], a[:, :, None], forced=True)
    zeros = np.zeros((n, n_p))
    (x_end, v_end, _), _ = march_forcings(system, scheme, forcing, zeros, zeros, history=False)
    start = np.linalg.solve(np.eye(system.n_state) - phi, _state(system, x_end, v_end))
    x0, v0 = start[:n], np.zeros((n, n_p))
    v0[system.massive] = start[n:]
    _, (dx, dv, da) = march_forcings(system, scheme, forcing, x0, v0, history=True)
    lam = np.array([d.log_period for d in derivatives])
    # the marched rates are the phase time's divided by T and T^2 (S1): back to d/dp at fixed phase
    dx, dv, da = (np.moveaxis(h, 2, 0) for h in (dx, dv, da))
    return dx, dv - lam[:, None, None] * v[None], da - 2.0 * lam[:, None, None] * a[None]


def _multiplier(system, scheme, phi, critical, derivatives):
    """``(dmu (P,) complex, repeated, why)`` of the eigenvalue of ``phi`` nearest ``critical``."""
    values, left, right = scipy.linalg.eig(phi, left=True, right=True)
    i = int(np.argmin(np.abs(values - critical)))
    mu, r, w = values[i], right[:, i], left[:, i]
    others = np.delete(values, i)
    overlap = abs(np.vdot(w, r)) / (np.linalg.norm(w) * np.linalg.norm(r))
    n_p = len(derivatives)
    if others.size and np.abs(others - mu).min() <= REPEATED_TOL * max(1.0, abs(mu)) or overlap < 1e-8:
        return np.full(n_p, np.nan + 0j), True, (
            f"the critical multiplier {mu:.6g} is repeated (or its eigenvectors nearly parallel, "
            f"|w^H r| = {overlap:.2g}): its derivative is not defined")
    n = system.n_dof
    columns = np.column_stack((r.real, r.imag))               # (s, 2): real and imaginary parts
    x0 = np.ascontiguousarray(columns[:n])
    v0 = np.zeros((n, 2))
    v0[system.massive] = columns[n:]
    _, (xh, vh, ah) = march_forcings(system, scheme, np.zeros((system.n_steps + 1, n, 2)), x0, v0,
                                     history=True)
    forcing = _forcings(system, derivatives, xh, vh, ah, forced=False)   # (N+1, n, 2P)
    zeros = np.zeros((n, 2 * n_p))
    (x_end, v_end, _), _ = march_forcings(system, scheme, forcing, zeros, zeros, history=False)
    end = _state(system, x_end, v_end)
    d_phi_r = end[:, 0::2] + 1j * end[:, 1::2]                # (s, P)
    return (np.conj(w) @ d_phi_r) / np.vdot(w, r), False, f"d|mu| of the critical multiplier {mu:.6g}"


def _radius(mu: complex, dmu: np.ndarray) -> np.ndarray:
    return (np.conj(mu) * dmu).real / abs(mu)


def response_derivative(system: PeriodicSystem, state, derivatives, *, scheme: Scheme | str = DEFAULT_SCHEME,
                        estimate_error: bool = True, multiplier: bool = True) -> ResponseDerivative:
    """Derivatives of the periodic steady state ``state`` (a :class:`SteadyState` of ``system`` by
    ``scheme``, not extrapolated) and of its critical multiplier's modulus with respect to each
    :class:`SystemDerivative` in ``derivatives`` (P of them), by direct differentiation (module notes).
    ``estimate_error`` repeats the computation on the N/2 grid (the N/2 monodromy and solution that
    ``steady_state`` kept) for the error estimates; ``multiplier=False`` skips the multiplier's derivative
    (``radius`` NaN).  Costs two marches of P columns (four with the
    multiplier) per grid, against the shooting's march of 2n + 1 columns."""
    started = time.perf_counter()
    check_system(system)
    scheme = get_scheme(scheme)
    derivatives = tuple(derivatives)
    if not derivatives or not all(isinstance(d, SystemDerivative) for d in derivatives):
        raise PeriodicError(f"derivatives: expected a non-empty sequence of periodic.SystemDerivative, got "
                            f"{derivatives!r}")
    shape3, shape2 = system.M.shape, system.f.shape
    for j, d in enumerate(derivatives):
        for name, shape in (("M", shape3), ("C", shape3), ("K", shape3), ("f", shape2)):
            array = getattr(d, name)
            if array is not None and np.shape(array) != shape:
                raise PeriodicError(f"derivatives[{j}].{name}: expected shape {shape} (the system's samples), "
                                    f"got {np.shape(array)}")
    if getattr(state, "extrapolated", False) or state.n_steps != system.n_steps:
        raise PeriodicError("state: expected the N-step steady state of this system, not extrapolated "
                            "(periodic.steady_state(system, extrapolate=False))")
    dx, dv, da = _response(system, scheme, state.monodromy, state.x, state.v, state.a, derivatives)
    n_p = len(derivatives)
    if multiplier:
        dmu, repeated, why = _multiplier(system, scheme, state.monodromy, state.critical_multiplier, derivatives)
    else:
        dmu, repeated, why = np.full(n_p, np.nan + 0j), False, "the multiplier's derivative was not asked for"
    x_coarse, factor = None, float("nan")
    error, radius_error = np.full(n_p, np.nan), np.full(n_p, np.nan)
    radius = _radius(state.critical_multiplier, dmu)
    if estimate_error:
        check_coarsenable(system.n_steps, "use an even n_steps or estimate_error=False")
        if getattr(state, "coarse_monodromy", None) is None:
            raise PeriodicError("state: the error estimate needs the N/2 solution and monodromy that "
                                "periodic.steady_state keeps with estimate_error=True")
        coarse = every_other_sample(system)
        coarse_d = tuple(d.every_other_sample() for d in derivatives)
        x_coarse, _, _ = _response(coarse, scheme, state.coarse_monodromy, state.x_coarse, state.v_coarse,
                                   state.a_coarse, coarse_d)
        factor = scheme.error_factor
        error = factor * np.abs(dx[:, ::2] - x_coarse).max(axis=(1, 2))
        if multiplier and not repeated:
            coarse_values = np.linalg.eigvals(state.coarse_monodromy)
            coarse_mu = coarse_values[np.argmin(np.abs(coarse_values - state.critical_multiplier))]
            dmu_coarse, coarse_repeated, _ = _multiplier(coarse, scheme, state.coarse_monodromy, coarse_mu,
                                                         coarse_d)
            radius_error = (np.full(n_p, np.inf) if coarse_repeated
                            else factor * np.abs(radius - _radius(coarse_mu, dmu_coarse)))
    return ResponseDerivative(x=dx, v=dv, a=da, x_coarse=x_coarse, error_factor=factor, error_estimate=error,
                              radius=radius, radius_error=radius_error, multiplier=dmu, repeated=repeated,
                              message=why, run_time=time.perf_counter() - started)
