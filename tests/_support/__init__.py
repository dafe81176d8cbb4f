"""Helpers shared by the test modules: reference models, numpy twins of kernels, the Newmark kernels'
forced linear-algebra paths, the warm launcher of the fault-injection tests, and the user-side
extensions of tests/test_extension.py (``extensions``). Fixtures are in ``tests/conftest.py``."""
