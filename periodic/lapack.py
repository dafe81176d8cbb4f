"""LU factorisation and solves inside numba kernels, in one convention: LAPACK's own (scipy's bundled dgetrf,
dgetrs, dgetri) and a hand-written twin for small or sparse matrices.

The one place in the packages that binds LAPACK: ``periodic``'s Newmark kernels and ``mechanisms``' Newton
iterations, step tangents and position continuation call these routines (``mechanisms`` may import this module of
``periodic`` and nothing else of it; ``tests/test_imports.py``).

Convention (LAPACK's, column-major):

- A matrix A (n, n) is passed as a C-order float64 array ``lu`` holding its transpose, ``lu[j, i] = A[i, j]``:
  that is A in LAPACK's column-major order (build it transposed, or copy with :func:`transpose`).
- :func:`factor_lapack` (dgetrf) and :func:`factor_loops` (hand-written) overwrite ``lu`` with the factors of
  ``P A = L U`` (partial pivoting by rows of A) as dgetrf leaves them, and ``pivots`` (n,) int32 with dgetrf's
  ``ipiv`` (1-based: row i was interchanged with row ``pivots[i] - 1``).  Both return False when a pivot is
  exactly zero.  The two give the same factors up to rounding, so either serves every solve:
- :func:`solve_rows_lapack` (dgetrs) solves ``A x = b`` (or ``A^T x = b``) for the m rows b of a C-order
  (m, n) array, LAPACK's column-major (n, m) right-hand side (one vector b (n,) as ``b.reshape((1, n))``);
  :func:`solve_columns_loops` (loops that skip zero factors) solves ``A x = b`` (or ``A^T x = b``) for the m
  columns of a C-order (n, m) array; :func:`invert_lapack` (dgetri) overwrites the factors with inv(A) in the
  same layout (the array then holds inv(A)^T).
- A matrix S at hand in C order, as it is, is A = S^T to these routines: factor it without copying, then
  solve ``S x = b`` with ``transposed``, or invert it (the array then holds inv(S^T)^T = inv(S)).
- :func:`pivot_ratio` is ``min |u_kk| / max |u_kk|``, a cheap singularity indicator; :func:`solve_in_place`
  solves one small system given in C order (transposed in place, factored and solved in one call).

Which to use: the loops beat LAPACK called from a kernel 2x at n = 2-12 (OpenBLAS's per-call overhead) and on
sparse matrices (a finite-element link's, 6-22 % nonzero: the loops skip zeros, LAPACK pays for them);
LAPACK's blocked dgetrf wins on dense matrices from n ~ 20 (``periodic._newmark`` and ``benchmarks/
bench_shooting_scale.py`` measure the crossover).  OpenBLAS's dgetrs splits many right-hand sides over threads,
which on a loaded machine made each call milliseconds: many columns go to the loops or to one dgemm with the
inverse.

LAPACK is reached through symbols registered with LLVM, not ctypes pointers, which numba refuses to cache: the
cached machine code names the symbol, and importing this module binds it to scipy's function in every process.
"""

from __future__ import annotations

import numba
import numpy as np
from llvmlite import binding as llvm_binding
from numba.extending import get_cython_function_address

__all__ = [
    "factor_lapack",
    "factor_loops",
    "invert_lapack",
    "pivot_ratio",
    "solve_columns_loops",
    "solve_in_place",
    "solve_rows_lapack",
    "transpose",
    "GETRI_WORK_PER_ROW",
]

_SYMBOLS = {name: f"flexvib_lapack_{name}" for name in ("dgetrf", "dgetrs", "dgetri")}
for _name, _symbol in _SYMBOLS.items():
    llvm_binding.add_symbol(_symbol, get_cython_function_address("scipy.linalg.cython_lapack", _name))
_INT_P, _DOUBLE_P = numba.types.CPointer(numba.int32), numba.types.CPointer(numba.float64)
# Fortran signatures, every argument by reference: dgetrf(m, n, a, lda, ipiv, info),
# dgetrs(trans, n, nrhs, a, lda, ipiv, b, ldb, info) and dgetri(n, a, lda, ipiv, work, lwork, info).
_dgetrf = numba.types.ExternalFunction(_SYMBOLS["dgetrf"], numba.void(
    _INT_P, _INT_P, _DOUBLE_P, _INT_P, _INT_P, _INT_P))
_dgetrs = numba.types.ExternalFunction(_SYMBOLS["dgetrs"], numba.void(
    numba.types.CPointer(numba.int8), _INT_P, _INT_P, _DOUBLE_P, _INT_P, _INT_P, _DOUBLE_P, _INT_P, _INT_P))
_dgetri = numba.types.ExternalFunction(_SYMBOLS["dgetri"], numba.void(
    _INT_P, _DOUBLE_P, _INT_P, _INT_P, _DOUBLE_P, _INT_P, _INT_P))
# dgetrs's `trans`: "N" solves A x = b, "T" solves A^T x = b
_TRANS = np.array([ord("N"), ord("T")], dtype=np.int8)
#: Length of the ``work`` array of :func:`invert_lapack` per row of the matrix (dgetri's block size; n is the
#: least it accepts).
GETRI_WORK_PER_ROW = 64


@numba.njit(cache=True)
def factor_lapack(lu, pivots):
    """``P A = L U`` of the matrix A whose transpose ``lu`` (n, n) holds (LAPACK dgetrf), in place; ``pivots``
    (n,) int32 receives dgetrf's 1-based pivots.  Returns False when a pivot is exactly zero."""
    ints = np.empty(2, dtype=np.int32)  # n, and info (LAPACK takes its integers by reference)
    ints[0] = lu.shape[0]
    _dgetrf(ints.ctypes, ints.ctypes, lu.ctypes, ints.ctypes, pivots.ctypes, ints[1:].ctypes)
    return ints[1] == 0  # info > 0: u_kk exactly zero at k = info


@numba.njit(cache=True)
def factor_loops(lu, pivots):
    """:func:`factor_lapack` by loops (same layout and pivots, results to rounding): Gaussian elimination by
    rows of A, which are the columns of ``lu``; rows of U whose entry is zero are skipped (sparse matrices).
    Returns False when a pivot is exactly zero."""
    n = lu.shape[0]
    for k in range(n):
        # lu[k, i] = A[i, k]: the pivot search runs along a row of lu
        p = k
        amax = abs(lu[k, k])
        for i in range(k + 1, n):
            if abs(lu[k, i]) > amax:
                amax = abs(lu[k, i])
                p = i
        pivots[k] = p + 1
        if amax == 0.0:
            return False
        if p != k:  # interchange rows k and p of A (all of them: L's part too, as dgetrf does)
            for j in range(n):
                tmp = lu[j, k]
                lu[j, k] = lu[j, p]
                lu[j, p] = tmp
        inv = 1.0 / lu[k, k]
        for i in range(k + 1, n):  # the multipliers L[i, k]
            lu[k, i] *= inv
        for j in range(k + 1, n):  # A[i, j] -= L[i, k] U[k, j] for i, j > k
            ukj = lu[j, k]
            if ukj != 0.0:
                for i in range(k + 1, n):
                    lu[j, i] -= lu[k, i] * ukj
    return True


@numba.njit(cache=True)
def solve_columns_loops(lu, pivots, b, transposed):
    """Overwrite ``b`` (n, m), C order, with ``A^-1 b`` (``A^-T b`` with ``transposed``: for a matrix S given in
    C order as it is, ``lu`` holds A = S^T and this solves S x = b), its m columns solved, from the factors of
    :func:`factor_lapack` or :func:`factor_loops`, by loops that skip zero factors."""
    n = lu.shape[0]
    m = b.shape[1]
    if transposed:
        # A^T = U^T L^T P: U^T y = b, then L^T w = y (U[l, i] = lu[i, l], L[l, i] = lu[i, l]: rows of lu)
        for i in range(n):
            for l in range(i):
                uli = lu[i, l]
                if uli != 0.0:
                    for j in range(m):
                        b[i, j] -= uli * b[l, j]
            inv = 1.0 / lu[i, i]
            for j in range(m):
                b[i, j] *= inv
        for i in range(n - 1, -1, -1):
            for l in range(i + 1, n):
                lli = lu[i, l]
                if lli != 0.0:
                    for j in range(m):
                        b[i, j] -= lli * b[l, j]
        for k in range(n - 1, -1, -1):  # x = P^T w: the interchanges in reverse order
            _swap_rows(b, k, pivots[k] - 1)
        return
    for k in range(n):  # P b, in dgetrf's order
        _swap_rows(b, k, pivots[k] - 1)
    for l in range(n):  # L y = P b (unit diagonal; L[i, l] = lu[l, i])
        for i in range(l + 1, n):
            lil = lu[l, i]
            if lil != 0.0:
                for j in range(m):
                    b[i, j] -= lil * b[l, j]
    for l in range(n - 1, -1, -1):  # U x = y (U[i, l] = lu[l, i], i <= l)
        inv = 1.0 / lu[l, l]
        for j in range(m):
            b[l, j] *= inv
        for i in range(l):
            uil = lu[l, i]
            if uil != 0.0:
                for j in range(m):
                    b[i, j] -= uil * b[l, j]


@numba.njit(cache=True)
def _swap_rows(b, k, p):
    if p != k:
        for j in range(b.shape[1]):
            tmp = b[k, j]
            b[k, j] = b[p, j]
            b[p, j] = tmp


@numba.njit(cache=True)
def solve_rows_lapack(lu, pivots, b, transposed):
    """Overwrite the m rows of ``b`` (m, n), C order (LAPACK's column-major (n, m)), with the solutions of
    ``A x = row`` (``A^T x = row`` with ``transposed``: for a matrix S given in C order as it is, ``lu`` holds
    A = S^T and this solves S x = row) from the factors of :func:`factor_lapack` or :func:`factor_loops`
    (LAPACK dgetrs).  One right-hand side b (n,): pass ``b.reshape((1, n))``."""
    ints = np.empty(3, dtype=np.int32)  # n, nrhs, info
    ints[0] = lu.shape[0]
    ints[1] = b.shape[0]
    trans = _TRANS[1:] if transposed else _TRANS[:1]
    _dgetrs(trans.ctypes, ints.ctypes, ints[1:].ctypes, lu.ctypes, ints.ctypes, pivots.ctypes,
            b.ctypes, ints.ctypes, ints[2:].ctypes)


@numba.njit(cache=True)
def invert_lapack(lu, pivots, work):
    """Overwrite the factors in ``lu`` (from :func:`factor_lapack` or :func:`factor_loops`) with inv(A) in the
    same layout, i.e. ``lu`` then holds inv(A)^T in C order (LAPACK dgetri; 4/3 n^3 flops).  ``work`` is scratch
    of at least n (best :data:`GETRI_WORK_PER_ROW` n) entries."""
    ints = np.empty(3, dtype=np.int32)  # n, lwork, info
    ints[0] = lu.shape[0]
    ints[1] = work.shape[0]
    _dgetri(ints.ctypes, lu.ctypes, ints.ctypes, pivots.ctypes, work.ctypes, ints[1:].ctypes, ints[2:].ctypes)


@numba.njit(cache=True)
def pivot_ratio(lu):
    """``min |u_kk| / max |u_kk|`` of the factors in ``lu`` (0 when they are all zero), a cheap singularity
    indicator (the condition number is at least its inverse, roughly)."""
    umax = 0.0
    umin = np.inf
    for k in range(lu.shape[0]):
        umax = max(umax, abs(lu[k, k]))
        umin = min(umin, abs(lu[k, k]))
    if umax == 0.0:
        return 0.0
    return umin / umax


@numba.njit(cache=True)
def transpose(source, target):
    """``target[:, :] = source.T`` (2-D), as a loop: an array assigned to a slice would compile numba's
    shape-mismatch message (string formatting, seconds of the first run's compilation)."""
    for i in range(source.shape[0]):
        for j in range(source.shape[1]):
            target[j, i] = source[i, j]


@numba.njit(cache=True)
def solve_in_place(a, b):
    """Overwrite ``b`` (n,) with the solution of ``a x = b`` for a small ``a`` (n, n) given as it is (C order,
    not transposed), which is overwritten: transposed in place into LAPACK's order, then by its factors
    (:func:`factor_loops`).  False when a pivot is exactly zero, or when the shapes do not match (not square).
    Inside kernels it replaces ``np.linalg.solve``, whose numba implementation alone costs seconds of the first
    run's compilation."""
    n = a.shape[0]
    if a.shape[1] != n or b.shape[0] != n:
        return False
    for i in range(n):  # into LAPACK's order
        for j in range(i + 1, n):
            tmp = a[i, j]
            a[i, j] = a[j, i]
            a[j, i] = tmp
    pivots = np.empty(n, dtype=np.int32)
    if not factor_loops(a, pivots):
        return False
    solve_columns_loops(a, pivots, b.reshape((n, 1)), False)
    return True
