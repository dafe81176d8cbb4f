"""Compiling the batched kernels of an assembled model ahead of use, and whether numba's disk cache
already holds them (``flexvib run`` compiles ``linear_terms`` in a helper process on a cold start)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ._assemble import assemble
from ._batch import linear_terms_kernel


def warm_up_linear_terms(mechanism) -> None:
    """Compile (or load from numba's disk cache) the kernel of ``Model.linear_terms_along`` for the
    assembled ``mechanism``, on two zero samples (the numba types are those of any motion)."""
    model = assemble(mechanism)
    samples = np.zeros((2, model.n_coords))
    model.linear_terms_along(np.zeros(2), samples, samples, samples, np.zeros((2, model.n_constraints)))


def linear_terms_cached() -> bool:
    """Whether numba's disk cache holds the ``linear_terms`` kernel (its index file exists)."""
    kernel = linear_terms_kernel
    return any(Path(kernel.stats.cache_path).glob(f"*.{kernel.py_func.__name__}-*.nbi"))
