"""An assembled model evaluated along a whole sampled motion, one numba call per quantity.

The nominal motion and ``linearize`` need the model at every sample of a period; through the
model's methods that costs a few Python calls per sample. These kernels loop over the samples inside
numba, calling the same element kernels (``_kernels``), so each result equals the method-by-method
evaluation (tests/test_batch.py):

* ``linear_terms``: mass matrix, residual ``R = M s'' - Q + Phi_s^T lam``, ``D = -dQ/ds'``,
  ``K = d(M s'')/ds - dQ/ds + d(Phi_s^T lam)/ds`` and the constraint Jacobian (linearisation);
* ``inertia_residual``: ``M s'' - Q`` (multipliers of the rigid inverse dynamics);
* ``constraint_terms``: ``Phi``, ``Phi_s``, ``Phi_t`` and ``gamma`` (rates, accelerations, residuals);
* ``continue_positions``: the plain Newton continuation steps of the nominal motion.

They read the model's private tables (``Model._tables``): a change of the tables or of a kernel's
signature must be made here too.
"""

from __future__ import annotations

import numba
import numpy as np

from . import _kernels


@numba.njit(cache=True)
def _linear_terms(S, Sd, Sdd, Lam, gx, gy, mp_int, mp_real, sp_int, sp_real, shp, idx, k0, c0,
                  ct_int, ct_real, h_lin, M, D, K, R, J):
    """Fill M, D, K (N, n, n), R (N, n), J (N, r, n) for the samples S, Sd, Sdd (N, n), Lam (N, r).
    Outputs must be zeroed on entry."""
    n_samples, n = S.shape
    Q = np.zeros(n)
    dQ_ds = np.zeros((n, n))
    for k in range(n_samples):
        s, sdot, sddot, lam = S[k], Sd[k], Sdd[k], Lam[k]
        _kernels.mass_matrix(s, mp_int, mp_real, shp, idx, M[k])
        Q[:] = 0.0
        _kernels.forces(s, sdot, gx, gy, mp_int, mp_real, sp_int, sp_real, shp, idx, k0, c0, Q)
        dQ_ds[:, :] = 0.0
        _kernels.force_jacobians(s, sdot, gx, gy, mp_int, mp_real, sp_int, sp_real, shp, idx, k0,
                                 c0, dQ_ds, D[k])
        _kernels.mass_matrix_jacobian(s, sddot, mp_int, mp_real, shp, idx, K[k])
        _kernels.constraint_force_jacobian(s, lam, ct_int, ct_real, shp, idx, K[k])
        J[k, :, :] = h_lin
        _kernels.constraint_jacobian(s, ct_int, ct_real, shp, idx, J[k])
        for a in range(n):
            acc = -Q[a]
            for b in range(n):
                acc += M[k, a, b] * sddot[b]
                K[k, a, b] -= dQ_ds[a, b]
                D[k, a, b] = -D[k, a, b]
            for row in range(lam.shape[0]):
                acc += J[k, row, a] * lam[row]
            R[k, a] = acc


def linear_terms(model, t, S, Sd, Sdd, Lam):
    """``(M, D, K, R, Phi_s)`` along samples ``S, Sd, Sdd`` (N, n), ``Lam`` (N, r) at times ``t``
    (N,) for an assembled ``Model``: shapes (N, n, n) x 3, (N, n), (N, r, n); see the module
    docstring. Torque drives (whose law is Python) are added here, vectorised."""
    n_samples, n = S.shape
    r = model.n_constraints
    M = np.zeros((n_samples, n, n))
    D = np.zeros((n_samples, n, n))
    K = np.zeros((n_samples, n, n))
    R = np.zeros((n_samples, n))
    J = np.zeros((n_samples, r, n))
    S, Sd, Sdd, Lam = (np.ascontiguousarray(a, dtype=np.float64) for a in (S, Sd, Sdd, Lam))
    tb = model._tables
    _linear_terms(S, Sd, Sdd, Lam, model._gx, model._gy, tb.mp_int, tb.mp_real, tb.sp_int,
                  tb.sp_real, tb.shp, tb.idx, tb.k0, tb.c0, tb.ct_int, tb.ct_real, tb.h_lin,
                  M, D, K, R, J)
    for info in model._torque_drives:
        # tau h enters Q; its derivatives are -kp h h^T (positions) and -kd h h^T (rates).
        h = info.gradient
        hh = np.outer(h, h)
        torque = np.array([model._torque(info, S[k], Sd[k], t[k]) for k in range(n_samples)])
        R -= torque[:, None] * h
        K += info.drive.kp * hh
        D += info.drive.kd * hh
    return M, D, K, R, J


@numba.njit(cache=True)
def _inertia_residual(S, Sd, Sdd, gx, gy, mp_int, mp_real, sp_int, sp_real, shp, idx, k0, c0, out):
    """out[k] = M(S[k]) Sdd[k] - Q(S[k], Sd[k]) without the torque drives; out zeroed on entry."""
    n_samples, n = S.shape
    M = np.zeros((n, n))
    Q = np.zeros(n)
    for k in range(n_samples):
        M[:, :] = 0.0
        Q[:] = 0.0
        _kernels.mass_matrix(S[k], mp_int, mp_real, shp, idx, M)
        _kernels.forces(S[k], Sd[k], gx, gy, mp_int, mp_real, sp_int, sp_real, shp, idx, k0, c0, Q)
        for a in range(n):
            acc = -Q[a]
            for b in range(n):
                acc += M[a, b] * Sdd[k, b]
            out[k, a] = acc


def inertia_residual(model, t, S, Sd, Sdd):
    """``M(s) s'' - Q(s, s', t)`` (N, n) along samples ``S, Sd, Sdd`` (N, n) at times ``t`` (N,) of
    an assembled ``Model``, torque drives included."""
    S, Sd, Sdd = (np.ascontiguousarray(a, dtype=np.float64) for a in (S, Sd, Sdd))
    out = np.zeros(S.shape)
    tb = model._tables
    _inertia_residual(S, Sd, Sdd, model._gx, model._gy, tb.mp_int, tb.mp_real, tb.sp_int,
                      tb.sp_real, tb.shp, tb.idx, tb.k0, tb.c0, out)
    for info in model._torque_drives:
        torque = np.array([model._torque(info, S[k], Sd[k], t[k]) for k in range(len(t))])
        out -= torque[:, None] * info.gradient
    return out


@numba.njit(cache=True)
def _continue_positions(s, start, drive_rows, drive_angles, rigid, phi0, h_lin, ct_int, ct_real,
                        shp, idx, newton_stop, max_correction, column_scale, max_iterations):
    """Positions s[k] (in place) for k = start.. by continuation: predictor the quadratic
    extrapolation of s[k-3..k-1], then Newton on the rigid coordinates. Returns the first k whose
    Newton did not converge or corrected more than ``max_correction`` (scaled), or len(s)."""
    n_samples, n = s.shape
    r = phi0.shape[0]
    n_rigid = rigid.shape[0]
    phi = np.empty(r)
    jac = np.empty((r, n))
    jac_r = np.empty((r, n_rigid))
    for k in range(start, n_samples):
        q = 3.0 * s[k - 1] - 3.0 * s[k - 2] + s[k - 3]
        total = 0.0
        converged = False
        for _ in range(max_iterations):
            # Phi = phi0 + h_lin s - drive angle (drive rows) + point-constraint terms.
            for i in range(r):
                acc = phi0[i]
                for j in range(n):
                    acc += h_lin[i, j] * q[j]
                phi[i] = acc
            for d in range(drive_rows.shape[0]):
                phi[drive_rows[d]] -= drive_angles[k, d]
            _kernels.constraints(q, ct_int, ct_real, shp, idx, phi)
            if np.abs(phi).max() < newton_stop:
                converged = True
                break
            jac[:, :] = h_lin
            _kernels.constraint_jacobian(q, ct_int, ct_real, shp, idx, jac)
            for i in range(r):
                for j in range(n_rigid):
                    jac_r[i, j] = jac[i, rigid[j]]
            step = np.linalg.solve(jac_r, phi)
            for j in range(n_rigid):
                q[rigid[j]] -= step[j]
                total = max(total, abs(step[j] / column_scale[j]))
        if not converged or total >= max_correction:
            return k
        s[k] = q
    return n_samples


def continue_positions(model, s, start, times, *, newton_stop, max_correction, column_scale):
    """Fill ``s[start:]`` (N+1, n) by fast continuation (see ``_continue_positions``) for an
    assembled ``Model``; returns the first sample it could not do (``len(s)`` when all are done).
    Needs ``start >= 3``; ``column_scale`` (n_rigid,) scales the corrections as the caller's
    careful path does."""
    from ._assemble import drive_law

    tb = model._tables
    rows = np.asarray(model.drive_rows, dtype=np.int64)
    times = np.asarray(times, dtype=float)
    angles = np.zeros((len(times), len(rows)))
    for j, info in enumerate(model._prescribed):     # same order as model.drive_rows
        angles[:, j] = drive_law(info.drive, model.period, times)[0]
    rigid = np.asarray(model.rigid_index, dtype=np.int64)
    return _continue_positions(s, start, rows, angles, rigid, tb.phi0, tb.h_lin, tb.ct_int,
                               tb.ct_real, tb.shp, tb.idx, newton_stop, max_correction,
                               np.ascontiguousarray(column_scale, dtype=np.float64), 8)


@numba.njit(cache=True)
def _constraint_terms(S, Sd, ct_int, ct_real, shp, idx, h_lin, J, gamma, phi):
    """J[k] = Phi_s(S[k]) (constant rows h_lin included); when Sd has rows, gamma[k] += the
    point-constraint part of gamma(S[k], Sd[k]); when phi has rows, phi[k] += h_lin S[k] + the
    point-constraint part of Phi(S[k]). Outputs hold the constant and drive parts on entry."""
    for k in range(S.shape[0]):
        J[k, :, :] = h_lin
        _kernels.constraint_jacobian(S[k], ct_int, ct_real, shp, idx, J[k])
        if Sd.shape[0] == S.shape[0]:
            _kernels.constraint_gamma(S[k], Sd[k], ct_int, ct_real, shp, idx, gamma[k])
        if phi.shape[0] == S.shape[0]:
            phi[k] += h_lin @ S[k]
            _kernels.constraints(S[k], ct_int, ct_real, shp, idx, phi[k])


def constraint_terms(model, t, S, Sd=None, *, with_values=False):
    """Constraint Jacobians (N, r, n) along samples ``S`` (N, n) at times ``t`` (N,), ``Phi_t``
    (N, r), with ``Sd`` (N, n) also ``gamma`` (N, r) (``Phi_s s'' = gamma``, else zeros), and with
    ``with_values`` a fourth array, ``Phi`` (N, r), for an assembled ``Model``; equal to its methods
    sample by sample."""
    from ._assemble import drive_law

    S = np.ascontiguousarray(S, dtype=np.float64)
    n_samples = S.shape[0]
    tb = model._tables
    J = np.zeros((n_samples, model.n_constraints, model.n_coords))
    rate = np.zeros((n_samples, model.n_constraints))
    gamma = np.zeros((n_samples, model.n_constraints))
    phi = np.tile(tb.phi0, (n_samples, 1)) if with_values else np.zeros((0, model.n_constraints))
    t = np.asarray(t, dtype=float)
    for info in model._prescribed:
        angle, angle_rate, angle_acc = drive_law(info.drive, model.period, t)
        rate[:, info.row] = -angle_rate
        gamma[:, info.row] = angle_acc          # -Phi_tt of the drive row
        if with_values:
            phi[:, info.row] -= angle
    Sd = np.zeros((0, S.shape[1])) if Sd is None else np.ascontiguousarray(Sd, dtype=np.float64)
    _constraint_terms(S, Sd, tb.ct_int, tb.ct_real, tb.shp, tb.idx, tb.h_lin, J, gamma, phi)
    return (J, rate, gamma, phi) if with_values else (J, rate, gamma)
