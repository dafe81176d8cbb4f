"""Fixtures shared by the test modules (no test module imports another)."""

from __future__ import annotations

import pytest

from tests._support import studies_helpers


@pytest.fixture(scope="session")
def crossing_problem():
    """``crossing_problem(damping=0.02)``: two modes whose frequencies cross at speed sqrt(3)."""
    return studies_helpers.crossing_problem


@pytest.fixture(scope="session")
def principal_tongue():
    """``principal_tongue(w0, epsilon)``: the speeds bounding the Mathieu principal tongue."""
    return studies_helpers.principal_tongue


@pytest.fixture(scope="session")
def assert_same():
    """``assert_same(a, b)``: two study results equal field by field, to the last bit."""
    return studies_helpers.assert_same
