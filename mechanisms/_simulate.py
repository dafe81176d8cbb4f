"""Full nonlinear runs: the generalized-alpha method on the index-3 constrained equations of motion.

The equations (see ``_protocol.py``, seed eq. 2.10), n coordinates ``s`` and r multipliers ``lam``:

    M(s) s'' + Phi_s(s, t)^T lam = Q(s, s', t),        Phi(s, t) = 0.

Generalized-alpha (Chung & Hulbert 1993, for constrained systems Arnold & Bruls 2007, Multibody Syst.
Dyn. 18:185) advances positions ``q``, velocities ``v``, the true accelerations ``sddot`` and the
auxiliary "alpha accelerations" ``a`` from ``t_n`` to ``t_{n+1} = t_n + h``:

    (1 - alpha_m) a_{n+1} + alpha_m a_n = (1 - alpha_f) sddot_{n+1} + alpha_f sddot_n      (GA1)
    q_{n+1} = q_n + h v_n + h^2 (1/2 - beta) a_n + h^2 beta a_{n+1}                      (GA2)
    v_{n+1} = v_n + h (1 - gamma) a_n + h gamma a_{n+1}                                  (GA3)

with the equations of motion and the position constraints ``Phi(q_{n+1}, t_{n+1}) = 0`` imposed
exactly at ``t_{n+1}`` (index 3: no drift). With the spectral radius at infinity ``rho_inf`` in
[0, 1] (Chung & Hulbert eq. 25-26):

    alpha_m = (2 rho - 1) / (rho + 1),  alpha_f = rho / (rho + 1),
    gamma = 1/2 + alpha_f - alpha_m,    beta = (gamma + 1/2)^2 / 4,

which is second order for ``q`` and ``v`` and damps the unresolved (stiff, e.g. axial) modes.
Eliminating ``a_{n+1}`` leaves ``q_{n+1} = qhat + beta' sddot_{n+1}``, ``v_{n+1} = vhat + gamma'
sddot_{n+1}`` with ``beta' = h^2 beta (1 - alpha_f) / (1 - alpha_m)`` and ``gamma' = h gamma
(1 - alpha_f) / (1 - alpha_m)``; Newton's method is run on ``x = (sddot_{n+1}, lam_{n+1})`` for

    r_q = M(q) sddot + Phi_s(q)^T lam - Q(q, v, t) = 0,     r_c = Phi(q, t) / beta' = 0,     (NR)

the constraint rows divided by ``beta'`` (Arnold & Bruls sec. 3.3; Bottasso, Bauchau & Cardona 2007)
so that the iteration matrix

    [ M + beta' K_t + gamma' C_t   Phi_s^T ]     K_t = d(M sddot)/ds - dQ/ds + d(Phi_s^T lam)/ds
    [ Phi_s                        0       ]     C_t = -dQ/dsdot

stays O(1) as h -> 0 instead of having rows of size O(h^2). ``M`` and ``Phi_s`` are evaluated for
the residual at every iteration anyway, so the matrix is refactorised with them once per step; the
tangent terms ``beta' K_t + gamma' C_t`` (the model's analytic derivatives) are kept across steps
while the iteration contracts by 1/4 or better, and re-evaluated when it does not (modified Newton).

Robustness (coarse grids, stiff geometrically nonlinear links, approximately consistent starts): an
increment that grows while the matrix is not the Jacobian at the current iterate is undone and
replaced by a true Newton step; an increment larger than the configuration scale, or two growing
ones in a row, end the attempt. A failed attempt is repeated by full Newton from the constant
predictor, and a step that still fails is retried as 2, 4, ..., ``2**max_step_halvings`` equal
substeps (the alpha acceleration (GA1) carries over between steps of different sizes unchanged);
the output stays on the user's uniform grid.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numba
import numpy as np

from periodic import lapack

from ._kinematics import ConvergenceError
from ._observables import default_observables
from ._parts import ArgumentError

__all__ = ["SimulationError", "SimulationResult", "simulate"]

logger = logging.getLogger(__name__)

_METHODS = ("generalized-alpha",)


class SimulationError(ConvergenceError):
    """A nonlinear run failed (Newton divergence, singular iteration matrix); ``.result`` holds the
    steps computed before the failure. A ``ConvergenceError``, hence a ``RuntimeError``."""

    def __init__(self, message: str, result: "SimulationResult"):
        super().__init__(message)
        self.result = result


@dataclass(frozen=True)
class SimulationResult:
    """A nonlinear run on the grid ``t``.

    Attributes
    ----------
    t : (n_t,) s
    s, sdot, sddot : (n_t, n) coordinates and their first and second time derivatives (SI units of
        each coordinate: m or rad, per s, per s^2).
    lam : (n_t, r) Lagrange multipliers (the constraint force on the coordinates is
        ``-Phi_s^T lam``).
    observables : {spec: (n_t,)} values of the requested observables (units in ``observable_units``).
    constraint_residual : (n_t,) ``max |Phi(s, t)|`` at the accepted state (m, or rad for angle
        constraints); bounded by the Newton tolerance, it does not drift.
    observable_error : {spec: float} Richardson estimate of the maximum global error of each
        observable over the run (``max |o_h - o_2h| / 3`` for a second-order method, on the common
        grid points), or of the coordinates (key ``"s"``) without observables; empty with
        ``estimate_error=False`` or after a failure.
    n_steps, n_newton, n_jacobian, n_factorizations : counts of accepted steps of the grid, Newton
        iterations, evaluations of the analytic derivatives (tangent terms) and LU factorisations of
        the iteration matrix (all attempts included).
    n_rejected, n_substeps : step attempts whose Newton solve failed and was retried with half the
        step (2, 4, ... substeps), and the substeps that replaced the rejected grid steps; 0 when
        every step converged at the user's step.
    min_pivot_ratio : smallest ``min |u_kk| / max |u_kk|`` of the LU factors of the iteration
        matrices of the converged Newton solves (failed attempts excluded: their matrices are
        evaluated at diverging iterates), a cheap conditioning indicator; below ~1e-13 (logged as a warning) the
        Newton increments may carry large rounding errors.
    status : 0 success, -1 failure (the arrays then end at the last accepted step).
    message : what happened, naming the time of a failure.
    run_time : wall-clock seconds of the whole call (including an error-estimate run).
    lag_states, lag_names : (N+1, L) the states ``y`` (N m) of the lagged controllers (the torques
        they add to their drives, ``tau y' + y = u``), integrated with the mechanism; L = 0 without.
    """

    t: np.ndarray
    s: np.ndarray
    sdot: np.ndarray
    sddot: np.ndarray
    lam: np.ndarray
    observables: Mapping[str, np.ndarray]
    observable_units: Mapping[str, str]
    constraint_residual: np.ndarray
    observable_error: Mapping[str, float]
    n_steps: int
    n_newton: int
    n_jacobian: int
    n_factorizations: int
    n_rejected: int
    n_substeps: int
    min_pivot_ratio: float
    status: int
    message: str
    run_time: float
    method: str
    rho_inf: float
    dt: float
    coord_labels: tuple[str, ...] = field(default=())
    lag_states: np.ndarray | None = None
    lag_names: tuple[str, ...] = field(default=())

    @property
    def success(self) -> bool:
        return self.status == 0


# ---------------------------------------------------------------------------------------------------
# Numba kernels
# ---------------------------------------------------------------------------------------------------
# The iteration matrix (n + r ~ 20-70) is factorised once and reused over a modified-Newton
# iteration, and its pivots give ``min_pivot_ratio``. LAPACK's dgetrf / dgetrs (``periodic.lapack``, the
# packages' one binding) do the work; numba's np.linalg.solve, which factorises and copies at every solve, made
# the thesis four-bar's runs 14-18 % slower (20 revolutions at 125 and 400 steps per period), whereas direct
# dgetrf / dgetrs calls cost 0-4 % (125) and 3-10 % (400) against the hand-written LU they replaced (medians
# of interleaved runs; a cold OpenBLAS call takes ~2-3 us more). The matrix is built transposed
# (``periodic.lapack``'s order).
@numba.njit(cache=True)
def _lu_factor(G_T, piv):
    """``P G = L U`` of the iteration matrix G whose transpose ``G_T`` (n, n) is given (``periodic.lapack``'s
    convention; LAPACK dgetrf), in place; ``piv`` (n,) int32 receives the pivots.

    Returns ``min |u_kk| / max |u_kk|`` (0.0 when a pivot is exactly zero) as a cheap singularity
    indicator."""
    if not lapack.factor_lapack(G_T, piv):
        return 0.0  # info > 0: u_kk exactly zero at k = info
    return lapack.pivot_ratio(G_T)


@numba.njit(cache=True)
def _tangent_terms(dMa_ds, dQ_ds, dQ_dv, dPhiTlam_ds, beta_p, gamma_p, out):
    """``beta' K_t + gamma' C_t`` of (NR), the part of the Newton matrix kept across iterations."""
    n = dMa_ds.shape[0]
    for i in range(n):
        for j in range(n):
            out[i, j] = (beta_p * (dMa_ds[i, j] - dQ_ds[i, j] + dPhiTlam_ds[i, j])
                         - gamma_p * dQ_dv[i, j])


@numba.njit(cache=True)
def _fill_iteration_matrix(M, tangent, Phi_s, out):
    """The transpose of the Newton matrix of (NR), ``[[M + beta' K_t + gamma' C_t, Phi_s^T],
    [Phi_s, 0]]``, into ``out`` (n + r, n + r): the matrix in column-major order for LAPACK.

    Returns ``max(1, max_k sum_j |Phi_s[k, j]|)``, the factor from a position error to the
    constraint residual that the acceptance test allows for."""
    n = M.shape[0]
    r = Phi_s.shape[0]
    for i in range(n):
        for j in range(n):
            out[j, i] = M[i, j] + tangent[i, j]
    row_sum_max = 1.0
    for k in range(r):
        row_sum = 0.0
        for j in range(n):
            out[n + k, j] = Phi_s[k, j]
            out[j, n + k] = Phi_s[k, j]
            row_sum += abs(Phi_s[k, j])
        row_sum_max = max(row_sum_max, row_sum)
        for m in range(r):
            out[n + k, n + m] = 0.0
    return row_sum_max


@numba.njit(cache=True)
def _max_abs(x):
    """``max |x_i|`` (0 for an empty array, NaN if any entry is NaN)."""
    out = 0.0
    for i in range(x.shape[0]):
        if not abs(x[i]) <= out:
            out = abs(x[i])
            if np.isnan(out):
                return out
    return out


@numba.njit(cache=True)
def _newton_update(LU, piv, M, sddot, Phi_s, lam, Q, Phi, qhat, vhat, beta_p, gamma_p, rhs,
                   q, v):
    """One (modified) Newton step on (NR): residual, solve, update ``sddot, lam`` and the positions
    and velocities ``q = qhat + beta' sddot``, ``v = vhat + gamma' sddot``. Returns the max-norm of
    the position increment ``beta' |d sddot|``."""
    n = M.shape[0]
    r = Phi_s.shape[0]
    for i in range(n):
        acc = -Q[i]
        for j in range(n):
            acc += M[i, j] * sddot[j]
        for k in range(r):
            acc += Phi_s[k, i] * lam[k]
        rhs[i] = -acc
    for k in range(r):
        rhs[n + k] = -Phi[k] / beta_p
    lapack.solve_rows_lapack(LU, piv, rhs.reshape((1, rhs.shape[0])), False)
    dq_max = 0.0
    finite = True
    for i in range(n):
        sddot[i] += rhs[i]
        q[i] = qhat[i] + beta_p * sddot[i]
        v[i] = vhat[i] + gamma_p * sddot[i]
        dq_max = max(dq_max, abs(beta_p * rhs[i]))
        finite = finite and np.isfinite(rhs[i])
    for k in range(r):
        lam[k] += rhs[n + k]
        finite = finite and np.isfinite(rhs[n + k])
    # max() drops NaN, so report non-finite increments explicitly
    return dq_max if finite else np.nan


@numba.njit(cache=True)
def _start_step(q, v, a, sddot_n, lam_n, sddot_prev, lam_prev, extrapolate, h, alpha_m, alpha_f,
                beta, gamma, beta_p, gamma_p, qhat, vhat, sddot, lam, q_new, v_new):
    """Predictor of the step from ``t_n``: the parts of (GA2), (GA3) known at ``t_n`` (``a_{n+1}``
    from (GA1) split into its known part ``(alpha_f sddot_n - alpha_m a_n) / (1 - alpha_m)`` and
    ``(1 - alpha_f) / (1 - alpha_m) sddot_{n+1}``), the guess of ``sddot_{n+1}, lam_{n+1}`` (linear
    extrapolation from ``t_{n-1}, t_n``, or the values at ``t_n``) and the positions and velocities
    ``q = qhat + beta' sddot``, ``v = vhat + gamma' sddot`` it implies."""
    for i in range(q.shape[0]):
        a_known = (alpha_f * sddot_n[i] - alpha_m * a[i]) / (1.0 - alpha_m)
        qhat[i] = q[i] + h * v[i] + h * h * ((0.5 - beta) * a[i] + beta * a_known)
        vhat[i] = v[i] + h * ((1.0 - gamma) * a[i] + gamma * a_known)
        sddot[i] = 2.0 * sddot_n[i] - sddot_prev[i] if extrapolate else sddot_n[i]
        q_new[i] = qhat[i] + beta_p * sddot[i]
        v_new[i] = vhat[i] + gamma_p * sddot[i]
    for k in range(lam.shape[0]):
        lam[k] = 2.0 * lam_n[k] - lam_prev[k] if extrapolate else lam_n[k]


@numba.njit(cache=True)
def _advance_alpha_acceleration(a, sddot_old, sddot_new, alpha_m, alpha_f):
    """(GA1) solved for ``a_{n+1}``, in place."""
    for i in range(a.shape[0]):
        a[i] = (alpha_f * sddot_old[i] + (1.0 - alpha_f) * sddot_new[i] - alpha_m * a[i]) / (
            1.0 - alpha_m)


# ---------------------------------------------------------------------------------------------------
# Python driver
# ---------------------------------------------------------------------------------------------------
def _generalized_alpha_parameters(rho_inf: float) -> tuple[float, float, float, float]:
    """(alpha_m, alpha_f, beta, gamma) of Chung & Hulbert (1993) eq. 25-26 for ``rho_inf``."""
    alpha_m = (2.0 * rho_inf - 1.0) / (rho_inf + 1.0)
    alpha_f = rho_inf / (rho_inf + 1.0)
    gamma = 0.5 + alpha_f - alpha_m
    beta = 0.25 * (gamma + 0.5) ** 2
    return alpha_m, alpha_f, beta, gamma


def _as_vector(value: Any, n: int, name: str) -> np.ndarray:
    arr = np.array(value, dtype=np.float64)
    if arr.shape != (n,):
        raise ArgumentError(f"`{name}` must have shape ({n},) (one value per coordinate); got shape "
                         f"{arr.shape}.")
    if not np.all(np.isfinite(arr)):
        raise ArgumentError(f"`{name}` must be finite; got non-finite entries at indices "
                         f"{np.flatnonzero(~np.isfinite(arr)).tolist()}.")
    return arr


def _positive(value: Any, name: str) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise TypeError(f"`{name}` must be a real number; got {value!r}.") from None
    if not (math.isfinite(x) and x > 0.0):
        raise ArgumentError(f"`{name}` must be positive and finite; got {value!r}.")
    return x


def _period_of(model: Any, period: float | None) -> float | None:
    """The drive period (s): the ``period`` argument, else the model's (the assembler sets it from
    ``Mechanism.period`` or the first drive's rate), else None."""
    if period is not None:
        return _positive(period, "period")
    model_period = getattr(model, "period", None)
    return None if model_period is None else float(model_period)


def _time_grid(t0: float, t_end, n_periods, dt, steps_per_period, period) -> tuple[float, int]:
    """(h, n_steps) of the uniform grid from the (t_end | n_periods) and (dt | steps_per_period)
    options; the step is shortened so that the grid ends exactly at ``t_end``."""
    if (t_end is None) == (n_periods is None):
        raise TypeError("give exactly one of `t_end` (s) and `n_periods`; got "
                        f"t_end={t_end!r}, n_periods={n_periods!r}.")
    if (dt is None) == (steps_per_period is None):
        raise TypeError("give exactly one of `dt` (s) and `steps_per_period`; got "
                        f"dt={dt!r}, steps_per_period={steps_per_period!r}.")
    needs_period = n_periods is not None or steps_per_period is not None
    if needs_period and period is None:
        raise ArgumentError("`n_periods` and `steps_per_period` need the period: this system has no "
                         "drive rate or `period` attribute; pass `period=` (s) or use `t_end`, "
                         "`dt`.")
    duration = (_positive(t_end, "t_end") - t0 if t_end is not None
                else _positive(n_periods, "n_periods") * period)
    if duration <= 0.0:
        raise ArgumentError(f"`t_end` must be after `t0` = {t0}; got t_end={t_end!r}.")
    if steps_per_period is not None:
        if int(steps_per_period) != steps_per_period or steps_per_period < 1:
            raise ArgumentError("`steps_per_period` must be a positive integer; got "
                             f"{steps_per_period!r}.")
        h_wanted = period / int(steps_per_period)
    else:
        h_wanted = _positive(dt, "dt")
    n_steps = max(1, int(math.ceil(duration / h_wanted - 1e-9)))
    return duration / n_steps, n_steps


def integrated_model(mechanism: Any, nominal: Any = None) -> Any:
    """The model ``simulate`` and ``PeriodMap`` integrate for the ``mechanism``: ``assemble(mechanism)``,
    and with torque drives the nominal inverse-dynamics torque as their feedforward
    (``feedforward_torques`` of ``nominal``, the mechanism's ``nominal_motion``, computed when not
    given). Its ``drive_torques`` is the torque a run applies (feedforward plus feedback clipped to the
    drive's limits, plus the lag states given)."""
    from ._assemble import assemble
    from ._kinematics import feedforward_torques, nominal_motion
    from ._parts import TorqueDrive

    if not any(isinstance(d, TorqueDrive) for d in mechanism.drives):
        return assemble(mechanism)
    nominal = nominal_motion(mechanism) if nominal is None else nominal
    return assemble(mechanism, feedforward=feedforward_torques(mechanism, nominal))


def _resolve_model(system: Any, need_nominal: bool):
    """(model, mechanism or None, nominal motion or None) from a Mechanism or a protocol model.

    A Mechanism is assembled here; with torque drives its nominal inverse-dynamics torque
    (``feedforward_torques``) is the drives' feedforward. The nominal motion is computed when a
    start state is needed or for the feedforward."""
    from ._parts import Mechanism, TorqueDrive
    if isinstance(system, Mechanism):
        from ._kinematics import nominal_motion
        torque_drives = any(isinstance(d, TorqueDrive) for d in system.drives)
        nominal = nominal_motion(system) if (need_nominal or torque_drives) else None
        return integrated_model(system, nominal), system, nominal
    required = ("n_coords", "n_constraints", "mass_matrix", "forces", "constraints",
                "constraint_jacobian", "constraint_rate", "constraint_gamma",
                "mass_matrix_jacobian", "force_jacobians", "constraint_force_jacobian")
    missing = [name for name in required if not hasattr(system, name)]
    if missing:
        raise TypeError("`system` must be a mechanisms.Mechanism or a model implementing "
                        f"mechanisms/_protocol.py's ConstrainedModel; {type(system).__name__} lacks "
                        f"{missing}.")
    mechanism = getattr(system, "mechanism", None)
    mechanism = mechanism if isinstance(mechanism, Mechanism) else None
    nominal = None
    if need_nominal and mechanism is not None:
        from . import nominal_motion
        nominal = nominal_motion(mechanism)
    return system, mechanism, nominal


def _initial_state(model, nominal, s0, sdot0, t0: float):
    n = int(model.n_coords)
    if s0 is None:
        if nominal is None:
            raise ArgumentError("`s0` is required when simulating a bare model: only a Mechanism (or a "
                             "model assembled from one) has a nominal rigid motion to start from.")
        if float(nominal.t[0]) != t0:
            raise ArgumentError(f"the nominal motion starts at t = {float(nominal.t[0])} s; pass `s0` "
                             f"and `sdot0` to start at t0 = {t0} s.")
        s_start = np.array(nominal.s[0], dtype=np.float64)
        v_start = np.array(nominal.sdot[0], dtype=np.float64)
    else:
        s_start = _as_vector(s0, n, "s0")
        v_start = np.zeros(n)
    if sdot0 is not None:
        v_start = _as_vector(sdot0, n, "sdot0")
    return s_start, v_start


def _lag_force(model, lag_states):
    """``sum_i h_i y_i`` (n,), the force of the lagged controllers' states ``y`` (L,) N m on the
    coordinates, or None with the lags at rest (``y = 0``: the force is zero)."""
    if not np.any(lag_states):
        return None
    return np.asarray(lag_states, dtype=np.float64) @ np.asarray(model.lag_gradients, dtype=np.float64)


def _consistent_accelerations(model, q, v, t, lag_force=None):
    """Solve ``[[M, Phi_s^T], [Phi_s, 0]] [sddot; lam] = [Q; gamma]`` (the index-1 form at ``t``);
    ``lag_force`` (n,), the lagged controllers' ``H^T y``, is added to ``Q`` when given."""
    n = q.shape[0]
    r = int(model.n_constraints)
    A = np.zeros((n + r, n + r))
    A[:n, :n] = model.mass_matrix(q)
    Phi_s = np.asarray(model.constraint_jacobian(q, t), dtype=np.float64)
    A[:n, n:] = Phi_s.T
    A[n:, :n] = Phi_s
    forces = model.forces(q, v, t)
    if lag_force is not None:
        forces = forces + lag_force
    b = np.concatenate([forces, model.constraint_gamma(q, v, t)])
    cond = np.linalg.cond(A)
    if not np.isfinite(cond) or cond > 1e13:
        raise ArgumentError(f"the augmented mass matrix at t = {t} s is singular (condition number "
                         f"{cond:.3g}): check for redundant constraints or massless coordinates.")
    x = np.linalg.solve(A, b)
    return x[:n], x[n:]


def _check_consistency(model, q, v, t, length_scale):
    """Raise if the initial state violates the position or velocity constraints."""
    phi = np.asarray(model.constraints(q, t), dtype=np.float64)
    if np.max(np.abs(phi), initial=0.0) > 1e-8 * length_scale:
        worst = int(np.argmax(np.abs(phi)))
        labels = list(getattr(model, "constraint_labels", ()))
        name = labels[worst] if worst < len(labels) else f"#{worst}"
        raise ArgumentError(f"`s0` violates the constraints at t0 = {t} s: "
                         f"|Phi| = {abs(phi[worst]):.3g} at constraint {name!r} (allowed 1e-8 x "
                         f"{length_scale:.3g}); start from an assembled configuration (e.g. "
                         "mechanisms.nominal_motion).")
    Phi_s = np.asarray(model.constraint_jacobian(q, t), dtype=np.float64)
    vel = Phi_s @ v + np.asarray(model.constraint_rate(q, t), dtype=np.float64)
    speed_scale = max(np.max(np.abs(v), initial=0.0), 1.0) * max(length_scale, 1.0)
    if np.max(np.abs(vel), initial=0.0) > 1e-8 * speed_scale:
        worst = int(np.argmax(np.abs(vel)))
        raise ArgumentError(f"`sdot0` violates the velocity constraints at t0 = {t} s: "
                         f"|Phi_s sdot + Phi_t| = {abs(vel[worst]):.3g} at constraint #{worst}; "
                         "project it onto the constraint tangent space or start from the nominal "
                         "motion.")


def _observable_evaluators(model, mechanism, observables):
    if observables is None:
        if mechanism is None or not hasattr(model, "observable"):
            return {}
        specs = list(default_observables(mechanism))
    else:
        if isinstance(observables, str):
            observables = (observables,)
        specs = list(observables)
        if specs and not hasattr(model, "observable"):
            raise TypeError(f"`observables` {specs} were asked for but the model "
                            f"{type(model).__name__} has no `observable(spec)` method.")
    return {spec: model.observable(spec) for spec in specs}


def simulate(system: Any, *, t_end: float | None = None, n_periods: float | None = None,
             dt: float | None = None, steps_per_period: int | None = None,
             s0: Sequence[float] | None = None, sdot0: Sequence[float] | None = None,
             t0: float = 0.0, period: float | None = None, method: str = "generalized-alpha",
             rho_inf: float = 0.8, observables: Sequence[str] | None = None, tol: float = 1e-10,
             max_iterations: int = 20, jacobian_reuse: bool = True, max_step_halvings: int = 6,
             perturbed_start: bool = False, estimate_error: bool = True,
             throw: bool = True, lag0: Sequence[float] | None = None) -> SimulationResult:
    """Integrate the full nonlinear constrained equations of motion on a uniform time grid.

    Parameters
    ----------
    system : a ``mechanisms.Mechanism`` (assembled with ``mechanisms.assemble``; torque drives get
        the nominal inverse-dynamics torque as feedforward) or any model implementing
        ``mechanisms._protocol.ConstrainedModel``.
    t_end, n_periods : the end time (s), or the number of drive periods, exactly one of them.
    dt, steps_per_period : the time step (s, shortened to end on ``t_end``), or steps per period.
    s0, sdot0 : initial coordinates and velocities (n,). Without ``s0`` a Mechanism (or a model
        with a ``mechanism`` attribute) starts on its nominal rigid motion
        (``mechanisms.nominal_motion``) at ``t0 = 0``, elastic coordinates zero; ``sdot0``
        defaults to the nominal velocities, or to zero with a given ``s0``. The state must
        satisfy the position and velocity constraints to 1e-8 relative; accelerations and
        multipliers are then solved for consistently.
    period : the period (s) used by ``n_periods`` / ``steps_per_period`` for a bare model without a
        ``period`` attribute.
    method : ``"generalized-alpha"``.
    rho_inf : spectral radius at infinite step in [0, 1]: smaller values damp unresolved
        high-frequency modes harder; second order for any value. Use ``rho_inf < 1`` whenever the
        model has stiff modes the step does not resolve (the axial modes of elastic links: h omega
        of 10-100 at ordinary steps): at 1 (no numerical damping, the trapezoidal rule) they keep
        their start-up energy, the index-3 multipliers oscillate undamped, and Newton fails on
        stiff nonlinear (geometrically stiffened) links; a warning is logged.
    observables : specs for ``model.observable(spec)`` (e.g. ``"coupler.deflection@0.5"``,
        ``"coupler.strain@0.25"``, ``"coupler.moment@0.5"``, ``"rocker.angle"``); default:
        ``mechanisms.default_observables`` of a Mechanism, none for a bare model.
    tol : Newton tolerance: iterations stop when the last position increment is below
        ``tol * max(1, max |s0|)`` (m or rad) and the constraint residual ``max |Phi|`` is below
        that times ``max(1, max row sum |Phi_s|)``.
    max_iterations : Newton iterations allowed per step (and per substep) before it is rejected.
        Newton also gives up early when its increments grow.
    max_step_halvings : a step whose Newton solve fails (no convergence, divergence, singular
        matrix, non-finite values) is retried as 2, 4, ..., ``2**max_step_halvings`` equal
        substeps (each by full Newton from the constant predictor) and the run goes on
        at the user's step; the output stays on the uniform grid and ``n_rejected`` counts the
        retries. 0 ends the run at the first failure. Substeps change the local error of that
        step only (the method stays second order).
    jacobian_reuse : keep the tangent terms of the iteration matrix across iterations and steps
        while Newton contracts well (modified Newton); ``False`` re-evaluates them at every
        iteration (full Newton).
    perturbed_start : start the alpha acceleration at Arnold & Bruls' (2007) perturbed value
        ``sddot(t0 + (alpha_m - alpha_f) h)`` (from two extra index-1 solves at ``t0 +- delta``)
        instead of ``sddot_0``: removes the O(h) start-up error that ``lam`` and ``sddot`` carry
        through the first steps (the first step's error drops from O(h^2) to O(h^3)). For smooth
        solutions only: with unresolved stiff (axial) modes the central difference picks up their
        huge jerk and excites them (the stiff double pendulum and the four-bar scenes then fail
        or lose accuracy), hence off by default.
    estimate_error : also run with twice the step and report the Richardson estimate of the global
        error of each observable in ``observable_error`` (costs about half a run more; ``False``
        for timing-critical loops).
    throw : raise ``SimulationError`` on failure; with ``False`` return the partial result with
        ``status = -1`` and a message naming the time.
    lag0 : the initial states (n_lags,) of the model's lagged controllers (N m; default 0, the lags
        at rest): e.g. the last entries of a linear steady state's ``z`` at t = 0.

    Returns
    -------
    SimulationResult
    """
    start_clock = time.perf_counter()
    if method not in _METHODS:
        raise ArgumentError(f"`method` must be one of {_METHODS}; got {method!r}.")
    rho = float(rho_inf)
    if not 0.0 <= rho <= 1.0:
        raise ArgumentError(f"`rho_inf` must lie in [0, 1]; got {rho_inf!r}.")
    if rho == 1.0:
        logger.warning("rho_inf = 1 damps nothing: unresolved stiff (axial) modes and the "
                       "multipliers keep their start-up oscillations, and Newton can fail on stiff "
                       "nonlinear links; use rho_inf < 1 (default 0.8) unless every mode is "
                       "resolved by the step.")
    if int(max_step_halvings) != max_step_halvings or not 0 <= max_step_halvings <= 20:
        raise ArgumentError("`max_step_halvings` must be an integer in [0, 20]; got "
                         f"{max_step_halvings!r}.")
    tol = _positive(tol, "tol")
    if int(max_iterations) != max_iterations or max_iterations < 1:
        raise ArgumentError(f"`max_iterations` must be a positive integer; got {max_iterations!r}.")
    model, mechanism, nominal = _resolve_model(system, need_nominal=s0 is None)
    t0 = float(t0)
    h, n_steps = _time_grid(t0, t_end, n_periods, dt, steps_per_period,
                            _period_of(model, period))
    q0, v0 = _initial_state(model, nominal, s0, sdot0, t0)
    length_scale = max(1.0, float(np.max(np.abs(q0), initial=0.0)))
    _check_consistency(model, q0, v0, t0, length_scale)
    evaluators = _observable_evaluators(model, mechanism, observables)

    options = (rho, tol * length_scale, int(max_iterations), jacobian_reuse,
               int(max_step_halvings), length_scale, bool(perturbed_start))
    n_lags = len(getattr(model, "lag_names", ()))
    lag0 = None if lag0 is None else _as_vector(lag0, n_lags, "lag0")
    run = _integrate(model, q0, v0, t0, h, n_steps, *options, lag0=lag0)
    obs = {spec: np.array([ev.value(q) for q in run["s"]]) for spec, ev in evaluators.items()}
    obs_error: dict[str, float] = {}
    if estimate_error and run["status"] == 0 and n_steps < 2:
        run["message"] += " No error estimate: a single step has no coarser grid to compare with."
    elif estimate_error and run["status"] == 0:
        # the coarse grid t0 + 2 k h, k <= n_steps // 2, is every other point of the fine one
        coarse = _integrate(model, q0, v0, t0, 2.0 * h, n_steps // 2, *options, lag0=lag0)
        if coarse["status"] != 0:
            run["message"] += (" Error estimate unavailable: the 2 dt run failed "
                               f"({coarse['message']})")
        else:
            for spec, ev in evaluators.items():
                o_coarse = np.array([ev.value(q) for q in coarse["s"]])
                # Richardson for an order-2 method: e_h ~ (o_h - o_2h) / (2^2 - 1)
                fine = obs[spec][::2][:o_coarse.size]
                obs_error[spec] = float(np.max(np.abs(fine - o_coarse)) / 3.0)
            # without observables the coordinates stand in, so the user still gets an estimate
            if not evaluators:
                fine = run["s"][::2][:coarse["s"].shape[0]]
                obs_error["s"] = float(np.max(np.abs(fine - coarse["s"])) / 3.0)

    result = SimulationResult(
        t=run["t"], s=run["s"], sdot=run["sdot"], sddot=run["sddot"], lam=run["lam"],
        observables=obs, observable_units={spec: getattr(ev, "unit", "") for spec, ev in
                                           evaluators.items()},
        constraint_residual=run["residual"], observable_error=obs_error,
        n_steps=run["n_steps"], n_newton=run["n_newton"], n_jacobian=run["n_jacobian"],
        n_factorizations=run["n_factorizations"], n_rejected=run["n_rejected"],
        n_substeps=run["n_substeps"], min_pivot_ratio=run["min_pivot_ratio"],
        status=run["status"], message=run["message"],
        run_time=time.perf_counter() - start_clock, method=method, rho_inf=rho, dt=h,
        coord_labels=tuple(getattr(model, "coord_labels", ())), lag_states=run["lag_states"],
        lag_names=tuple(getattr(model, "lag_names", ())))
    if result.min_pivot_ratio < 1e-13:
        logger.warning("the iteration matrix was ill-conditioned (pivot ratio %.2g): check the "
                       "constraint rows for near-redundancy or reduce extreme stiffness contrasts",
                       result.min_pivot_ratio)
    if result.status != 0:
        if throw:
            raise SimulationError(result.message, result)
        logger.warning(result.message)
    return result


class _Stepper:
    """Newton's method on (NR) for one step of any size from a given state, with the buffers, the
    kept tangent terms and the counts shared by all steps of a run."""

    def __init__(self, model, rho, abs_tol, max_iterations, jacobian_reuse, length_scale):
        self.model = model
        # a Newton increment larger than the configuration itself is outside the region of
        # convergence: Newton from there found spurious roots of the step equations (positions of
        # 1e3 m on the four-bar scene at 16 steps per period)
        self.max_increment = length_scale
        self.alpha_m, self.alpha_f, self.beta, self.gamma = _generalized_alpha_parameters(rho)
        self.abs_tol, self.max_iterations, self.jacobian_reuse = abs_tol, max_iterations, \
            jacobian_reuse
        n, r = int(model.n_coords), int(model.n_constraints)
        # the Newton iterates (updated in place); after a converged solve, the new state
        self.q, self.v, self.sddot, self.lam = np.empty(n), np.empty(n), np.empty(n), np.empty(r)
        self.qhat, self.vhat = np.empty(n), np.empty(n)
        self.sddot_before, self.lam_before = np.empty(n), np.empty(r)
        self.rhs = np.empty(n + r)
        self.G = np.empty((n + r, n + r))
        self.tangent = np.empty((n, n))
        self.piv = np.empty(n + r, dtype=np.int32)
        self.tangent_h = None      # the step the kept tangent terms were scaled with, or None
        self.residual = np.nan     # max |Phi| at the last converged solve
        self.counts = {"n_newton": 0, "n_jacobian": 0, "n_factorizations": 0}
        self.min_pivot_ratio = np.inf
        # lagged controllers' states, integrated with the step (None without lags)
        self.lags = _Lags(model) if len(getattr(model, "lag_names", ())) else None
        self.t = np.nan            # the time of the last step solved

    def drop_tangent(self):
        self.tangent_h = None

    def solve(self, q_n, v_n, a_n, sddot_n, lam_n, sddot_prev, lam_prev, extrapolate, t, h,
              full_newton=False):
        """The step from ``t - h`` (state ``q_n, v_n``, alpha acceleration ``a_n``, ``sddot_n``,
        ``lam_n``) to ``t``. The predictor extrapolates linearly from ``sddot_prev, lam_prev`` (at
        ``t - 2h``) when ``extrapolate``; if modified Newton fails from it, the step is solved once
        more by full Newton (Jacobian at every iterate) from the constant predictor, the most
        robust variant on the stiff, geometrically nonlinear links (on the shipped six-bar and
        four-bar scenes modified Newton failed at coarse steps where full Newton converged).
        Returns "" on success (new state in ``q, v, sddot, lam``), else what went wrong."""
        alpha_m, alpha_f, beta, gamma = self.alpha_m, self.alpha_f, self.beta, self.gamma
        beta_p = h * h * beta * (1.0 - alpha_f) / (1.0 - alpha_m)
        gamma_p = h * gamma * (1.0 - alpha_f) / (1.0 - alpha_m)
        if self.tangent_h != h:
            self.tangent_h = None
        self.t = t
        if self.lags is not None:
            self.lags.begin(h)
        full_newton = full_newton or not self.jacobian_reuse
        failure = ""
        for _attempt in range(2):
            failure = self._newton(q_n, v_n, a_n, sddot_n, lam_n, sddot_prev, lam_prev,
                                   extrapolate, t, h, beta_p, gamma_p, full_newton)
            if not failure:
                if full_newton:
                    self.tangent_h = None
                return ""
            self.tangent_h = None
            if full_newton and not extrapolate:
                break           # the retry would repeat this attempt exactly
            extrapolate, full_newton = False, True
        return failure

    def _newton(self, q_n, v_n, a_n, sddot_n, lam_n, sddot_prev, lam_prev, extrapolate, t, h,
                beta_p, gamma_p, full_newton):
        model, abs_tol, max_iterations = self.model, self.abs_tol, self.max_iterations
        q, v, sddot, lam, qhat, vhat = self.q, self.v, self.sddot, self.lam, self.qhat, self.vhat
        G, piv, tangent, counts = self.G, self.piv, self.tangent, self.counts
        _start_step(q_n, v_n, a_n, sddot_n, lam_n, sddot_prev, lam_prev, extrapolate, h,
                    self.alpha_m, self.alpha_f, self.beta, self.gamma, beta_p, gamma_p, qhat, vhat,
                    sddot, lam, q, v)
        factorized = False
        iterations, prev_dq, phi_scale = 0, np.inf, 1.0
        candidate, growths = False, 0
        min_pivot_ratio = np.inf
        while True:
            Phi = np.ascontiguousarray(model.constraints(q, t), dtype=np.float64)
            if candidate:
                # the increments say converged; accept if the constraints agree to tol as well
                step_residual = _max_abs(Phi)
                if step_residual <= abs_tol * phi_scale:
                    self.residual = step_residual
                    self.min_pivot_ratio = min(self.min_pivot_ratio, min_pivot_ratio)
                    return ""
                candidate = False
                if iterations >= max_iterations:
                    return (f"the constraint residual stalled at {step_residual:.3g} > "
                            f"{abs_tol * phi_scale:.3g} after {iterations} iterations (`tol` "
                            "below round-off?)")
            M = np.ascontiguousarray(model.mass_matrix(q), dtype=np.float64)
            Q = np.ascontiguousarray(model.forces(q, v, t), dtype=np.float64)
            if self.lags is not None:
                Q = Q + self.lags.force(q, v, t)
            Phi_s = np.ascontiguousarray(model.constraint_jacobian(q, t), dtype=np.float64)
            exact = self.tangent_h is None    # the matrix will be the Jacobian at this iterate
            if exact:
                dQ_ds, dQ_dv = model.force_jacobians(q, v, t)
                if self.lags is not None:
                    dQ_ds, dQ_dv = self.lags.add_force_jacobians(q, v, t, dQ_ds, dQ_dv)
                _tangent_terms(
                    np.ascontiguousarray(model.mass_matrix_jacobian(q, sddot), dtype=np.float64),
                    np.ascontiguousarray(dQ_ds, dtype=np.float64),
                    np.ascontiguousarray(dQ_dv, dtype=np.float64),
                    np.ascontiguousarray(model.constraint_force_jacobian(q, lam, t),
                                         dtype=np.float64),
                    beta_p, gamma_p, tangent)
                counts["n_jacobian"] += 1
                self.tangent_h = h
                factorized = False
            if not factorized:
                # M and Phi_s are evaluated for the residual anyway: the matrix takes them fresh
                # once per step (they rotate with the links) and keeps the O(h) tangent terms,
                # which are re-evaluated only when the iteration contracts slowly
                phi_scale = _fill_iteration_matrix(M, tangent, Phi_s, G)
                pivot_ratio = _lu_factor(G, piv)
                counts["n_factorizations"] += 1
                factorized = True
                min_pivot_ratio = min(min_pivot_ratio, pivot_ratio)
                if not pivot_ratio > 0.0:
                    return ("the iteration matrix is singular (zero pivot): check for redundant "
                            "constraints or a toggle position")
            self.sddot_before[:], self.lam_before[:] = sddot, lam
            dq = _newton_update(G, piv, M, sddot, Phi_s, lam, Q, Phi, qhat, vhat, beta_p, gamma_p,
                                self.rhs, q, v)
            counts["n_newton"] += 1
            iterations += 1
            # contraction of the increments (Hairer & Wanner II, sec. IV.8), across refactorisations
            theta = dq / prev_dq if math.isfinite(prev_dq) and prev_dq > 0.0 else 0.0
            if not math.isfinite(dq):
                # NaN or inf anywhere in M, Q, Phi, Phi_s or the matrix reaches the increment
                return "the Newton increment is not finite (non-finite model output?)"
            # error left in the iterate: about theta |dq| < |dq| / 4 (see below). The cheaper test
            # theta / (1 - theta) |dq| <= tol (Hairer & Wanner II, sec. IV.8) was tried and
            # accepted errors of ~100 tol in the elastic coordinates: a stale matrix contracts
            # unevenly over 2-3 iterates. A candidate is accepted once Phi at it is also below tol
            # times the row sums of Phi_s (checked above, in the evaluation the next iteration
            # would need anyway).
            if dq <= abs_tol:
                candidate = True
                continue
            if iterations >= max_iterations:
                return (f"Newton's method did not converge in {iterations} iterations (last "
                        f"position increment {dq:.3g}, tolerance {abs_tol:.3g})")
            wild = dq > self.max_increment
            if wild and exact:
                return (f"Newton's method diverged (position increment {dq:.3g} larger than the "
                        f"configuration scale {self.max_increment:.3g})")
            if (theta > 1.0 or wild) and not exact:
                # a growing increment from a matrix evaluated elsewhere (an earlier iterate or
                # step): on strongly nonlinear links (geometric stiffening couples the stiff axial
                # and the bending coordinates) one such increment can throw the iterate out of
                # Newton's region of convergence (the arm and four-bar scenes did). Undo it and
                # take a true Newton step from the previous iterate instead.
                sddot[:], lam[:] = self.sddot_before, self.lam_before
                np.add(qhat, beta_p * sddot, out=q)
                np.add(vhat, gamma_p * sddot, out=v)
                self.tangent_h = None
                continue
            prev_dq = dq
            # growing increments with the exact Jacobian: outside Newton's region of convergence;
            # two in a row end the attempt (the caller then retries with a smaller step) instead
            # of iterating to overflow
            growths = growths + 1 if theta > 1.0 else 0
            if growths >= 2:
                return f"Newton's method diverged (position increment {dq:.3g})"
            # contracting too slowly: re-evaluate the matrix at this iterate. An evaluation costs
            # about one iteration, and at theta = 0.25 the stale matrix gains only 0.6 digits per
            # iteration, whereas a fresh one converges quadratically.
            if theta > 0.25 or full_newton:
                self.tangent_h = None

    def advance_alpha_acceleration(self, a, sddot_old):
        """(GA1) for the step just solved: ``a`` becomes ``a_{n+1}``; the lag states move on with it."""
        _advance_alpha_acceleration(a, sddot_old, self.sddot, self.alpha_m, self.alpha_f)
        if self.lags is not None:
            self.lags.commit(self.q, self.v, self.t)


class _Lags:
    """The states ``y`` (N m) of a model's lagged controllers, ``tau y' + y = u(t, s, s')``
    (``Model.lag_inputs_along``), integrated with each step by the trapezoidal rule (order 2, A-stable,
    as the generalized-alpha step):

        y_{n+1} = ((1 - r) y_n + r (u_n + u_{n+1})) / (1 + r),     r = h / (2 tau),

    implicit in the step's unknowns through ``u_{n+1}``: Newton's forces get ``h_i y_{n+1}`` and its
    Jacobians ``h_i r / (1 + r) du/ds`` (and ``du/ds'``), so the step solves the mechanism and its
    lags together.  ``y`` starts at 0 (the lag at rest; ``u`` is 0 on the nominal motion)."""

    def __init__(self, model):
        self.model = model
        self.tau = np.asarray(model.lag_time_constants, dtype=float)
        self.gradients = np.asarray(model.lag_gradients, dtype=float)   # (L, n)
        self.y = np.zeros(self.tau.size)
        self.u = None              # the input at the committed state (None before the first step)
        self.ratio = np.zeros(self.tau.size)
        self.history = [self.y.copy()]

    def _input(self, q, v, t):
        u, du_ds, du_dv = self.model.lag_inputs_along(np.array([t], dtype=float), q[None], v[None])
        return u[0], du_ds[0], du_dv[0]

    def start(self, q, v, t, y0=None):
        """The states ``y0`` (default 0) and the input at the initial state (once, before the first step)."""
        if y0 is not None:
            self.y = np.array(y0, dtype=float)
            self.history = [self.y.copy()]
        self.u = self._input(q, v, t)[0]

    def begin(self, h):
        self.ratio = 0.5 * h / self.tau

    def _next(self, u_new):
        r = self.ratio
        return ((1.0 - r) * self.y + r * (self.u + u_new)) / (1.0 + r)

    def force(self, q, v, t):
        """``sum_i h_i y_{n+1, i}`` (n,) at the iterate ``q, v`` of the step to ``t``."""
        return self._next(self._input(q, v, t)[0]) @ self.gradients

    def add_force_jacobians(self, q, v, t, dQ_ds, dQ_dv):
        _, du_ds, du_dv = self._input(q, v, t)
        weights = self.gradients.T * (self.ratio / (1.0 + self.ratio))    # (n, L)
        return dQ_ds + weights @ du_ds, dQ_dv + weights @ du_dv

    def commit(self, q, v, t):
        """The step to ``t`` converged at ``q, v``: move the states on."""
        u_new = self._input(q, v, t)[0]
        self.y, self.u = self._next(u_new), u_new

    def snapshot(self):
        return self.y.copy(), self.u.copy()

    def restore(self, saved):
        self.y, self.u = saved[0].copy(), saved[1].copy()


def _integrate(model, q0, v0, t0, h, n_steps, rho, abs_tol, max_iterations, jacobian_reuse,
               max_halvings, length_scale, perturbed_start, lag0=None):
    """The generalized-alpha loop on the uniform grid ``t0 + k h``; a step whose Newton solve fails
    is retried as 2, 4, ..., ``2**max_halvings`` equal substeps. Returns a dict of the arrays and
    counts (see ``simulate``)."""
    n = q0.shape[0]
    r = int(model.n_constraints)
    stepper = _Stepper(model, rho, abs_tol, max_iterations, jacobian_reuse, length_scale)
    if stepper.lags is not None:
        stepper.lags.start(q0, v0, t0, lag0)

    t_grid = t0 + h * np.arange(n_steps + 1)
    S = np.empty((n_steps + 1, n))
    V = np.empty((n_steps + 1, n))
    A = np.empty((n_steps + 1, n))
    L = np.empty((n_steps + 1, r))
    residual = np.empty(n_steps + 1)

    # the lags' force at t0 is part of Q in the index-1 equations, as in every step's
    start_force = None if stepper.lags is None else _lag_force(model, stepper.lags.y)
    sddot0, lam0 = _consistent_accelerations(model, q0, v0, t0, start_force)
    S[0], V[0], A[0], L[0] = q0, v0, sddot0, lam0
    residual[0] = np.max(np.abs(model.constraints(q0, t0)), initial=0.0)

    if perturbed_start:
        a = _perturbed_alpha_acceleration(model, q0, v0, sddot0, t0,
                                          (stepper.alpha_m - stepper.alpha_f) * h)
    else:
        a = sddot0.copy()      # alpha acceleration a_0 = sddot_0: an O(h) error in a_0
    n_rejected, n_substeps, status, message, done = 0, 0, 0, "", 0
    for step in range(1, n_steps + 1):
        t = t_grid[step]
        # predictor: linear extrapolation of sddot and lam (an O(h^2) guess, about one Newton
        # iteration fewer per step than sddot_{n+1} = sddot_n)
        failure = stepper.solve(S[step - 1], V[step - 1], a, A[step - 1], L[step - 1],
                                A[max(step - 2, 0)], L[max(step - 2, 0)], step >= 2, t, h)
        if failure and max_halvings:
            n_rejected += 1
            failure, failed_subdivisions, substeps = _substeps(
                stepper, S[step - 1], V[step - 1], a, A[step - 1], L[step - 1], t - h, h,
                max_halvings)
            n_rejected += failed_subdivisions
            n_substeps += substeps
        elif not failure:
            stepper.advance_alpha_acceleration(a, A[step - 1])
        if failure:
            status = -1
            retried = f" (also in {2 ** max_halvings} substeps)" if max_halvings else ""
            message = (f"generalized-alpha failed in the step from t = {t - h:.9g} s to "
                       f"t = {t:.9g} s: {failure}{retried}. Try a smaller `dt` or `rho_inf`, or "
                       "check the initial state.")
            break
        S[step], V[step], A[step], L[step] = stepper.q, stepper.v, stepper.sddot, stepper.lam
        residual[step] = stepper.residual
        if stepper.lags is not None:
            stepper.lags.history.append(stepper.lags.y.copy())
        done = step
    if status == 0:
        message = (f"generalized-alpha reached t = {t_grid[-1]:.9g} s in {n_steps} steps of "
                   f"{h:.6g} s")
        message += (f" ({n_rejected} rejected and retried in {n_substeps} substeps)."
                    if n_rejected else ".")
    end = done + 1
    return {"t": t_grid[:end], "s": S[:end], "sdot": V[:end], "sddot": A[:end], "lam": L[:end],
            "residual": residual[:end], "n_steps": done, "n_rejected": n_rejected,
            "n_substeps": n_substeps, "status": status, "message": message,
            "min_pivot_ratio": float(stepper.min_pivot_ratio), **stepper.counts,
            "lag_states": (np.zeros((end, 0)) if stepper.lags is None
                           else np.array(stepper.lags.history[:end]))}


def _perturbed_alpha_acceleration(model, q0, v0, sddot0, t0, delta):
    """Arnold & Bruls' (2007, sec. 4) perturbed starting value ``a_0 = sddot(t0 + delta)``, with
    ``delta = (alpha_m - alpha_f) h``, to O(h^2).

    (GA1) holds with an O(h^2) defect only when ``a_n`` approximates ``sddot(t_n + delta)``; the
    plain start ``a_0 = sddot_0`` is off by O(h), which the multipliers and accelerations carry
    as an O(h) error through the first steps (decaying like ``(alpha_m / alpha_f)^n``). Here
    ``sddot(t0 + delta) = sddot_0 + (sddot_+ - sddot_-) / 2 + O(delta^3)`` from the index-1
    accelerations at the Taylor states ``q0 +- delta v0 + delta^2 / 2 sddot_0``,
    ``v0 +- delta sddot_0`` and ``t0 +- delta`` (central difference of ``sddot``)."""
    if delta == 0.0:
        return sddot0.copy()
    sides = []
    for sign in (1.0, -1.0):
        d = sign * delta
        q = q0 + d * v0 + 0.5 * d * d * sddot0
        v = v0 + d * sddot0
        sides.append(_consistent_accelerations(model, q, v, t0 + d)[0])
    return sddot0 + 0.5 * (sides[0] - sides[1])


def _substeps(stepper, q_n, v_n, a, sddot_n, lam_n, t_n, h, max_halvings):
    """Retry the step from ``t_n`` as ``2**k`` equal substeps, k = 1 ... ``max_halvings``, until
    all of them converge (full Newton from constant predictors: the extrapolation's history has the
    wrong spacing).
    On success the end state is in ``stepper`` and ``a`` (in place) is its alpha acceleration.
    Returns (failure or "", failed attempts after the full step's, substeps taken)."""
    q, v, a_n = np.empty_like(q_n), np.empty_like(v_n), a.copy()
    sddot, lam = np.empty_like(sddot_n), np.empty_like(lam_n)
    lags_n = stepper.lags.snapshot() if stepper.lags is not None else None
    failure = ""
    for level in range(1, max_halvings + 1):
        m = 2 ** level
        hs = h / m
        q[:], v[:], a[:], sddot[:], lam[:] = q_n, v_n, a_n, sddot_n, lam_n
        if lags_n is not None:
            stepper.lags.restore(lags_n)
        for j in range(1, m + 1):
            failure = stepper.solve(q, v, a, sddot, lam, sddot, lam, False, t_n + j * hs, hs,
                                    full_newton=True)
            if failure:
                break
            stepper.advance_alpha_acceleration(a, sddot)
            q[:], v[:], sddot[:], lam[:] = stepper.q, stepper.v, stepper.sddot, stepper.lam
        if not failure:
            logger.debug("step from t = %.9g s taken in %d substeps", t_n, m)
            stepper.drop_tangent()     # the next full step needs tangent terms scaled for h
            return "", level - 1, m
    a[:] = a_n
    return failure, max_halvings, 0


# ---------------------------------------------------------------------------------------------------
# Tangent of the discrete step map (for shooting: the monodromy of a run)
# ---------------------------------------------------------------------------------------------------
def _propagate_tangent(model, run: Mapping[str, Any], h: float, rho_inf: float, start: np.ndarray,
                       lag_start: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Carry the sensitivity of the integrator's state through the converged steps of ``run``.

    ``start`` (4, n, p): d(q, v, a, sddot) / d(p start parameters) at ``t0``; ``lag_start`` (L, p)
    d y / d(parameters) of the model's L lag states (default 0). Returns the same two at the run's
    last step. Differentiating (GA1)-(GA3) and the converged step equations (NR) gives, per step,
    with the Jacobians at the new state (``q, v, sddot, lam`` at ``t_{n+1}``):

        G [d sddot_{n+1}; d lam_{n+1}] = -[K_t d qhat + C_t d vhat - H^T d c_n;  Phi_s d qhat / beta']

    ``G`` the exact iteration matrix of (NR) (``K_t``, ``C_t`` from ``linear_terms_along``: the
    same analytic derivatives Newton uses), ``d qhat``, ``d vhat`` the differentiated predictors of
    ``_start_step``; then ``d q = d qhat + beta' d sddot``, ``d v = d vhat + gamma' d sddot`` and
    (GA1) for ``d a``. ``lam`` does not enter the next step (only its predictor), so the state is
    (q, v, a, sddot). The run must have taken every step at ``h`` (no substeps): the caller checks
    ``run["n_substeps"]``. A singular ``G`` gives NaN sensitivities.

    Lags (``_Lags``): ``y_{n+1} = c_n + w u(q_{n+1}, v_{n+1})`` with the known part ``c_n = ((1 - r)
    y_n + r u_n) / (1 + r)``, ``w = r / (1 + r)``, enters Q as ``H^T y_{n+1}`` (``H`` the lags'
    gradients, (L, n)): ``K_t``, ``C_t`` gain ``-H^T w du/ds``, ``-H^T w du/ds'`` (the terms
    ``_Lags.add_force_jacobians`` gives Newton) and the right-hand side the known part ``d c_n``.
    """
    from ._batch import linear_terms_along

    alpha_m, alpha_f, beta, gamma = _generalized_alpha_parameters(rho_inf)
    beta_p = h * h * beta * (1.0 - alpha_f) / (1.0 - alpha_m)
    gamma_p = h * gamma * (1.0 - alpha_f) / (1.0 - alpha_m)
    terms = linear_terms_along(model, run["t"][1:], run["s"][1:], run["sdot"][1:],
                               run["sddot"][1:], run["lam"][1:])
    state = np.array(start, dtype=np.float64, order="C")
    lags = _LagTangent(model, run, h, state.shape[2], lag_start)
    stiffness, damping = lags.with_force_jacobians(terms.stiffness, terms.damping)
    _tangent_steps(np.ascontiguousarray(terms.mass), np.ascontiguousarray(stiffness),
                   np.ascontiguousarray(damping), np.ascontiguousarray(terms.jacobian), h,
                   alpha_m, alpha_f, beta, gamma, beta_p, gamma_p, state, lags.gradients,
                   lags.decay, lags.weight, lags.du_ds, lags.du_dv, lags.state)
    return state, lags.state


class _LagTangent:
    """The lag terms of ``_propagate_tangent`` along ``run``: ``gradients`` H (L, n), per lag the
    trapezoidal rule's ``decay`` (1 - r) / (1 + r) and ``weight`` r / (1 + r) (L,), the inputs'
    derivatives ``du_ds``, ``du_dv`` (N+1, L, n) at the run's states and the sensitivity ``state``
    (L, p) (L = 0 without lags: empty arrays, and the kernel's lag loops do nothing)."""

    def __init__(self, model, run, h, n_columns, lag_start):
        n, n_samples = run["s"].shape[1], run["s"].shape[0]
        n_lags = len(getattr(model, "lag_names", ()))
        self.state = (np.zeros((n_lags, n_columns)) if lag_start is None
                      else np.array(lag_start, dtype=np.float64, order="C").reshape(n_lags, n_columns))
        if not n_lags:
            self.gradients = np.zeros((0, n))
            self.decay = self.weight = np.zeros(0)
            self.du_ds = self.du_dv = np.zeros((n_samples, 0, n))
            return
        ratio = 0.5 * h / np.asarray(model.lag_time_constants, dtype=np.float64)
        self.decay, self.weight = (1.0 - ratio) / (1.0 + ratio), ratio / (1.0 + ratio)
        self.gradients = np.ascontiguousarray(model.lag_gradients, dtype=np.float64)
        _, du_ds, du_dv = model.lag_inputs_along(run["t"], run["s"], run["sdot"])
        self.du_ds = np.ascontiguousarray(du_ds, dtype=np.float64)
        self.du_dv = np.ascontiguousarray(du_dv, dtype=np.float64)

    def with_force_jacobians(self, stiffness, damping):
        """``K_t``, ``C_t`` (N, n, n) at the steps' new states with the lag force's Jacobians (the
        arrays themselves without lags)."""
        if not self.decay.size:
            return stiffness, damping
        weighted = self.gradients.T * self.weight                      # (n, L)
        return (stiffness - weighted @ self.du_ds[1:], damping - weighted @ self.du_dv[1:])


@numba.njit(cache=True)
def _tangent_steps(mass, K, C, Phi_s, h, alpha_m, alpha_f, beta, gamma, beta_p, gamma_p, state,
                   lag_gradients, lag_decay, lag_weight, du_ds, du_dv, lag_state):
    """The step loop of ``_propagate_tangent``, in place on ``state`` (4, n, p) = d(q, v, a, sddot)
    and ``lag_state`` (L, p) = d y: per step the differentiated predictors (``_start_step``) and the
    known part of the lags, ``d c_n = decay d y_n + weight (du/ds d q_n + du/ds' d v_n)``, the exact
    iteration matrix from ``mass``, ``K``, ``C`` (N, n, n, the lags' force Jacobians included) and
    ``Phi_s`` (N, r, n) factorised (LAPACK) and solved for the p columns (right-hand side with
    ``lag_gradients^T d c_n``), then (GA2), (GA3), (GA1) and ``d y_{n+1} = d c_n + weight (du/ds
    d q_{n+1} + du/ds' d v_{n+1})``; ``du_ds``, ``du_dv`` (N+1, L, n) at the grid's states. A zero
    pivot fills ``state`` with NaN.

    One factorisation per step replaced a batched ``np.linalg.inv`` of all N matrices and BLAS
    products: 11 ms instead of 17 ms per period on ``four_bar_fem4`` (N = 256, n + r = 30, p = 24),
    and no BLAS threads, which on a loaded machine made the old kernel ~100x slower."""
    n, p = state.shape[1], state.shape[2]
    r = Phi_s.shape[1]
    dq, dv, da, dsddot = state[0], state[1], state[2], state[3]
    dqhat = np.empty((n, p))
    dvhat = np.empty((n, p))
    tangent = np.empty((n, n))
    G_T = np.empty((n + r, n + r))
    piv = np.empty(n + r, dtype=np.int32)
    solution = np.empty((n + r, p))       # the right-hand sides, then d(sddot, lam), as columns
    n_lags = lag_state.shape[0]
    lag_known = np.empty((n_lags, p))     # d c_n, the lags' part known at t_n
    for step in range(mass.shape[0]):
        _lag_input_change(du_ds[step], du_dv[step], dq, dv, lag_weight, lag_known)
        for k in range(n_lags):
            for j in range(p):
                lag_known[k, j] += lag_decay[k] * lag_state[k, j]
        for i in range(n):
            for j in range(p):
                da_known = (alpha_f * dsddot[i, j] - alpha_m * da[i, j]) / (1.0 - alpha_m)
                dqhat[i, j] = dq[i, j] + h * dv[i, j] + h * h * ((0.5 - beta) * da[i, j]
                                                                 + beta * da_known)
                dvhat[i, j] = dv[i, j] + h * ((1.0 - gamma) * da[i, j] + gamma * da_known)
        for j in range(p):
            for i in range(n):
                acc = 0.0
                for k in range(n):
                    acc += K[step, i, k] * dqhat[k, j] + C[step, i, k] * dvhat[k, j]
                solution[i, j] = -acc
                for k in range(n_lags):
                    solution[i, j] += lag_gradients[k, i] * lag_known[k, j]
            for k in range(r):
                acc = 0.0
                for i in range(n):
                    acc += Phi_s[step, k, i] * dqhat[i, j]
                solution[n + k, j] = -acc / beta_p
        for i in range(n):
            for j in range(n):
                tangent[i, j] = beta_p * K[step, i, j] + gamma_p * C[step, i, j]
        _fill_iteration_matrix(mass[step], tangent, Phi_s[step], G_T)
        if not _lu_factor(G_T, piv) > 0.0:
            state[:] = np.nan
            lag_state[:] = np.nan
            return
        lapack.solve_columns_loops(G_T, piv, solution, False)
        for i in range(n):
            for j in range(p):
                dsddot_new = solution[i, j]
                dq[i, j] = dqhat[i, j] + beta_p * dsddot_new
                dv[i, j] = dvhat[i, j] + gamma_p * dsddot_new
                da[i, j] = (alpha_f * dsddot[i, j] + (1.0 - alpha_f) * dsddot_new
                            - alpha_m * da[i, j]) / (1.0 - alpha_m)
                dsddot[i, j] = dsddot_new
        _lag_input_change(du_ds[step + 1], du_dv[step + 1], dq, dv, lag_weight, lag_state)
        for k in range(n_lags):
            for j in range(p):
                lag_state[k, j] += lag_known[k, j]


@numba.njit(cache=True)
def _lag_input_change(du_ds, du_dv, dq, dv, weight, out):
    """``out[k] = weight[k] (du_ds[k] dq + du_dv[k] dv)`` (L, p), the weighted change of the lags'
    inputs ``u`` (L,) for the changes ``dq``, ``dv`` (n, p) of the state; ``du_ds``, ``du_dv`` (L, n)."""
    for k in range(out.shape[0]):
        for j in range(out.shape[1]):
            acc = 0.0
            for i in range(dq.shape[0]):
                acc += du_ds[k, i] * dq[i, j] + du_dv[k, i] * dv[i, j]
            out[k, j] = weight[k] * acc
