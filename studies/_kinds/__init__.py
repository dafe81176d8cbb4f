"""The study kinds shipped with flexvib, one module each; importing this package registers them
(``studies.register_kind``), in the order a run performs them.

Adding a study kind: write one module here (a study function, its result class with ``plot``, and
``KIND = register_kind(StudyKind(...))`` declaring its table keys and their checks, how it runs, its
cost model, summary line, headlines, figures and demo entry; ``sweep.py`` is a grid study to copy,
``steady_state.py`` a single one), then add its name to the import below. Nothing else names the
kinds: the ``[studies]`` table, the resource guard, the warm-up, the summary table, the figures and
``studies.load`` ask the registry (``studies.kinds()``). A kind defined outside the package registers
itself the same way, with the public ``studies.StudyKind`` and ``studies.register_kind``.
"""

# isort: off
# imported to register each kind, in the order a run performs them (not alphabetical)
from . import (  # noqa: F401
    steady_state,
    sweep,
    campbell,
    stability_chart,
    nonlinear_check,
    nonlinear_steady_state,
    nonlinear_sweep,
    error_cost,
    control_comparison,
    run_up,
    optimize,
    sensitivity,
)
# isort: on
