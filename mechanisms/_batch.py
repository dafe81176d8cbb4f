"""The terms of the linearised equations along a whole sampled motion in one numba call.

``linearize`` needs, at every sample of the nominal motion, the mass matrix, the residual
``R = M s'' - Q + Phi_s^T lam``, ``D = -dQ/ds'``, ``K = d(M s'')/ds - dQ/ds + d(Phi_s^T lam)/ds`` and
the constraint Jacobian. Evaluating them through the model's methods costs a few Python calls per
sample; this kernel loops over the samples inside numba, calling the same element kernels
(``_kernels``), so the result is identical to the method-by-method evaluation (tested).
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
