"""Numba kernels: Newmark's scheme on many columns at once, with the hand-written LU or LAPACK of
``periodic.lapack``.

Newmark's scheme for ``M(t) x'' + C(t) x' + K(t) x = f(t)`` on ``t_k = k h`` (Newmark 1959;
Hughes, The Finite Element Method, eq. 9.1.5-9.1.7), written in predictor-corrector form:

    (N1)  x~ = x_k + h v_k + h^2 (1/2 - beta) a_k,       v~ = v_k + h (1 - gamma) a_k
    (N2)  (M_{k+1} + gamma h C_{k+1} + beta h^2 K_{k+1}) a_{k+1} = f_{k+1} - C_{k+1} v~ - K_{k+1} x~
    (N3)  x_{k+1} = x~ + beta h^2 a_{k+1},               v_{k+1} = v~ + gamma h a_{k+1}
    (N0)  M_0 a_0 = f_0 - C_0 v_0 - K_0 x_0                                    (start)

beta = 1/4, gamma = 1/2 (average acceleration) is the trapezoidal rule on the first-order form.

First-order coordinates (``first_order[i] = 1``: row i and column i of M zero, e.g. a sensor or actuator
lag ``tau y' + y = u``) are integrated by the same steps.  (N2) enforces every row at t_{k+1}, so
their rates v_i obey the row equation at every sample, and (N1, N3) give
``x_{k+1} - (beta/gamma) h v_{k+1} = x_k + (1 - beta/gamma) h v_k + h^2 (1/2 - beta/gamma) a_k``:
for ``2 beta = gamma`` (the trapezoidal member) that is the trapezoidal rule
``x_{k+1} = x_k + h/2 (v_k + v_{k+1})`` whatever a_i is, so a_i is a free auxiliary (set to 0) and
not a state.  The start (N0) then solves for the rates of first-order coordinates instead of their
accelerations: ``B_0 [a; v_1] = f_0 - C_0 v - K_0 x`` with ``B_0`` = M_0 whose first-order columns are
C_0's (v_1 = 0 on the right), the consistent initial values of the row equations.
Every column ``j`` of the state matrices is an independent solution; column ``j`` sees the force
``forced[j] * f`` (1 for the particular solution, 0 for the homogeneous unit states).  The effective
matrix of (N2) is factorised once per step and applied to all columns.

Cost per step, m columns (m = 2n+1 for the monodromy, 1 for the forced run): 2/3 n^3 (LU) +
2 n^2 m (solves) + 4 n^2 m (the products C v~ and K x~), about 12.7 n^3 flops at m = 2n+1.  Three
linear solvers do the LU and the solves; :func:`march` runs the one :func:`choose_solver` picks:

- ``SOLVE_LOOPS`` (:func:`newmark_march`), the hand-written LU (``periodic.lapack.factor_rowmajor``), for
  n < ``LAPACK_FROM_N_DOF`` = 20, and for sparse matrices (fewer than ``LAPACK_FROM_DENSITY`` = 50 %
  nonzero entries, as a finite-element link's: its loops skip zeros; 1.2x faster than LAPACK on the four-bar with 16-64
  coupler elements, n = 48-192).  It beats np.linalg.solve inside njit (which copies to Fortran
  order) 6x at n = 2 and 4x at n = 10, and LAPACK called from the kernel 2x at n = 2-12 (OpenBLAS's
  per-call overhead).
- ``SOLVE_INVERSE`` (:func:`newmark_march_lapack`) for n >= 20 and many columns: LAPACK dgetrf,
  dgetri (4/3 n^3 more flops) and all columns in one dgemm.  dgetrs on the 2n+1 columns at once
  runs at only 4-17 GFLOP/s here (OpenBLAS's triangular solves, n = 16..200): no faster than the
  column loops up to n = 64, whereas dgemm runs at 35-48 GFLOP/s, so the inverse pays for itself
  from n ~ 20.  Per step on one core (benchmarks/bench_shooting_scale.py, CPU time): 1.02x the
  loops' speed at n = 20, 1.15x at 24, 1.24x at 40, 1.6x at 200, where the step runs at 34 GFLOP/s
  (counting the flops above, not dgetri's extra), 1.7x the rate of scipy's lu_factor + lu_solve
  of the same size.  The inverse's rounding error is of the order of the LU solve's, cond(S) eps
  (tested against a backward-stable solve on stiff systems); S = M + gamma h C + beta h^2 K is
  dominated by M when the step resolves the modes.
- ``SOLVE_LAPACK`` (:func:`newmark_march_lapack`), dgetrf and dgetrs, for n >= 20 and few columns
  (the forced run): 1.2x faster than the loops at n = 20, 4.4x at n = 200.

The LAPACK path is a kernel of its own so that runs at small n compile none of it (the cold start of
a small model is unchanged; the LAPACK kernel compiles in about 2.6 s on first use).
"""

from __future__ import annotations

import numba
import numpy as np

from . import lapack


# forceinline on the helpers of a few lines: LLVM inlines them into every caller (its alwaysinline),
# so the machine code is what numba's inline="always" gave, while numba types and lowers each once, as
# a kernel of its own, instead of once per call site (inline="always" cost about 7 % more of the first
# run's compilation: docs/benchmarks.md, session 9).
# no_cfunc_wrapper on every kernel: none is passed as a first-class function, and the C wrapper numba
# builds for that costs about 35 ms of the first run's compilation per kernel (no_cpython_wrapper too
# on ``_residual_force``, which only kernels call).
@numba.njit(cache=True, forceinline=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def _copy(source, target):
    """target[:, :] = source (2-D), as a loop: an array assigned to a slice would compile numba's
    shape-mismatch message (string formatting, seconds of the first run's compilation)."""
    for i in range(source.shape[0]):
        for j in range(source.shape[1]):
            target[i, j] = source[i, j]


@numba.njit(cache=True, forceinline=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def _start_system(M0, C0, first_order, v, out):
    """``out`` = the matrix of (N0): M_0 with the columns of first-order coordinates taken from C_0; their
    rows of ``v`` (n, m) set to 0, since those rates are unknowns of (N0), not data."""
    n = M0.shape[0]
    for j in range(n):
        if first_order[j]:
            for i in range(n):
                out[i, j] = C0[i, j]
            for col in range(v.shape[1]):
                v[j, col] = 0.0
        else:
            for i in range(n):
                out[i, j] = M0[i, j]


@numba.njit(cache=True, forceinline=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def _split_start(first_order, v, a):
    """After (N0): the rows of first-order coordinates in ``a`` (n, m) are their rates: move them to
    ``v`` and set the (free, see the module notes) auxiliary accelerations to 0."""
    for i in range(v.shape[0]):
        if first_order[i]:
            for col in range(v.shape[1]):
                v[i, col] = a[i, col]
                a[i, col] = 0.0


# From this many coordinates on, BLAS (np.dot) beats the plain loops for the products C v and K x
# (measured: 2x faster at n = 20 and 40, 2x slower at n = 2..5).
_BLAS_FROM_N_DOF = 8


@numba.njit(cache=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def _residual_force(Ck, Kk, fk, forced, x, v, out, work):
    """``out = forced * f_k - C_k v - K_k x`` for all columns (right-hand side of N0 and N2)."""
    n, m = x.shape
    if n >= _BLAS_FROM_N_DOF:
        np.dot(Ck, v, out)
        np.dot(Kk, x, work)
        for i in range(n):
            for j in range(m):
                out[i, j] = forced[j] * fk[i] - out[i, j] - work[i, j]
        return
    for i in range(n):
        for j in range(m):
            out[i, j] = forced[j] * fk[i]
        for l in range(n):
            cil = Ck[i, l]
            kil = Kk[i, l]
            for j in range(m):
                out[i, j] -= cil * v[l, j] + kil * x[l, j]


@numba.njit(cache=True, no_cfunc_wrapper=True)
def newmark_march(M, C, K, f, first_order, h, beta, gamma, forced, x, v, a, x_hist, v_hist, a_hist):
    """March ``x, v`` (n, m) from ``t_0`` to ``t_N`` in place; ``a`` (n, m) receives the final acceleration.

    M, C, K (N+1, n, n), f (N+1, n), first_order (n,) int8 (1 for a first-order coordinate, see the
    module notes; its rows of ``v`` are replaced by consistent rates at the start), forced (m,).  When ``x_hist`` has
    N+1 rows the states at all
    samples are written to ``x_hist, v_hist, a_hist`` (N+1, n, m); pass zero-row arrays to skip.
    Returns -1 on success, else the sample index whose matrix (M_0 in N0, the effective matrix of
    N2 otherwise) has an exactly zero pivot.  The hand-written LU and column loops (small n);
    :func:`newmark_march_lapack` is the large-n twin, :func:`march` picks one.
    """
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
    # (N0): starting acceleration (and the rates of first-order coordinates)
    _start_system(M[0], C[0], first_order, v, lu)
    _residual_force(C[0], K[0], f[0], forced, x, v, a, work)
    if not lapack.factor_rowmajor(lu, piv):
        return 0
    lapack.solve_rowmajor(lu, piv, a)
    _split_start(first_order, v, a)
    if store:
        _copy(x, x_hist[0])
        _copy(v, v_hist[0])
        _copy(a, a_hist[0])
    for k in range(n_samples - 1):
        # (N1): predictors
        for i in range(n):
            for j in range(m):
                xp[i, j] = x[i, j] + h * v[i, j] + h * h * (0.5 - beta) * a[i, j]
                vp[i, j] = v[i, j] + h * (1.0 - gamma) * a[i, j]
        # (N2): effective matrix and right-hand side at t_{k+1}
        for i in range(n):
            for j in range(n):
                lu[i, j] = M[k + 1, i, j] + c_a * C[k + 1, i, j] + k_a * K[k + 1, i, j]
        if not lapack.factor_rowmajor(lu, piv):
            return k + 1
        _residual_force(C[k + 1], K[k + 1], f[k + 1], forced, xp, vp, a, work)
        lapack.solve_rowmajor(lu, piv, a)
        # (N3): correctors
        for i in range(n):
            for j in range(m):
                x[i, j] = xp[i, j] + k_a * a[i, j]
                v[i, j] = vp[i, j] + c_a * a[i, j]
        if store:
            _copy(x, x_hist[k + 1])
            _copy(v, v_hist[k + 1])
            _copy(a, a_hist[k + 1])
    return -1


# ---------------------------------------------------------------------------------------------------
# Large n: LAPACK's blocked LU, and the solves of all columns as one matrix product
# ---------------------------------------------------------------------------------------------------
# periodic.lapack's convention: its LAPACK routines read their array as the transpose of the matrix.  The
# kernel fills the effective matrix S as it is (no strided copy), so LAPACK factors S^T: dgetrs then solves
# S x = b with `transposed`, and dgetri leaves inv(S^T)^T = inv(S) in C order, ready for one dgemm.
#: The linear solvers of :func:`march` (see :func:`choose_solver`): the hand-written LU and its
#: column loops (:func:`newmark_march`); LAPACK's dgetrf and dgetrs (the columns transposed to
#: LAPACK's order and back, O(n m)); LAPACK's dgetrf and dgetri, and all columns in one dgemm
#: (both :func:`newmark_march_lapack`).
SOLVE_LOOPS, SOLVE_LAPACK, SOLVE_INVERSE = 0, 1, 2


@numba.njit(cache=True, no_cfunc_wrapper=True)
def _lapack_factor(lu, pivots, getri_work, invert):
    """dgetrf of ``lu`` (n, n), which holds S in C order (``periodic.lapack`` factors S^T), and with
    ``invert`` dgetri, which leaves inv(S) in C order.  Returns False when a pivot is exactly zero."""
    if not lapack.factor_lapack(lu, pivots):
        return False
    if invert:
        lapack.invert_lapack(lu, pivots, getri_work)
    return True


@numba.njit(cache=True, no_cfunc_wrapper=True)
def _lapack_solve(lu, pivots, b, work, work_t, invert):
    """Overwrite ``b`` (n, m) with ``S^-1 b`` from :func:`_lapack_factor`: one dgemm with the inverse, or
    dgetrs on the columns transposed to LAPACK's order (C-order (m, n) is LAPACK's (n, m)) and back.
    ``work`` (n, m) and ``work_t`` (m, n) are scratch."""
    if invert:
        _copy(b, work)
        np.dot(lu, work, b)
        return
    lapack.transpose(b, work_t)
    lapack.solve_rows_lapack(lu, pivots, work_t, True)
    lapack.transpose(work_t, b)


@numba.njit(cache=True, no_cfunc_wrapper=True)
def newmark_march_lapack(M, C, K, f, first_order, h, beta, gamma, forced, x, v, a, x_hist, v_hist, a_hist,
                         invert):
    """:func:`newmark_march` (same arguments, results to rounding, and return value) with LAPACK:
    dgetrf per step, then with ``invert`` dgetri and one dgemm for all columns (many columns), else
    dgetrs (one column).  A kernel of its own, so that runs at small n compile none of it."""
    n_samples = M.shape[0]
    n, m = x.shape
    store = x_hist.shape[0] == n_samples
    lu = np.empty((n, n))
    pivots = np.empty(n, dtype=np.int32)
    getri_work = np.empty(lapack.GETRI_WORK_PER_ROW * n)
    predicted = np.empty((2, n, m))  # x~ and v~ of (N1)
    work, work_t = np.empty((n, m)), np.empty((m, n))
    c_a, k_a = gamma * h, beta * h * h
    # (N0), then per step (N1) predictors, (N2) effective matrix and solve, (N3) correctors
    _start_system(M[0], C[0], first_order, v, lu)
    _residual_force(C[0], K[0], f[0], forced, x, v, a, work)
    if not _lapack_factor(lu, pivots, getri_work, invert):
        return 0
    _lapack_solve(lu, pivots, a, work, work_t, invert)
    _split_start(first_order, v, a)
    for k in range(n_samples):
        if store:
            _copy(x, x_hist[k])
            _copy(v, v_hist[k])
            _copy(a, a_hist[k])
        if k == n_samples - 1:
            break
        for i in range(n):
            for j in range(m):
                predicted[0, i, j] = x[i, j] + h * v[i, j] + h * h * (0.5 - beta) * a[i, j]
                predicted[1, i, j] = v[i, j] + h * (1.0 - gamma) * a[i, j]
        for i in range(n):
            for j in range(n):
                lu[i, j] = M[k + 1, i, j] + c_a * C[k + 1, i, j] + k_a * K[k + 1, i, j]
        if not _lapack_factor(lu, pivots, getri_work, invert):
            return k + 1
        _residual_force(C[k + 1], K[k + 1], f[k + 1], forced, predicted[0], predicted[1], a, work)
        _lapack_solve(lu, pivots, a, work, work_t, invert)
        for i in range(n):
            for j in range(m):
                x[i, j] = predicted[0, i, j] + k_a * a[i, j]
                v[i, j] = predicted[1, i, j] + c_a * a[i, j]
    return -1


#: From this many coordinates on, :func:`choose_solver` leaves the hand-written LU for LAPACK
#: (measured crossover, see the module notes and ``benchmarks/bench_shooting_scale.py``).
LAPACK_FROM_N_DOF = 20
#: ... and only for matrices with at least this fraction of nonzero entries: the hand-written LU and
#: solves skip zeros, so on the sparse matrices of a finite-element link (6-22 % nonzero in the
#: four-bar with 16-64 coupler elements) they beat LAPACK 1.2x, which pays for every zero.
LAPACK_FROM_DENSITY = 0.5


def choose_solver(n_dof: int, n_columns: int, density: float = 1.0) -> int:
    """The linear solver for ``n_dof`` coordinates, ``n_columns`` right-hand sides and matrices with
    ``density`` (fraction of nonzero entries): the hand-written LU below :data:`LAPACK_FROM_N_DOF`
    or :data:`LAPACK_FROM_DENSITY`; else LAPACK, with the inverse and one matrix product when the
    columns are many (the monodromy's 2n+1), dgetrs otherwise (the forced run's single column).
    Reads both constants at each call, so tests can force either path."""
    if n_dof < LAPACK_FROM_N_DOF or density < LAPACK_FROM_DENSITY:
        return SOLVE_LOOPS
    return SOLVE_INVERSE if 2 * n_columns > n_dof else SOLVE_LAPACK


def nonzero_fraction(M, C, K) -> float:
    """The fraction of entries of ``M + C + K`` at sample 0 that may be nonzero (the union of their
    patterns): a cheap measure of the sparsity the hand-written LU exploits."""
    pattern = (M[0] != 0.0) | (C[0] != 0.0) | (K[0] != 0.0)
    return float(np.count_nonzero(pattern)) / pattern.size


def march(M, C, K, f, h, beta, gamma, forced, x, v, a, x_hist, v_hist, a_hist, solver=None, first_order=None):
    """:func:`newmark_march` or :func:`newmark_march_lapack` by ``solver`` (one of ``SOLVE_LOOPS,
    SOLVE_LAPACK, SOLVE_INVERSE``; default :func:`choose_solver`'s pick), same arguments and return;
    ``first_order`` (n,) int8 flags first-order coordinates (default: none)."""
    if first_order is None:
        first_order = np.zeros(M.shape[1], dtype=np.int8)
    if solver is None:
        n, m = x.shape
        density = nonzero_fraction(M, C, K) if n >= LAPACK_FROM_N_DOF else 1.0  # O(n^2): only when it matters
        solver = choose_solver(n, m, density)
    if solver == SOLVE_LOOPS:
        return newmark_march(M, C, K, f, first_order, h, beta, gamma, forced, x, v, a, x_hist, v_hist, a_hist)
    return newmark_march_lapack(M, C, K, f, first_order, h, beta, gamma, forced, x, v, a, x_hist, v_hist, a_hist,
                                solver == SOLVE_INVERSE)


@numba.njit(cache=True, no_cfunc_wrapper=True)
def mass_pivot_ratios(M):
    """For each sample of M (N+1, n, n): smallest |LU pivot| / largest |entry| (0 when singular)."""
    n_samples, n = M.shape[0], M.shape[1]
    out = np.empty(n_samples)
    lu = np.empty((n, n))
    piv = np.empty(n, dtype=np.int32)
    for k in range(n_samples):
        _copy(M[k], lu)
        scale = 0.0  # max |entry| (NaN if one is), a loop: np.abs(lu).max() compiles a ufunc and a reduction
        for i in range(n):
            for j in range(n):
                entry = abs(lu[i, j])
                if entry > scale or entry != entry:  # a NaN stays: no comparison passes it
                    scale = entry
        if scale == 0.0 or not lapack.factor_rowmajor(lu, piv):
            out[k] = 0.0
            continue
        smallest = abs(lu[0, 0])
        for i in range(1, n):
            smallest = min(smallest, abs(lu[i, i]))
        out[k] = smallest / scale
    return out
