"""The Newmark kernel's linear-algebra paths, forced for a test: the hand-written LU for every n
(``"loops"``) or LAPACK for every n (``"lapack"``: dgetri and one matrix product for many columns,
dgetrf / dgetrs for the forced run's one column).  ``periodic._newmark.choose_solver`` otherwise
picks by the number of coordinates and the matrices' density."""

from __future__ import annotations

import contextlib
import sys

from periodic import _newmark  # the Newmark kernels' solver thresholds, forced: no public face

#: The paths, for ``pytest.mark.parametrize`` and fixture ``params``.
PATHS = ("loops", "lapack")


@contextlib.contextmanager
def kernel_path(path: str):
    """Within the block, ``periodic`` marches every system on ``path`` (one of :data:`PATHS`)."""
    saved = _newmark.LAPACK_FROM_N_DOF, _newmark.LAPACK_FROM_DENSITY
    _newmark.LAPACK_FROM_N_DOF, _newmark.LAPACK_FROM_DENSITY = {"loops": (sys.maxsize, 2.0), "lapack": (0, 0.0)}[path]
    try:
        yield
    finally:
        _newmark.LAPACK_FROM_N_DOF, _newmark.LAPACK_FROM_DENSITY = saved

