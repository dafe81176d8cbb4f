"""What a study kind is built with: the one internal module every module of ``studies._kinds``
imports its infrastructure from (checking its table, its cost model as the namespace ``cost``,
storing its result, running grid points, verdicts and summary rows). The declaration itself
(``StudyKind``, ``register_kind``) comes from ``studies._kind``, as it does for a kind defined
outside the package (``studies.StudyKind``); the numerics (``studies._numerics``), the figures
(``studies._plots``) and the problems' helpers (``studies._mechanism``) are imported on their own.
"""

from __future__ import annotations

# its cost model for the resource guard (cost.sizes_at, cost.grid_cost, ...)
from . import _cost as cost

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
    axis,
    boolean,
    fraction,
    integer,
    number,
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
    "cost",
    "AXIS_KEYS",
    "ComputationError",
    "GridResult",
    "HARMONIC_WHY",
    "Headline",
    "MAX_AXIS_POINTS",
    "MAX_HARMONIC",
    "MAX_PERIODS",
    "MAX_STEPS",
    "PEAK_UNITS",
    "PERIODS_WHY",
    "Result",
    "SPEED",
    "STEPS_WHY",
    "StudiesError",
    "Summary",
    "WARM_UP_STEPS",
    "axis",
    "boolean",
    "check_grid",
    "check_integer",
    "check_n_steps",
    "check_parameter",
    "collect",
    "combine",
    "fraction",
    "grid_status",
    "grid_summary",
    "integer",
    "is_numerical_failure",
    "largest_over_grid",
    "listed",
    "number",
    "open_store",
    "ranges",
    "reduction_check",
    "reduction_headlines",
    "reject_unknown",
    "response_rows",
    "run_grid",
    "speed_values",
    "steps",
    "sub_table",
]
