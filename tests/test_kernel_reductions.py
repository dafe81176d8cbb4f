"""The loops that replaced ``np.abs(x).max()`` inside kernels (a numba reduction that cost 2-3 % of the
first run's compilation) give numpy's answer, NaN included: a NaN constraint residual is never
"converged", a NaN mass matrix never gets a finite pivot ratio."""

from __future__ import annotations

import numpy as np
import scipy.linalg

from mechanisms import _batch  # internal kernels: no public face
from periodic import _newmark  # internal kernel: no public face


def test_max_abs_is_numpys_including_nan_and_empty():
    rng = np.random.default_rng(3)
    for values in (rng.standard_normal(7), -np.abs(rng.standard_normal(4)), np.array([0.0, -0.0])):
        assert _batch._max_abs(values) == np.abs(values).max()
    assert _batch._max_abs(np.empty(0)) == 0.0
    for where in (0, 3, 6):
        values = rng.standard_normal(7)
        values[where] = np.nan
        assert np.isnan(_batch._max_abs(values))


def test_mass_pivot_ratios_against_scipys_lu():
    rng = np.random.default_rng(4)
    M = rng.standard_normal((5, 4, 4)) + 3.0 * np.eye(4)
    M[2, 1, :] = 0.0  # a singular sample
    expected = []
    for sample in M:
        lu = scipy.linalg.lu_factor(sample, check_finite=False)[0] if sample[1].any() else np.zeros((4, 4))
        smallest = np.abs(np.diag(lu)).min()
        expected.append(0.0 if smallest == 0.0 else smallest / np.abs(sample).max())
    assert np.allclose(_newmark.mass_pivot_ratios(M), expected, rtol=1e-12, atol=0.0)
    M[3, 2, 2] = np.nan
    ratios = _newmark.mass_pivot_ratios(M)
    assert np.isnan(ratios[3])  # as np.abs(M).max() made it: never a finite, trusted ratio
    assert np.isfinite(ratios[[0, 1, 4]]).all()
