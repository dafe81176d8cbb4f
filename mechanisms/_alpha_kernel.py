"""The fused generalized-alpha step: one numba call runs the whole Newton iteration of a step (``_newton``:
residual, Jacobian, LU and update, the same iteration as ``_alpha_step._Stepper._newton`` line for line),
on the model's tables, with the time-dependent terms of the step's time evaluated once by the caller
(``StepKernel.at``): the drive rows' angles, the torque drives' and the lagged controllers' constant
parts. The Python path (``_Stepper._newton``, a chain of calls into the model's methods) cost about
2.5 ms a step on the six-bar, most of it the calls' and the wrappers' overhead (docs/benchmarks.md).

The torque laws the kernel evaluates are the affine ones: per term k (a torque drive or a lag)

    tau_k = c_k(t) + P_k . s + D_k . s',    Q += tau_k g_k,

with a motor's command ``tau_k + e_k g_k . s'`` clipped to ``+-command_limit`` and ``tau_k`` to
``+-torque_limit`` (``Model._torque_terms``); a lag's term is its state ``y_{n+1}`` of the trapezoidal
rule (``_alpha_step._Lags``), ``c = ((1 - r) y_n + r (u_n + u0(t))) / (1 + r)``, ``P, D`` its law's gains
times ``r / (1 + r)``. A controller's feedback of an observable nonlinear in ``s`` is not affine: such a
model has no ``StepKernel`` (``Model.step_kernel`` returns None) and keeps the Python path.
"""
from __future__ import annotations

import math

import numba
import numpy as np

from periodic import lapack

from . import _kernels
from ._parts import drive_law

# failure codes of ``_newton`` (0: converged); ``StepKernel.failure`` words them
STALLED, SINGULAR, NOT_FINITE, NO_CONVERGENCE, WILD, DIVERGED = 1, 2, 3, 4, 5, 6

# no_cfunc_wrapper on every kernel here and in _alpha_step, _alpha_tangent: none is passed as a
# first-class function, and the C wrapper numba builds for that is first-run compilation for nothing.

@numba.njit(cache=True, no_cfunc_wrapper=True)
def _affine_torques(s, v, grad, const, pos_gain, rate_gain, back_emf, command_limit, torque_limit,
                    out, d_s, d_v, jacobians):
    """``out += tau_k g_k`` over the affine torque terms (module docstring), and with ``jacobians``
    ``d_s += g_k dtau_k/ds^T``, ``d_v += g_k dtau_k/ds'^T``; ``grad, pos_gain, rate_gain`` (m, n)."""
    n = s.shape[0]
    for k in range(grad.shape[0]):
        tau = const[k]
        for j in range(n):
            tau += pos_gain[k, j] * s[j] + rate_gain[k, j] * v[j]
        free = True        # the law's derivatives hold (not clipped)
        emf_only = False   # clipped command: dtau/ds = 0, dtau/ds' = -e g
        if command_limit[k] < math.inf:
            emf = 0.0
            for j in range(n):
                emf += grad[k, j] * v[j]
            emf *= back_emf[k]
            command = tau + emf
            if abs(command) > command_limit[k]:
                free, emf_only = False, True
            tau = min(max(command, -command_limit[k]), command_limit[k]) - emf
        if torque_limit[k] < math.inf:
            if abs(tau) > torque_limit[k]:
                free, emf_only = False, False
            tau = min(max(tau, -torque_limit[k]), torque_limit[k])
        for i in range(n):
            out[i] += tau * grad[k, i]
        if not jacobians:
            continue
        for i in range(n):
            g = grad[k, i]
            if g == 0.0:
                continue
            if free:
                for j in range(n):
                    d_s[i, j] += g * pos_gain[k, j]
                    d_v[i, j] += g * rate_gain[k, j]
            elif emf_only:
                for j in range(n):
                    d_v[i, j] -= g * back_emf[k] * grad[k, j]


@numba.njit(cache=True, no_cfunc_wrapper=True)
def _constraint_values(q, phi0, h_lin, drive_rows, drive_angles, ct_int, ct_real, shp, idx, out):
    """``Phi(q, t)`` (r,) as ``Model.constraints``: constant part, drive rows (their angles at t
    given), the kernel's terms."""
    for k in range(out.shape[0]):
        acc = 0.0
        for j in range(q.shape[0]):
            acc += h_lin[k, j] * q[j]
        out[k] = phi0[k] + acc
    for d in range(drive_rows.shape[0]):
        out[drive_rows[d]] -= drive_angles[d]
    _kernels.constraints(q.reshape((1, q.shape[0])), ct_int, ct_real, shp, idx, out.reshape((1, out.shape[0])))


@numba.njit(cache=True, no_cfunc_wrapper=True)
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


@numba.njit(cache=True, no_cfunc_wrapper=True)
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


@numba.njit(cache=True, no_cfunc_wrapper=True)
def _newton(q_n, v_n, a_n, sddot_n, lam_n, sddot_prev, lam_prev, extrapolate, h, beta_p, gamma_p,
            full_newton, tangent_valid, alpha_m, alpha_f, beta, gamma, abs_tol, max_iterations,
            max_increment, gx, gy, mp_int, mp_real, sp_int, sp_real, shp, idx, k0, c0, ct_int,
            ct_real, phi0, h_lin, drive_rows, drive_angles, grad, const, pos_gain, rate_gain,
            back_emf, command_limit, torque_limit, q, v, sddot, lam, qhat, vhat, tangent, G, piv,
            counts, info):
    """Newton's method on the step equations (NR) of ``_alpha_step`` from ``t - h`` to ``t``: the
    iteration of ``_Stepper._newton`` (predictor, modified Newton with the kept tangent terms
    ``tangent`` (n, n) when ``tangent_valid``, the undo of a growing stale increment, acceptance by
    increment and constraint residual) in one call. ``q, v, sddot, lam, qhat, vhat`` receive the
    iterates, ``G`` (n + r, n + r) and ``piv`` the factorised matrix; ``counts`` (3,) int64 gets the
    Newton iterations, Jacobian evaluations and factorisations added.

    Returns ``(code, tangent_valid, iterations)``: code 0 (converged; ``info[0]`` the constraint
    residual, ``info[1]`` the smallest pivot ratio) or a failure code of this module with its
    numbers in ``info[2:4]``."""
    n = q.shape[0]
    r = lam.shape[0]
    M = np.empty((n, n))
    Q = np.empty(n)
    Phi = np.empty(r)
    Phi_s = np.empty((r, n))
    d_s = np.empty((n, n))
    d_v = np.empty((n, n))
    d_ma = np.empty((n, n))
    d_lam = np.empty((n, n))
    rhs = np.empty(n + r)
    sddot_before = np.empty(n)
    lam_before = np.empty(r)
    # one-sample views for the model kernels, which take samples along a leading axis
    q_row, v_row, sddot_row = q.reshape((1, n)), v.reshape((1, n)), sddot.reshape((1, n))
    lam_row, Q_row = lam.reshape((1, r)), Q.reshape((1, n))
    M_row, Phi_s_row = M.reshape((1, n, n)), Phi_s.reshape((1, r, n))
    d_s_row, d_v_row = d_s.reshape((1, n, n)), d_v.reshape((1, n, n))
    d_ma_row, d_lam_row = d_ma.reshape((1, n, n)), d_lam.reshape((1, n, n))
    # the same kernels as the Python path's, so both evaluate the same expressions
    _start_step_values(q_n, v_n, a_n, sddot_n, lam_n, sddot_prev, lam_prev, extrapolate, h, alpha_m,
                       alpha_f, beta, gamma, beta_p, gamma_p, qhat, vhat, sddot, lam, q, v)
    factorized = False
    iterations = 0
    prev_dq = np.inf
    phi_scale = 1.0
    candidate = False
    growths = 0
    min_pivot_ratio = np.inf
    while True:
        _constraint_values(q, phi0, h_lin, drive_rows, drive_angles, ct_int, ct_real, shp, idx, Phi)
        if candidate:
            step_residual = _max_abs_value(Phi)
            if step_residual <= abs_tol * phi_scale:
                info[0] = step_residual
                info[1] = min_pivot_ratio
                return 0, tangent_valid, iterations
            candidate = False
            if iterations >= max_iterations:
                info[2] = step_residual
                info[3] = abs_tol * phi_scale
                return STALLED, tangent_valid, iterations
        M[:, :] = 0.0
        _kernels.mass_matrix(q_row, mp_int, mp_real, shp, idx, M_row)
        Q[:] = 0.0
        _kernels.forces(q_row, v_row, gx, gy, mp_int, mp_real, sp_int, sp_real, shp, idx, k0, c0, Q_row)
        exact = not tangent_valid
        if exact:
            d_s[:, :] = 0.0
            d_v[:, :] = 0.0
            _kernels.force_jacobians(q_row, v_row, gx, gy, mp_int, mp_real, sp_int, sp_real, shp, idx,
                                     k0, c0, d_s_row, d_v_row)
        _affine_torques(q, v, grad, const, pos_gain, rate_gain, back_emf, command_limit,
                        torque_limit, Q, d_s, d_v, exact)
        Phi_s[:, :] = h_lin
        _kernels.constraint_jacobian(q_row, ct_int, ct_real, shp, idx, Phi_s_row)
        if exact:
            d_ma[:, :] = 0.0
            _kernels.mass_matrix_jacobian(q_row, sddot_row, mp_int, mp_real, shp, idx, d_ma_row)
            d_lam[:, :] = 0.0
            _kernels.constraint_force_jacobian(q_row, lam_row, ct_int, ct_real, shp, idx, d_lam_row)
            for i in range(n):
                for j in range(n):
                    tangent[i, j] = (beta_p * (d_ma[i, j] - d_s[i, j] + d_lam[i, j])
                                     - gamma_p * d_v[i, j])
            counts[1] += 1
            tangent_valid = True
            factorized = False
        if not factorized:
            # the matrix transposed (LAPACK's order) with M and Phi_s fresh, the tangent terms kept
            phi_scale = _fill_iteration_matrix(M, tangent, Phi_s, G)
            if lapack.factor_lapack(G, piv):
                pivot_ratio = lapack.pivot_ratio(G)
            else:
                pivot_ratio = 0.0
            counts[2] += 1
            factorized = True
            min_pivot_ratio = min(min_pivot_ratio, pivot_ratio)
            if not pivot_ratio > 0.0:
                return SINGULAR, tangent_valid, iterations
        sddot_before[:] = sddot
        lam_before[:] = lam
        # residual of (NR) and the update (the Python iteration's own kernel)
        dq = _newton_update(G, piv, M, sddot, Phi_s, lam, Q, Phi, qhat, vhat, beta_p, gamma_p, rhs, q, v)
        counts[0] += 1
        iterations += 1
        theta = dq / prev_dq if (np.isfinite(prev_dq) and prev_dq > 0.0) else 0.0
        if not np.isfinite(dq):
            return NOT_FINITE, tangent_valid, iterations
        if dq <= abs_tol:
            candidate = True
            continue
        if iterations >= max_iterations:
            info[2] = dq
            info[3] = abs_tol
            return NO_CONVERGENCE, tangent_valid, iterations
        wild = dq > max_increment
        if wild and exact:
            info[2] = dq
            info[3] = max_increment
            return WILD, tangent_valid, iterations
        if (theta > 1.0 or wild) and not exact:
            # a growing increment from a stale matrix: undo it, take a true Newton step instead
            sddot[:] = sddot_before
            lam[:] = lam_before
            for i in range(n):
                q[i] = qhat[i] + beta_p * sddot[i]
                v[i] = vhat[i] + gamma_p * sddot[i]
            tangent_valid = False
            continue
        prev_dq = dq
        growths = growths + 1 if theta > 1.0 else 0
        if growths >= 2:
            info[2] = dq
            return DIVERGED, tangent_valid, iterations
        if theta > 0.25 or full_newton:
            tangent_valid = False


@numba.njit(cache=True, inline="always", no_cfunc_wrapper=True)
def _max_abs_value(x):
    """``max |x_i|`` (NaN if any entry is NaN), as ``_alpha_step._max_abs``."""
    out = 0.0
    for i in range(x.shape[0]):
        if not abs(x[i]) <= out:
            out = abs(x[i])
            if np.isnan(out):
                return out
    return out


@numba.njit(cache=True, inline="always", no_cfunc_wrapper=True)
def _start_step_values(q, v, a, sddot_n, lam_n, sddot_prev, lam_prev, extrapolate, h, alpha_m,
                       alpha_f, beta, gamma, beta_p, gamma_p, qhat, vhat, sddot, lam, q_new, v_new):
    """The predictor of ``_alpha_step._start_step`` (the same arithmetic)."""
    for i in range(q.shape[0]):
        a_known = (alpha_f * sddot_n[i] - alpha_m * a[i]) / (1.0 - alpha_m)
        qhat[i] = q[i] + h * v[i] + h * h * ((0.5 - beta) * a[i] + beta * a_known)
        vhat[i] = v[i] + h * ((1.0 - gamma) * a[i] + gamma * a_known)
        sddot[i] = 2.0 * sddot_n[i] - sddot_prev[i] if extrapolate else sddot_n[i]
        q_new[i] = qhat[i] + beta_p * sddot[i]
        v_new[i] = vhat[i] + gamma_p * sddot[i]
    for k in range(lam.shape[0]):
        lam[k] = 2.0 * lam_n[k] - lam_prev[k] if extrapolate else lam_n[k]


def _rows(vectors, n):
    """The vectors (each (n,)) as a C-contiguous (m, n) float array."""
    return np.ascontiguousarray(np.array([np.asarray(x, dtype=np.float64) for x in vectors],
                                         dtype=np.float64).reshape(len(vectors), n))


class StepKernel:
    """A ``Model``'s equations as the fused step reads them (``Model.step_kernel``): its tables, the
    prescribed drives' rows and the affine torque terms; ``at(t, lags)`` evaluates the terms of the
    step's time, ``newton(...)`` runs a step's Newton iteration.

    ``tables`` (``_model._Tables``), ``gravity`` (gx, gy) m/s^2, ``period`` s, ``prescribed`` and
    ``torque_drives`` the model's ``_DriveInfo`` tuples, ``lags`` its ``_Lag`` tuple (all with affine
    laws: no ``feedback`` of an observable nonlinear in s)."""

    def __init__(self, tables, gravity, period, prescribed, torque_drives, lags, n_coords):
        self.tables = tables
        self.gx, self.gy = float(gravity[0]), float(gravity[1])
        self.period = period
        self.n = int(n_coords)
        self.prescribed = tuple(prescribed)
        self.torque_drives = tuple(torque_drives)
        self.lags = tuple(lags)
        self.drive_rows = np.array([d.row for d in self.prescribed], dtype=np.int64)
        self.drive_angles = np.zeros(len(self.prescribed))
        n, m_d, m_l = self.n, len(self.torque_drives), len(self.lags)
        infos = self.torque_drives + tuple(lag.law for lag in self.lags)
        self.grad = _rows([info.gradient for info in infos], n)
        self._law_pos = _rows([info.position_gain for info in infos], n)
        self._law_rate = _rows([info.rate_gain for info in infos], n)
        self.pos_gain, self.rate_gain = self._law_pos.copy(), self._law_rate.copy()
        self.const = np.zeros(m_d + m_l)
        # the lags' inputs are the unsaturated laws; the drives' limits as Model._torque_terms reads them
        self.back_emf = np.array([d.back_emf for d in self.torque_drives] + [0.0] * m_l, dtype=np.float64)
        self.command_limit = np.array([d.command_limit for d in self.torque_drives] + [math.inf] * m_l,
                                      dtype=np.float64)
        self.torque_limit = np.array([d.torque_limit for d in self.torque_drives] + [math.inf] * m_l,
                                     dtype=np.float64)
        self._lag_ratio = None

    def _law_constant(self, info, t):
        """``kp angle(t) + kd rate(t) + feedforward(t)`` of a drive law (``Model._torque_terms``)."""
        angle, rate, _ = drive_law(info.drive, self.period, t)
        value = info.kp * angle + info.kd * rate
        if info.feedforward is not None:
            value = value + float(info.feedforward(t))
        return float(value)

    def at(self, t, lags=None):
        """The terms of the step to ``t`` (s): drive angles, torque constants and, with the lags'
        integrator ``lags`` (``_alpha_step._Lags``, its ``begin(h)`` called), their terms."""
        for d, info in enumerate(self.prescribed):
            self.drive_angles[d] = drive_law(info.drive, self.period, t)[0]
        m_d = len(self.torque_drives)
        for k, info in enumerate(self.torque_drives):
            self.const[k] = self._law_constant(info, t)
        if lags is None or not self.lags:
            return
        ratio = lags.ratio
        if self._lag_ratio is None or not np.array_equal(ratio, self._lag_ratio):
            weight = (ratio / (1.0 + ratio))[:, None]
            self.pos_gain[m_d:] = self._law_pos[m_d:] * weight
            self.rate_gain[m_d:] = self._law_rate[m_d:] * weight
            self._lag_ratio = ratio.copy()
        for i, lag in enumerate(self.lags):
            u0 = self._law_constant(lag.law, t)
            self.const[m_d + i] = ((1.0 - ratio[i]) * lags.y[i] + ratio[i] * (lags.u[i] + u0)) / (
                1.0 + ratio[i])

    def bind(self, stepper):
        """The arguments of ``_newton`` that stay the same over a run: the method's parameters and
        tolerances of ``stepper`` (``_alpha_step._Stepper``), this model's arrays, the stepper's
        buffers and ``counts`` (3,) int64, ``info`` (4,) (built once: a step's call passes only the
        state)."""
        tb = self.tables
        return (stepper.alpha_m, stepper.alpha_f, stepper.beta, stepper.gamma, float(stepper.abs_tol),
                int(stepper.max_iterations), float(stepper.max_increment), self.gx, self.gy, tb.mp_int,
                tb.mp_real, tb.sp_int, tb.sp_real, tb.shp, tb.idx, tb.k0, tb.c0, tb.ct_int, tb.ct_real,
                tb.phi0, tb.h_lin, self.drive_rows, self.drive_angles, self.grad, self.const,
                self.pos_gain, self.rate_gain, self.back_emf, self.command_limit, self.torque_limit,
                stepper.q, stepper.v, stepper.sddot, stepper.lam, stepper.qhat, stepper.vhat,
                stepper.tangent, stepper.G, stepper.piv, stepper.kernel_counts, stepper.kernel_info)


#: ``_newton(q_n, v_n, a_n, sddot_n, lam_n, sddot_prev, lam_prev, extrapolate, h, beta_p, gamma_p,
#: full_newton, tangent_valid, *StepKernel.bind(stepper))``
newton = _newton


def failure_message(code, iterations, info):
    """The words of ``_newton``'s failure ``code`` (the Python path's messages)."""
    if code == STALLED:
        return (f"the constraint residual stalled at {info[2]:.3g} > {info[3]:.3g} after "
                f"{iterations} iterations (`tol` below round-off?)")
    if code == SINGULAR:
        return ("the iteration matrix is singular (zero pivot): check for redundant constraints or a "
                "toggle position")
    if code == NOT_FINITE:
        return "the Newton increment is not finite (non-finite model output?)"
    if code == NO_CONVERGENCE:
        return (f"Newton's method did not converge in {iterations} iterations (last position "
                f"increment {info[2]:.3g}, tolerance {info[3]:.3g})")
    if code == WILD:
        return (f"Newton's method diverged (position increment {info[2]:.3g} larger than the "
                f"configuration scale {info[3]:.3g})")
    return f"Newton's method diverged (position increment {info[2]:.3g})"


def compiled() -> bool:
    """Whether ``_newton`` is compiled in this process or saved in numba's disk cache for this source
    (then loading it costs milliseconds, not its compile). The disk check reads the cache's index
    through numba's ``FunctionCache`` (not a public API: any change there reads as "not saved", and
    the caller falls back to the Python iteration or to compiling on a long run)."""
    if _newton.signatures:
        return True
    try:
        return bool(_newton._cache._cache_file._load_index())
    except Exception:  # noqa: BLE001 - numba internals moved or the cache is unreadable: not saved
        return False

