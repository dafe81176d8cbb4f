"""The mesh term of the error budget: the response with each elastic link's discretisation refined
one level (provisional stub: the ``mesh`` helper writes it; this one says "not applicable")."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

from ._numerics import DEFAULT_SCHEME


@dataclass(frozen=True)
class MeshError:
    """The mesh error of a problem's steady state at one point.

    ``response``, ``peak``, ``peak_to_peak``: {spec: float} the estimated max abs error of the
    response samples, of the peak and of the peak-to-peak, in the observable's unit (NaN unknown);
    ``method`` words ("one refinement (2x elements), known order 4", "not applicable: ...");
    ``applicable`` False for a problem without elastic links; ``run_time`` s."""

    response: dict[str, float]
    peak: dict[str, float]
    peak_to_peak: dict[str, float]
    method: str
    applicable: bool
    run_time: float


def mesh_error(problem: Any, values: Mapping[str, float], *, observables: Any = None, n_steps: int,
               scheme: str = DEFAULT_SCHEME) -> MeshError:
    """Provisional: "not applicable" for every problem (the ``mesh`` helper's module replaces it)."""
    return MeshError(response={}, peak={}, peak_to_peak={},
                     method="not applicable: the mesh estimate is not built yet", applicable=False,
                     run_time=0.0)
