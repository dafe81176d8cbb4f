"""The errors of ``studies`` and the one place that sorts any error into bad input or a numerical
failure (the ``flexvib`` exit codes 2 and 1, and which studies of a run are reported as failed).

Convention for the whole project: bad input raises a ``ValueError`` subclass (``TypeError`` for wrong
types or unknown keyword options) naming the key or argument, what was expected and what was
received; a computation that fails on good input raises a ``RuntimeError`` subclass.
"""

from __future__ import annotations


class StudiesError(ValueError):
    """Bad input to a study: a ``[studies]`` table or an argument that cannot be run (unknown keys or
    parameters, wrong types, bad ranges), or a result file that is not one."""


class ComputationError(RuntimeError):
    """A study that cannot be computed on good input (e.g. the nonlinear run does not converge)."""


class UsageError(Exception):
    """Bad input on the command line: reported as ``flexvib: error: ...`` with exit code 2."""


def input_errors() -> tuple[type[BaseException], ...]:
    """The classes of bad input (exit code 2): every package's input-error class."""
    import linearize
    import mechanisms
    import periodic

    return (UsageError, StudiesError, mechanisms.MechanismError, mechanisms.ArgumentError,
            linearize.LinearizationError, periodic.PeriodicError)


def numerical_failures() -> tuple[type[BaseException], ...]:
    """The classes of numerical failures (exit code 1; in a run, the study is reported as failed and
    the others go on): ``RuntimeError`` (every package's failure classes subclass it), singular
    matrices and floating-point errors."""
    import numpy as np

    return (RuntimeError, np.linalg.LinAlgError, ArithmeticError)


def is_numerical_failure(error: BaseException) -> bool:
    """Whether ``error`` is a numerical failure; ``NotImplementedError`` and ``RecursionError``
    subclass ``RuntimeError`` but are bugs."""
    return (isinstance(error, numerical_failures())
            and not isinstance(error, (NotImplementedError, RecursionError)))


def interruption(error: BaseException | None) -> KeyboardInterrupt | None:
    """The ``KeyboardInterrupt`` (a signal) that ``error`` is, or was raised from or while handling
    (None: not an interrupt). A signal during the initialisation of an extension module does not
    arrive as itself: pybind11's modules (scipy's HiGHS, imported with ``scipy.optimize``) turn it
    into ``ImportError("initialization failed")`` raised from it."""
    seen = set()
    while error is not None and id(error) not in seen:
        if isinstance(error, KeyboardInterrupt):
            return error
        seen.add(id(error))
        error = error.__cause__ or error.__context__
    return None
