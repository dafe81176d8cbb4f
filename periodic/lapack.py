"""LU factorisation and solves inside numba kernels: LAPACK's (scipy's bundled dgetrf, dgetrs, dgetri,
bound here once) and a hand-written LU for small or sparse matrices.

The one place in the packages that binds LAPACK or writes an LU: ``periodic``'s Newmark kernels and
``mechanisms``' Newton iterations, step tangents and position continuation call these routines (``mechanisms``
may import this module of ``periodic`` and nothing else of it; ``tests/test_imports.py``).

LAPACK's convention (column-major), for every ``*_lapack`` routine and :func:`solve_columns_loops`:

- A matrix A (n, n) is passed as a C-order float64 array ``lu`` holding its transpose, ``lu[j, i] = A[i, j]``:
  that is A in LAPACK's column-major order (build it transposed, or copy with :func:`transpose`).  A matrix S
  at hand in C order as it is is A = S^T to these routines.
- :func:`factor_lapack` (dgetrf) overwrites ``lu`` with the factors of ``P A = L U`` (partial pivoting by rows
  of A), ``pivots`` (n,) int32 with dgetrf's ``ipiv`` (1-based: row i was interchanged with row
  ``pivots[i] - 1``), and returns False when a pivot is exactly zero.
- :func:`solve_rows_lapack` (dgetrs) solves ``A x = b`` (or ``A^T x = b``: S x = b for S given as it is) for
  the m rows b of a C-order (m, n) array, LAPACK's column-major (n, m) right-hand side (one vector b (n,) as
  ``b.reshape((1, n))``); :func:`solve_columns_loops` solves ``A x = b`` for the m columns of a C-order (n, m)
  array by loops; :func:`invert_lapack` (dgetri) overwrites the factors with inv(A) in the same layout (the
  array then holds inv(A)^T, which is inv(S) for S given as it is).

The hand-written LU, :func:`factor_rowmajor` and :func:`solve_rowmajor`, takes the matrix in C order as it is
(row-major ``P A = L U``, the same 1-based int32 pivots): the same elimination written in LAPACK's layout was
1.4-1.7x slower at n = 2-6 (equal from n = 12), where the Newmark kernels spend their time.
:func:`solve_in_place` solves one small system with it; :func:`pivot_ratio` (``min |u_kk| / max |u_kk|``, a
cheap singularity indicator) reads the diagonal of either layout.

Which to use: the loops beat LAPACK called from a kernel 2x at n = 2-12 (OpenBLAS's per-call overhead) and on
sparse matrices (a finite-element link's, 6-22 % nonzero: the loops skip zeros, LAPACK pays for them);
LAPACK's blocked dgetrf wins on dense matrices from n ~ 20 (``periodic._newmark`` and ``benchmarks/
bench_shooting_scale.py`` measure the crossover).

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
    "factor_rowmajor",
    "invert_lapack",
    "pivot_ratio",
    "solve_columns_loops",
    "solve_in_place",
    "solve_rowmajor",
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

# no_cfunc_wrapper on every kernel: none is passed as a first-class function (the C wrapper numba builds
# for that is first-run compilation for nothing, about 35 ms a kernel).


@numba.njit(cache=True, no_cfunc_wrapper=True)
def factor_lapack(lu, pivots):
    """``P A = L U`` of the matrix A whose transpose ``lu`` (n, n) holds (LAPACK dgetrf), in place; ``pivots``
    (n,) int32 receives dgetrf's 1-based pivots.  Returns False when a pivot is exactly zero."""
    ints = np.empty(2, dtype=np.int32)  # n, and info (LAPACK takes its integers by reference)
    ints[0] = lu.shape[0]
    _dgetrf(ints.ctypes, ints.ctypes, lu.ctypes, ints.ctypes, pivots.ctypes, ints[1:].ctypes)
    return ints[1] == 0  # info > 0: u_kk exactly zero at k = info


@numba.njit(cache=True, no_cfunc_wrapper=True)
def factor_rowmajor(a, pivots):
    """``P A = L U`` with partial pivoting of the matrix A given in C order as it is (``a[i, j] = A[i, j]``,
    the row-major layout, not LAPACK's), in place: ``a`` receives L (unit diagonal, below) and U, ``pivots``
    (n,) int32 the 1-based row interchanges as dgetrf's.  Rows whose multiplier is zero are skipped (sparse
    matrices).  Returns False when a pivot is exactly zero.  Solve with :func:`solve_rowmajor`."""
    n = a.shape[0]
    for k in range(n):
        p = k
        amax = abs(a[k, k])
        for i in range(k + 1, n):
            if abs(a[i, k]) > amax:
                amax = abs(a[i, k])
                p = i
        pivots[k] = p + 1
        if amax == 0.0:
            return False
        if p != k:
            for j in range(n):
                tmp = a[k, j]
                a[k, j] = a[p, j]
                a[p, j] = tmp
        inv = 1.0 / a[k, k]
        for i in range(k + 1, n):
            lik = a[i, k] * inv
            a[i, k] = lik
            if lik != 0.0:
                for j in range(k + 1, n):
                    a[i, j] -= lik * a[k, j]
    return True


@numba.njit(cache=True, no_cfunc_wrapper=True)
def solve_rowmajor(lu, pivots, b):
    """Overwrite ``b`` (n, m), C order, with ``A^-1 b`` (its m columns solved) from :func:`factor_rowmajor`,
    by loops that skip zero factors.  One right-hand side b (n,): pass ``b.reshape((n, 1))``."""
    n = lu.shape[0]
    m = b.shape[1]
    for k in range(n):
        p = pivots[k] - 1
        if p != k:
            for j in range(m):
                tmp = b[k, j]
                b[k, j] = b[p, j]
                b[p, j] = tmp
    for i in range(n):  # L y = P b, unit diagonal
        for l in range(i):
            lil = lu[i, l]
            if lil != 0.0:
                for j in range(m):
                    b[i, j] -= lil * b[l, j]
    for i in range(n - 1, -1, -1):  # U x = y
        for l in range(i + 1, n):
            uil = lu[i, l]
            if uil != 0.0:
                for j in range(m):
                    b[i, j] -= uil * b[l, j]
        inv = 1.0 / lu[i, i]
        for j in range(m):
            b[i, j] *= inv


@numba.njit(cache=True, no_cfunc_wrapper=True)
def solve_columns_loops(lu, pivots, b):
    """Overwrite ``b`` (n, m), C order, with ``A^-1 b`` (its m columns solved) from the factors of
    :func:`factor_lapack`, by loops that skip zero factors (no BLAS threads: OpenBLAS's dgetrs splits many
    right-hand sides over threads, which on a loaded machine made each call milliseconds)."""
    n = lu.shape[0]
    m = b.shape[1]
    for k in range(n):  # P b, in dgetrf's order
        _swap_rows(b, k, pivots[k] - 1)
    for l in range(n):  # L y = P b (unit diagonal; L[i, l] = lu[l, i]: a row of lu per column of L)
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


# forceinline on the helpers of a few lines: LLVM inlines them into every caller (its alwaysinline),
# so the machine code is what numba's inline="always" gave, while numba types and lowers each once, as
# a kernel of its own, instead of once per call site (inline="always" cost about 7 % more of the first
# run's compilation: docs/benchmarks.md, session 9).
@numba.njit(cache=True, forceinline=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def _swap_rows(b, k, p):
    if p != k:
        for j in range(b.shape[1]):
            tmp = b[k, j]
            b[k, j] = b[p, j]
            b[p, j] = tmp


# One explicit signature, compiled (or loaded) at import: a kernel that passes ``transposed`` as a
# constant would otherwise compile this for ``Literal[bool](False)`` and ``Literal[bool](True)`` apart
# (one signature each, in the order the callers first compile), which tests/test_jit.py refuses.
@numba.njit("void(float64[:, ::1], int32[::1], float64[:, ::1], boolean)", cache=True, no_cfunc_wrapper=True)
def solve_rows_lapack(lu, pivots, b, transposed):
    """Overwrite the m rows of ``b`` (m, n), C order (LAPACK's column-major (n, m)), with the solutions of
    ``A x = row`` (``A^T x = row`` with ``transposed``: for a matrix S given in C order as it is, ``lu`` holds
    A = S^T and this solves S x = row) from the factors of :func:`factor_lapack` (LAPACK dgetrs).  One
    right-hand side b (n,): pass ``b.reshape((1, n))``."""
    ints = np.empty(3, dtype=np.int32)  # n, nrhs, info
    ints[0] = lu.shape[0]
    ints[1] = b.shape[0]
    trans = _TRANS[1:] if transposed else _TRANS[:1]
    _dgetrs(trans.ctypes, ints.ctypes, ints[1:].ctypes, lu.ctypes, ints.ctypes, pivots.ctypes,
            b.ctypes, ints.ctypes, ints[2:].ctypes)


@numba.njit(cache=True, no_cfunc_wrapper=True)
def invert_lapack(lu, pivots, work):
    """Overwrite the factors in ``lu`` (from :func:`factor_lapack`) with inv(A) in the
    same layout, i.e. ``lu`` then holds inv(A)^T in C order (LAPACK dgetri; 4/3 n^3 flops).  ``work`` is scratch
    of at least n (best :data:`GETRI_WORK_PER_ROW` n) entries."""
    ints = np.empty(3, dtype=np.int32)  # n, lwork, info
    ints[0] = lu.shape[0]
    ints[1] = work.shape[0]
    _dgetri(ints.ctypes, lu.ctypes, ints.ctypes, pivots.ctypes, work.ctypes, ints[1:].ctypes, ints[2:].ctypes)


@numba.njit(cache=True, no_cfunc_wrapper=True)
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


@numba.njit(cache=True, no_cfunc_wrapper=True)
def transpose(source, target):
    """``target[:, :] = source.T`` (2-D) as a loop (a slice assignment's shape check compiles slowly)."""
    for i in range(source.shape[0]):
        for j in range(source.shape[1]):
            target[j, i] = source[i, j]


@numba.njit(cache=True, no_cfunc_wrapper=True)
def solve_in_place(a, b):
    """Overwrite ``b`` (n,) with the solution of ``a x = b`` for a small ``a`` (n, n) given as it is (C order),
    which is overwritten by its factors (:func:`factor_rowmajor`).  False when a pivot is exactly zero, or when
    the shapes do not match (not square).  Inside kernels it replaces ``np.linalg.solve``, whose numba
    implementation alone costs seconds of the first run's compilation."""
    n = a.shape[0]
    if a.shape[1] != n or b.shape[0] != n:
        return False
    pivots = np.empty(n, dtype=np.int32)
    if not factor_rowmajor(a, pivots):
        return False
    solve_rowmajor(a, pivots, b.reshape((n, 1)))
    return True
