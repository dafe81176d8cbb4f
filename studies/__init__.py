"""Parametric studies of periodic mechanisms: steady state, sweeps, Campbell diagrams, stability
charts, nonlinear checks, error against run time, the start-up with and without control, optimisation
of design values and gains; HDF5 results and the ``flexvib`` command.

Each kind of study is a :class:`StudyKind` in one registry (:func:`kinds`); :func:`register_kind`
adds one from outside the package (its table, run, result class, cost model, demo table, summary).
Every result's ``plot(*, axes=None)`` returns a :class:`Plot` (figure, axes, artists by name). Bad
input raises :class:`StudiesError` (a ``ValueError``); a study that cannot be computed raises a
``RuntimeError`` (:class:`ComputationError` here)."""

from ._cost import Estimate as Estimate
from ._cost import estimate as estimate
from ._cost import steady_solves as steady_solves
from ._errors import ComputationError as ComputationError
from ._errors import StudiesError as StudiesError
from ._grid import PointOutcome as PointOutcome
from ._grid import process_pool as process_pool
from ._grid import run_grid as run_grid
from ._guard import ResourceError as ResourceError
from ._guard import guard as guard
from ._kind import StudyKind as StudyKind
from ._kind import kind_of as kind_of
from ._kind import kinds as kinds
from ._kind import register_kind as register_kind
from ._kinds.campbell import CampbellResult as CampbellResult
from ._kinds.campbell import campbell as campbell
from ._kinds.control_comparison import ControlComparison as ControlComparison
from ._kinds.control_comparison import control_comparison as control_comparison
from ._kinds.error_cost import ErrorCostResult as ErrorCostResult
from ._kinds.error_cost import error_cost as error_cost
from ._kinds.nonlinear_check import NonlinearCheck as NonlinearCheck
from ._kinds.nonlinear_check import nonlinear_check as nonlinear_check
from ._kinds.nonlinear_steady_state import NonlinearSteadyState as NonlinearSteadyState
from ._kinds.nonlinear_steady_state import nonlinear_steady_state as nonlinear_steady_state
from ._kinds.nonlinear_sweep import NonlinearSweep as NonlinearSweep
from ._kinds.nonlinear_sweep import nonlinear_sweep as nonlinear_sweep
from ._kinds.optimize import FrequencySeparation as FrequencySeparation
from ._kinds.optimize import MassBudget as MassBudget
from ._kinds.optimize import OptimizeResult as OptimizeResult
from ._kinds.optimize import StabilityMargin as StabilityMargin
from ._kinds.optimize import TorqueLimit as TorqueLimit
from ._kinds.optimize import optimize as optimize
from ._kinds.run_up import RunUp as RunUp
from ._kinds.run_up import run_up as run_up
from ._kinds.sensitivity import SensitivityResult as SensitivityResult
from ._kinds.sensitivity import sensitivity as sensitivity
from ._kinds.stability_chart import StabilityChart as StabilityChart
from ._kinds.stability_chart import stability_chart as stability_chart
from ._kinds.steady_state import SteadyStateResult as SteadyStateResult
from ._kinds.steady_state import steady_state as steady_state
from ._kinds.sweep import SweepResult as SweepResult
from ._kinds.sweep import sweep as sweep
from ._mechanism import MechanismProblem as MechanismProblem
from ._plots import Plot as Plot
from ._problem import Description as Description
from ._problem import Linear as Linear
from ._problem import NonlinearRun as NonlinearRun
from ._problem import PeriodicCoefficients as PeriodicCoefficients
from ._problem import PeriodicProblem as PeriodicProblem
from ._problem import mathieu_problem as mathieu_problem
from ._result import StudyResult as StudyResult
from ._resultfile import ResultFile as ResultFile
from ._store import FORMAT_VERSION as FORMAT_VERSION
from ._store import Result as Result
from ._store import ResultFileError as ResultFileError
from ._store import StorageError as StorageError
from ._store import load as load
from ._store import open_file as open_file
from ._summary import Headline as Headline
from ._summary import Summary as Summary

__all__ = [
    "FORMAT_VERSION",
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
