"""Parametric studies of periodic mechanisms: steady state, sweeps, Campbell diagrams, stability
charts, nonlinear checks, error against run time, the start-up with and without control, optimisation
of design values and gains; HDF5 results and the ``flexvib`` command.

Each kind of study is a :class:`StudyKind` in one registry (:func:`kinds`); :func:`register_kind`
adds one from outside the package (its table, run, result class, cost model, demo table, summary).
Every result's ``plot(*, axes=None)`` returns a :class:`Plot` (figure, axes, artists by name). Bad
input raises :class:`StudiesError` (a ``ValueError``); a study that cannot be computed raises a
``RuntimeError`` (:class:`ComputationError` here)."""

# The names below are imported on first use (PEP 562), from ``studies._face``: ``import studies`` is
# light, and the first name used imports them all (registering the study kinds, as an eager import did).
def __getattr__(name: str):
    if name.startswith("_"):   # a submodule (``from studies import _store``): the import system's
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    from . import _face

    if not hasattr(_face, name):
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals().update({public: getattr(_face, public) for public in __all__})
    return getattr(_face, name)


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


__all__ = [
    "FORMAT_VERSION",
    "DamagedResultError",
    "Headline",
    "Result",
    "StudyResult",
    "ResultFile",
    "StudyKind",
    "Summary",
    "kind_of",
    "kinds",
    "register_kind",
    "steady_solves",
    "CampbellResult",
    "ComputationError",
    "ControlComparison",
    "control_comparison",
    "FrequencySeparation",
    "MassBudget",
    "OptimizeResult",
    "SensitivityResult",
    "StabilityMargin",
    "register_constraint",
    "TorqueLimit",
    "optimize",
    "sensitivity",
    "Description",
    "Estimate",
    "ResourceError",
    "ResultFileError",
    "StorageError",
    "estimate",
    "guard",
    "ErrorCostResult",
    "Linear",
    "MechanismProblem",
    "NonlinearCheck",
    "NonlinearSteadyState",
    "NonlinearSweep",
    "NonlinearRun",
    "PeriodicCoefficients",
    "PeriodicProblem",
    "Plot",
    "PointOutcome",
    "StabilityChart",
    "SteadyStateResult",
    "StudiesError",
    "SweepResult",
    "campbell",
    "error_cost",
    "load",
    "mathieu_problem",
    "nonlinear_check",
    "run_up",
    "RunUp",
    "nonlinear_steady_state",
    "nonlinear_sweep",
    "open_file",
    "process_pool",
    "run_grid",
    "stability_chart",
    "steady_state",
    "sweep",
]
