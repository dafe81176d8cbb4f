"""Parametric studies of periodic mechanisms: steady state, sweeps, Campbell diagrams, stability
charts, nonlinear checks, error against run time; HDF5 results and the ``flexvib`` command."""

from ._grid import PointOutcome as PointOutcome
from ._grid import run_grid as run_grid
from ._mechanism import MechanismProblem as MechanismProblem
from ._problem import Linear as Linear
from ._problem import NonlinearRun as NonlinearRun
from ._problem import PeriodicCoefficients as PeriodicCoefficients
from ._problem import PeriodicProblem as PeriodicProblem
from ._problem import mathieu_problem as mathieu_problem
from ._results import CampbellResult as CampbellResult
from ._results import ErrorCostResult as ErrorCostResult
from ._results import NonlinearCheck as NonlinearCheck
from ._results import StabilityChart as StabilityChart
from ._results import SteadyStateResult as SteadyStateResult
from ._results import SweepResult as SweepResult
from ._store import load as load
from ._store import open_file as open_file
from ._studies import campbell as campbell
from ._studies import error_cost as error_cost
from ._studies import nonlinear_check as nonlinear_check
from ._studies import stability_chart as stability_chart
from ._studies import steady_state as steady_state
from ._studies import sweep as sweep

__all__ = [
    "CampbellResult", "ErrorCostResult", "Linear", "MechanismProblem", "NonlinearCheck", "NonlinearRun",
    "PeriodicCoefficients", "PeriodicProblem", "PointOutcome", "StabilityChart", "SteadyStateResult",
    "SweepResult", "campbell", "error_cost", "load", "mathieu_problem", "nonlinear_check", "open_file",
    "run_grid", "stability_chart", "steady_state", "sweep",
]
