"""Numba kernel: Newmark's scheme with one forcing per column, for the parameter derivatives of a
steady state (``periodic._sensitivity``): each column is driven by its own forcing history instead of
``forced[j] * f``, all columns with one factorisation per step (equations (N0)-(N3) of
``periodic._newmark``)."""

from __future__ import annotations

import numba
import numpy as np

from . import lapack
from ._newmark import _BLAS_FROM_N_DOF, _copy, _split_start, _start_system


@numba.njit(cache=True, no_cfunc_wrapper=True)
def _residual_columns(Ck, Kk, Fk, x, v, out, work):
    """``out = F_k - C_k v - K_k x`` for all columns (F_k (n, m): one forcing per column)."""
    n, m = x.shape
    if n >= _BLAS_FROM_N_DOF:
        np.dot(Ck, v, out)
        np.dot(Kk, x, work)
        for i in range(n):
            for j in range(m):
                out[i, j] = Fk[i, j] - out[i, j] - work[i, j]
        return
    for i in range(n):
        for j in range(m):
            out[i, j] = Fk[i, j]
        for l in range(n):
            cil = Ck[i, l]
            kil = Kk[i, l]
            for j in range(m):
                out[i, j] -= cil * v[l, j] + kil * x[l, j]


@numba.njit(cache=True, no_cfunc_wrapper=True)
def newmark_march_forcings(M, C, K, F, first_order, h, beta, gamma, x, v, a, x_hist, v_hist, a_hist):
    """``periodic._newmark.newmark_march`` with column j driven by ``F[:, :, j]`` (F (N+1, n, m)):
    equations (N0)-(N3) there, one LU per step (the hand-written one, which skips the zeros of sparse
    matrices) applied to all columns.  Same arguments otherwise, same return value."""
    n_samples = M.shape[0]
    n, m = x.shape
    store = x_hist.shape[0] == n_samples
    lu = np.empty((n, n))
    piv = np.empty(n, dtype=np.int32)
    xp = np.empty((n, m))
    vp = np.empty((n, m))
    work = np.empty((n, m))
    c_a = gamma * h
    k_a = beta * h * h
    _start_system(M[0], C[0], first_order, v, lu)
    _residual_columns(C[0], K[0], F[0], x, v, a, work)
    if not lapack.factor_rowmajor(lu, piv):
        return 0
    lapack.solve_rowmajor(lu, piv, a)
    _split_start(first_order, v, a)
    if store:
        _copy(x, x_hist[0])
        _copy(v, v_hist[0])
        _copy(a, a_hist[0])
    for k in range(n_samples - 1):
        for i in range(n):
            for j in range(m):
                xp[i, j] = x[i, j] + h * v[i, j] + h * h * (0.5 - beta) * a[i, j]
                vp[i, j] = v[i, j] + h * (1.0 - gamma) * a[i, j]
        for i in range(n):
            for j in range(n):
                lu[i, j] = M[k + 1, i, j] + c_a * C[k + 1, i, j] + k_a * K[k + 1, i, j]
        if not lapack.factor_rowmajor(lu, piv):
            return k + 1
        _residual_columns(C[k + 1], K[k + 1], F[k + 1], xp, vp, a, work)
        lapack.solve_rowmajor(lu, piv, a)
        for i in range(n):
            for j in range(m):
                x[i, j] = xp[i, j] + k_a * a[i, j]
                v[i, j] = vp[i, j] + c_a * a[i, j]
        if store:
            _copy(x, x_hist[k + 1])
            _copy(v, v_hist[k + 1])
            _copy(a, a_hist[k + 1])
    return -1
