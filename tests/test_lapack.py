"""periodic.lapack, the packages' one home of LU factorisations inside numba kernels: LAPACK's dgetrf, dgetrs
and dgetri and the hand-written twin, against numpy's solve and inverse and scipy's LU (pivots and U), in
LAPACK's convention (the array holds the matrix transposed)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from periodic import lapack


def _matrix(n, seed):
    rng = np.random.default_rng(seed)
    return rng.normal(size=(n, n)) + np.sqrt(n) * np.eye(n), rng  # well conditioned


@pytest.mark.parametrize("n", [1, 2, 13, 60])
def test_lapack_factors_are_scipy_s_lu_of_the_matrix_whose_transpose_is_given(n):
    """LAPACK's layout: the array holds A^T; the factors are P A = L U (scipy's lu of A: pivots, factors, and
    the pivot ratio of its U)."""
    A, _ = _matrix(n, n)
    lu, pivots = A.T.copy(), np.empty(n, dtype=np.int32)
    assert lapack.factor_lapack(lu, pivots)
    reference, reference_pivots = scipy.linalg.lu_factor(A)
    np.testing.assert_array_equal(pivots, reference_pivots + 1)
    np.testing.assert_allclose(lu.T, reference, rtol=0, atol=1e-12 * np.abs(reference).max())
    diagonal = np.abs(np.diag(scipy.linalg.lu(A)[2]))
    assert lapack.pivot_ratio(lu) == pytest.approx(diagonal.min() / diagonal.max(), rel=1e-12)


@pytest.mark.parametrize("n", [1, 2, 13, 60])
def test_the_row_major_lu_is_scipy_s_lu_of_the_matrix_as_given(n):
    A, _ = _matrix(n, n)
    lu, pivots = A.copy(), np.empty(n, dtype=np.int32)
    assert lapack.factor_rowmajor(lu, pivots)
    reference, reference_pivots = scipy.linalg.lu_factor(A)
    np.testing.assert_array_equal(pivots, reference_pivots + 1)
    np.testing.assert_allclose(lu, reference, rtol=0, atol=1e-12 * np.abs(reference).max())


@pytest.mark.parametrize("n", [1, 2, 13, 60])
def test_every_solve_matches_numpy(n):
    A, rng = _matrix(n, n)
    B = rng.normal(size=(n, 2 * n + 1))  # the shooting's 2n + 1 columns
    assert np.linalg.cond(A) < 1e3
    expected = np.linalg.solve(A, B)
    lu, pivots = A.T.copy(), np.empty(n, dtype=np.int32)
    assert lapack.factor_lapack(lu, pivots)
    columns = B.copy()
    lapack.solve_columns_loops(lu, pivots, columns)
    np.testing.assert_allclose(columns, expected, rtol=0, atol=1e-12)
    rows = B.T.copy(order="C")  # LAPACK's column-major (n, m)
    lapack.solve_rows_lapack(lu, pivots, rows, False)
    np.testing.assert_allclose(rows.T, expected, rtol=0, atol=1e-12)
    vector = B[:, 0].copy()
    lapack.solve_rows_lapack(lu, pivots, vector.reshape((1, n)), False)
    np.testing.assert_allclose(vector, expected[:, 0], rtol=0, atol=1e-12)
    rows = B.T.copy(order="C")  # transposed: the same factors solve A^T x = b
    lapack.solve_rows_lapack(lu, pivots, rows, True)
    np.testing.assert_allclose(rows.T, np.linalg.solve(A.T, B), rtol=0, atol=1e-12)
    lapack.invert_lapack(lu, pivots, np.empty(lapack.GETRI_WORK_PER_ROW * n))
    np.testing.assert_allclose(lu.T, np.linalg.inv(A), rtol=0, atol=1e-12)
    lu, pivots = A.copy(), np.empty(n, dtype=np.int32)
    assert lapack.factor_rowmajor(lu, pivots)
    columns = B.copy()
    lapack.solve_rowmajor(lu, pivots, columns)
    np.testing.assert_allclose(columns, expected, rtol=0, atol=1e-12)


def test_a_matrix_as_it_is_is_its_transpose_to_the_lapack_routines():
    """S in C order is A = S^T: factor it unchanged, then solve S x = b with ``transposed`` or invert it into
    inv(S) in C order (the Newmark LAPACK kernel's use)."""
    S, rng = _matrix(7, 1)
    b = rng.normal(size=(3, 7))
    lu, pivots = S.copy(), np.empty(7, dtype=np.int32)
    assert lapack.factor_lapack(lu, pivots)
    rows = b.copy()
    lapack.solve_rows_lapack(lu, pivots, rows, True)
    np.testing.assert_allclose(S @ rows.T, b.T, rtol=0, atol=1e-12)
    lapack.invert_lapack(lu, pivots, np.empty(7))  # the least work dgetri accepts
    np.testing.assert_allclose(lu, np.linalg.inv(S), rtol=0, atol=1e-12)


def test_backward_stable_with_zero_diagonals():
    """A zero diagonal, as in the Newton matrix's constraint block: residual ~ n eps |A| |x|."""
    rng = np.random.default_rng(0)
    for n in (1, 5, 30):
        A = rng.normal(size=(n, n)) + n * np.eye(n) * rng.choice([0.0, 1.0])
        b = rng.normal(size=n)
        for layout in (A.T, A):
            lu, pivots = layout.copy(), np.empty(n, dtype=np.int32)
            x = b.copy()
            if layout is A:
                assert lapack.factor_rowmajor(lu, pivots)
                lapack.solve_rowmajor(lu, pivots, x.reshape((n, 1)))
            else:
                assert lapack.factor_lapack(lu, pivots)
                lapack.solve_columns_loops(lu, pivots, x.reshape((n, 1)))
            assert np.linalg.norm(A @ x - b) <= 1e-12 * n * np.linalg.norm(A) * np.linalg.norm(x)


@pytest.mark.parametrize("factor", [lapack.factor_lapack, lapack.factor_rowmajor])
def test_an_exactly_zero_pivot_is_reported(factor):
    # rank 2 of 3 with no zero entries: elimination leaves an exact zero pivot (dyadic entries), which the
    # Newmark kernels report as the singular sample and the Newton iteration as a singular matrix
    A = np.array([[2.0, 1.0, 3.0], [4.0, 2.0, 6.0], [1.0, 3.0, 0.5]])
    assert not factor(A.T.copy(), np.empty(3, dtype=np.int32))
    assert not factor(A.copy(), np.empty(3, dtype=np.int32))
    assert not factor(np.zeros((3, 3)), np.empty(3, dtype=np.int32))


def test_the_loops_skip_zeros_and_still_solve_a_sparse_matrix():
    """A banded matrix (a finite-element link's pattern) whose zero factors the loops skip."""
    n = 40
    A = (np.diag(np.full(n, 4.0)) + np.diag(np.full(n - 1, -1.0), 1) + np.diag(np.full(n - 1, -1.5), -1)
         + np.diag(np.full(n - 3, 0.5), 3))
    b = np.random.default_rng(2).normal(size=(n, 3))
    lu, pivots = A.copy(), np.empty(n, dtype=np.int32)
    assert lapack.factor_rowmajor(lu, pivots)
    x = b.copy()
    lapack.solve_rowmajor(lu, pivots, x)
    np.testing.assert_allclose(x, np.linalg.solve(A, b), rtol=0, atol=1e-13)
    lu = A.T.copy()
    assert lapack.factor_lapack(lu, pivots)
    x = b.copy()
    lapack.solve_columns_loops(lu, pivots, x)
    np.testing.assert_allclose(x, np.linalg.solve(A, b), rtol=0, atol=1e-13)


@pytest.mark.parametrize("n", [1, 2, 3, 7])
def test_solve_in_place_matches_numpy(n):
    rng = np.random.default_rng(n)
    a = rng.standard_normal((n, n)) + n * np.eye(n)
    a[0, 0] = 0.0  # the first step needs a row swap (partial pivoting)
    b = rng.standard_normal(n)
    expected = np.linalg.solve(a, b) if np.linalg.matrix_rank(a) == n else None
    work, x = a.copy(), b.copy()
    ok = lapack.solve_in_place(work, x)
    if expected is None:
        assert not ok
    else:
        assert ok
        np.testing.assert_allclose(x, expected, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(a @ x, b, rtol=1e-12, atol=1e-12)


def test_solve_in_place_refuses_singular_and_non_square_systems():
    assert not lapack.solve_in_place(np.array([[1.0, 2.0], [2.0, 4.0]]), np.ones(2))
    assert not lapack.solve_in_place(np.zeros((2, 3)), np.ones(2))
