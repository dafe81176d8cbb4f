"""The registry of study kinds: ``KINDS`` maps each ``[studies.<name>]`` table to its
:class:`studies._kind.StudyKind`, in the order a run performs them.

Adding a study kind: write one module here (a study function, its result class with ``plot``, and a
``KIND = StudyKind(...)`` declaring its table keys and their checks, how it runs, its summary line and
figures; ``sweep.py`` is a grid study to copy, ``steady_state.py`` a single one), then add one line
to ``_MODULES`` below. ``studies._plan`` (scene tables) and ``studies.cli`` (summaries, figures) find
it here; export its study function and result class from ``studies/__init__.py`` for users.
"""

from __future__ import annotations

from typing import Any

from .._kind import StudyKind
from . import (
    campbell,
    control_comparison,
    error_cost,
    nonlinear_check,
    nonlinear_steady_state,
    nonlinear_sweep,
    optimize,
    stability_chart,
    steady_state,
    sweep,
)

_MODULES = (
    steady_state,
    sweep,
    campbell,
    stability_chart,
    nonlinear_check,
    nonlinear_steady_state,
    nonlinear_sweep,
    error_cost,
    control_comparison,
    optimize,
)

KINDS: dict[str, StudyKind] = {module.KIND.name: module.KIND for module in _MODULES}
_BY_RESULT = {kind.result: kind for kind in KINDS.values()}


def kind_of(result: Any) -> StudyKind:
    """The kind whose result ``result`` is (e.g. one read back by ``studies.load``)."""
    return _BY_RESULT[type(result)]
