"""What a study kind is built with: the one internal module every module of ``studies._kinds`` imports
its infrastructure from (declaring and registering the kind and checking its table, its cost model, storing
its result, running grid points, verdicts and summary rows). The numerics (``studies._numerics``) and the
figures (``studies._plots``) are imported on their own, as are the problems' helpers (``studies._mechanism``).
"""

from __future__ import annotations

# its cost model for the resource guard
from ._cost import (
    FAMILY_DOUBLES,
    LINEARISATION_DOUBLES,
    NONLINEAR_DOUBLES,
    NONLINEAR_STEP_N2_SECONDS,
    NONLINEAR_STEP_SECONDS,
    SHOOTING_PERIODS,
    STUDY_SECONDS,
    SWEEP_POINT_PERIODS,
    Estimate,
    Sizes,
    axis_words,
    grid_cost,
    largest_sizes,
    linearisation,
    nonlinear_period_seconds,
    sizes_at,
    solve_seconds,
    steady_solves,
    tangent_bytes,
    with_reduction_check,
)

# errors
from ._errors import (
    ComputationError,
    StudiesError,
    is_numerical_failure,
)

# grid points
from ._grid import (
    run_grid,
)

# declaring a kind and checking its table
from ._kind import (
    AXIS_KEYS,
    HARMONIC_WHY,
    MAX_AXIS_POINTS,
    MAX_HARMONIC,
    MAX_PERIODS,
    MAX_STEPS,
    PERIODS_WHY,
    STEPS_WHY,
    WARM_UP_STEPS,
    StudyKind,
    axis,
    boolean,
    fraction,
    integer,
    number,
    register_kind,
    reject_unknown,
    speed_values,
    steps,
    sub_table,
)

# the speed parameter
from ._problem import (
    SPEED,
)

# storing its result
from ._store import (
    Result,
)

# argument checks and grid results
from ._studies import (
    GridResult,
    check_grid,
    check_integer,
    check_n_steps,
    check_parameter,
    collect,
    grid_status,
    grid_summary,
    open_store,
    reduction_check,
    reduction_headlines,
)

# its rows of the summary table
from ._summary import (
    PEAK_UNITS,
    Headline,
    Summary,
    largest_over_grid,
    listed,
    ranges,
    response_rows,
)

# a verdict from several
from ._verdicts import (
    combine,
)

__all__ = [
    "AXIS_KEYS",
    "ComputationError",
    "Estimate",
    "FAMILY_DOUBLES",
    "GridResult",
    "HARMONIC_WHY",
    "Headline",
    "LINEARISATION_DOUBLES",
    "MAX_AXIS_POINTS",
    "MAX_HARMONIC",
    "MAX_PERIODS",
    "MAX_STEPS",
    "NONLINEAR_DOUBLES",
    "NONLINEAR_STEP_N2_SECONDS",
    "NONLINEAR_STEP_SECONDS",
    "PEAK_UNITS",
    "PERIODS_WHY",
    "Result",
    "SHOOTING_PERIODS",
    "SPEED",
    "STEPS_WHY",
    "STUDY_SECONDS",
    "SWEEP_POINT_PERIODS",
    "Sizes",
    "StudiesError",
    "StudyKind",
    "Summary",
    "WARM_UP_STEPS",
    "axis",
    "axis_words",
    "boolean",
    "check_grid",
    "check_integer",
    "check_n_steps",
    "check_parameter",
    "collect",
    "combine",
    "fraction",
    "grid_cost",
    "grid_status",
    "grid_summary",
    "integer",
    "is_numerical_failure",
    "largest_over_grid",
    "largest_sizes",
    "linearisation",
    "listed",
    "nonlinear_period_seconds",
    "number",
    "open_store",
    "ranges",
    "reduction_check",
    "reduction_headlines",
    "register_kind",
    "reject_unknown",
    "response_rows",
    "run_grid",
    "sizes_at",
    "solve_seconds",
    "speed_values",
    "steady_solves",
    "steps",
    "sub_table",
    "tangent_bytes",
    "with_reduction_check",
]
