"""The error budget of a result: per observable, each source of error it can estimate, in the
observable's unit, their total, the dominant one and the status they decide (docs/methods.md, "Error
budget").

Terms (``TERMS``): ``time_step`` (N against N/2 steps with the scheme's order), ``mesh`` (each elastic
link's discretisation refined one level, ``studies._mesh_error``), ``linearisation`` (chord steps of the
full nonlinear periodic problem from the linear answer, ``linearize.linearisation_error``) and
``reduction`` (a reduced link against the next larger mode set, where a link is reduced). A term's
value is a float (a study of one point) or an array of the grid's shape; NaN: unknown (it applies,
but its estimate could not be trusted); a term that does not apply (a ``PeriodicProblem`` has no mesh
and no linearisation, a nonlinear state no linearisation) is the string ``NOT_APPLICABLE``, never 0.

The input term ``input`` (``INPUT``; the V&V split) is apart from these numerical terms: the
first-order band of the quantity from the tolerances on its parameters (``studies.sensitivity``), how
far the answer moves when the inputs do, not how far it is from the model's exact answer. It is shown
beside them (``input_band``) and enters neither the total, nor the dominant term, nor the tolerance
check, so a verdict means what it meant without tolerances.

The total is the sum of the magnitudes of the known numerical terms: terms can have opposite signs, and
an honest bar must not let them cancel. An applicable term that is unknown makes the total unknown
(NaN) and the status ``inaccurate`` ("the estimate is not trustworthy"), never ``ok``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

#: The terms of a budget, in the order they are shown.
TERMS = ("time_step", "mesh", "linearisation", "reduction")
#: The input term: the first-order band from the parameters' tolerances, outside the numerical total.
INPUT = "input"
#: The value of a term that does not apply to a result.
NOT_APPLICABLE = "not applicable"
#: The value of a term that applies but that no estimator covers for the quantity (the mesh term of a
#: spectral radius or of a frequency): outside the total, said in words, not judged.
NOT_ESTIMATED = "not estimated"
#: The default relative tolerance of the total error (``[studies] error_tolerance``, a study keyword).
ERROR_TOLERANCE = 0.02
#: The fix of each term, for the message of an inaccurate result.
FIXES = {
    "time_step": "refine n_steps",
    "mesh": "add elements (or Ritz / reduced modes) to the elastic links",
    "linearisation": "run the nonlinear state (nonlinear_steady_state), or lower the load",
    "reduction": "keep more modes of the reduced links",
}
#: Words of each term.
WORDS = {"time_step": "time step", "mesh": "mesh", "linearisation": "linearisation",
         "reduction": "modal reduction", INPUT: "input (tolerances)"}


def check_tolerance(value: Any, where: str = "error_tolerance") -> float:
    """``value`` as a relative tolerance in (0, 1); else ``StudiesError`` naming ``where``."""
    from ._errors import StudiesError

    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (0.0 < value < 1.0):
        raise StudiesError(f"{where}: expected a relative error tolerance between 0 and 1 "
                           f"(default {ERROR_TOLERANCE}), got {value!r}")
    return float(value)


def _applies(value: Any) -> bool:
    return not isinstance(value, str)


def _numerical(terms: Mapping[str, Any]) -> dict[str, Any]:
    """The numerical terms of one quantity (all but the input term)."""
    return {name: value for name, value in terms.items() if name != INPUT}


@dataclass(frozen=True)
class ErrorBudget:
    """The error budget of one quantity of a result (e.g. each observable's peak-to-peak).

    ``terms``: {spec: {term: value}} in the observable's unit (float or array of the grid's shape;
    NaN unknown; ``NOT_APPLICABLE`` where the term does not apply); ``methods``: {term: how it was
    estimated, in words}; ``run_times``: {term: s} the cost of each estimate."""

    terms: Mapping[str, Mapping[str, Any]]
    methods: Mapping[str, str] = field(default_factory=dict)
    run_times: Mapping[str, float] = field(default_factory=dict)

    def __getitem__(self, spec: str) -> Mapping[str, Any]:
        return self.terms[spec]

    def __iter__(self):
        return iter(self.terms)

    def __len__(self) -> int:
        return len(self.terms)

    def total(self, spec: str) -> Any:
        """The sum of the magnitudes of the applicable numerical terms (NaN where one is unknown); the
        input term stays apart (``input_band``)."""
        parts = [np.abs(np.asarray(v, dtype=float)) for v in _numerical(self.terms[spec]).values() if _applies(v)]
        if not parts:
            return math.nan
        total = sum(parts)
        return float(total) if np.ndim(total) == 0 else total

    def dominant(self, spec: str) -> Any:
        """The name of the largest applicable term (an array of names for a grid; "" where none is
        known), an unknown term dominating a known one (it may be anything)."""
        names = [k for k, v in _numerical(self.terms[spec]).items() if _applies(v)]
        if not names:
            return ""
        values = np.stack([np.asarray(self.terms[spec][k], dtype=float) for k in names])
        key = np.where(np.isnan(values), np.inf, np.abs(values))
        pick = np.argmax(key, axis=0)
        chosen = np.asarray(names, dtype=object)[pick]
        return str(chosen) if np.ndim(chosen) == 0 else chosen.astype(str)

    def unknown(self, spec: str) -> list[str]:
        """The applicable terms that are unknown (anywhere on a grid)."""
        return [k for k, v in _numerical(self.terms[spec]).items()
                if _applies(v) and np.isnan(np.asarray(v, dtype=float)).any()]

    def input_band(self, spec: str) -> Any:
        """The input term of ``spec`` (the tolerances' first-order band), ``NOT_APPLICABLE`` without."""
        return self.terms[spec].get(INPUT, NOT_APPLICABLE)

    def as_json(self) -> dict[str, dict[str, Any]]:
        """{spec: {term: value}} as a result file stores a budget of floats (NaN as null)."""
        return {spec: {k: (v if isinstance(v, str) else (None if math.isnan(float(v)) else float(v)))
                       for k, v in terms.items()} for spec, terms in self.terms.items()}

    @classmethod
    def from_json(cls, data: Mapping[str, Mapping[str, Any]], methods: Mapping[str, str] | None = None,
                  run_times: Mapping[str, float] | None = None) -> "ErrorBudget":
        terms = {spec: {k: (math.nan if v is None else v if isinstance(v, str) else float(v))
                        for k, v in values.items()} for spec, values in data.items()}
        return cls(terms, dict(methods or {}), dict(run_times or {}))


def budget_of(specs: Any, **terms: Mapping[str, Any] | str) -> dict[str, dict[str, Any]]:
    """{spec: {term: value}} from ``term=`` {spec: value} or ``NOT_APPLICABLE`` (a term missing for
    a spec is unknown, NaN)."""
    out: dict[str, dict[str, Any]] = {}
    for spec in specs:
        out[spec] = {}
        for name in TERMS:
            if name not in terms:
                continue
            values = terms[name]
            out[spec][name] = values if isinstance(values, str) else values.get(spec, math.nan)
    return out


def verdict(budget: ErrorBudget, values: Mapping[str, float], tolerance: float,
            quantity: str = "peak-to-peak") -> tuple[str, str]:
    """``(status, message)`` of a one-point result from the budget of its ``quantity`` ({spec:
    value}): ``inaccurate`` where an applicable term is unknown ("not trustworthy") or where the
    total exceeds ``tolerance * |value|``, the message naming the dominant term and its fix; ``ok``
    otherwise."""
    messages = []
    for spec, value in values.items():
        unknown = budget.unknown(spec)
        if unknown:
            messages.append(f"{spec}: the error estimate is not trustworthy: the "
                            f"{' and '.join(WORDS[k] for k in unknown)} term is unknown; "
                            f"{FIXES[unknown[0]]}")
            continue
        total = budget.total(spec)
        if not total <= tolerance * abs(float(value)):
            dominant = budget.dominant(spec)
            messages.append(f"{spec}: {quantity} error {total:.3g} exceeds error_tolerance "
                            f"{tolerance:g} of the value {float(value):.3g}, mostly "
                            f"{WORDS.get(dominant, dominant)} ({abs(budget[spec][dominant]):.3g}); "
                            f"{FIXES.get(dominant, '')}")
    return ("inaccurate", "; ".join(messages)) if messages else ("ok", "")


def beside(status: str, found: tuple[str, str]) -> tuple[str, str]:
    """The budget's verdict ``found`` beside a point's own ``status``: near a resonance (where the
    periodic verdict already says the numbers are sensitive, and refining the step does not remove
    the cause) an ``inaccurate`` budget is reported in the message and the word stays
    ``near_resonance``, as ``periodic.steady_state`` does with its own untrusted error."""
    if status == "near_resonance" and found[0] == "inaccurate":
        return "near_resonance", found[1]
    return found


def describe(budget: ErrorBudget, spec: str, unit: str = "", *, terms: bool = True) -> str:
    """"total 1.4 mm, mostly linearisation (linearisation 1.36, time step 0.01, mesh not applicable)" of
    one-point results; without the parenthesis where ``terms`` is False (a narrow panel's title)."""
    from ._summary import DISPLAY_UNITS

    shown, factor = DISPLAY_UNITS.get(unit, (unit, 1.0))
    suffix = f" {shown}" if shown and shown != "1" else ""
    parts = []
    for name, value in _numerical(budget[spec]).items():
        if isinstance(value, str):
            parts.append(f"{WORDS[name]} {value}")
        elif math.isnan(float(value)):
            parts.append(f"{WORDS[name]} unknown")
        else:
            parts.append(f"{WORDS[name]} {factor * abs(float(value)):.2g}")
    total = budget.total(spec)
    total_words = "unknown" if not math.isfinite(total) else f"{factor * total:.2g}{suffix}"
    words = f"total {total_words}, mostly {WORDS.get(budget.dominant(spec), '-')}"
    words = f"{words} ({', '.join(parts)})" if terms else words
    band = budget.input_band(spec)
    if not isinstance(band, str):
        words += f"; input band {factor * abs(float(band)):.2g}{suffix} from the tolerances (apart)"
    return words


#: The terms of a spectral radius (a stability chart's cell, a Campbell diagram's speed) besides its
#: time step (N against N/2), and their words (``error_methods``).
RADIUS_TERMS = {"mesh": NOT_ESTIMATED, "linearisation": NOT_APPLICABLE}
RADIUS_METHODS = {
    "time_step": "N against N/2 steps (periodic.floquet)",
    "mesh": "not estimated: the mesh estimate (studies._mesh_error) covers the response observables, not the "
            "multipliers; refine the elastic links to check",
    "linearisation": "not applicable: the multipliers are those of the linearised system, the stability of "
                     "small vibrations about the nominal motion"}


def radius_mesh_words(term: Any) -> str:
    """The mesh term of a radius in a short phrase: its largest value, or its words (None: a result
    written before the term, not estimated)."""
    if term is None:
        return NOT_ESTIMATED
    if isinstance(term, str):
        return term
    finite = np.asarray(term, dtype=float)[np.isfinite(np.asarray(term, dtype=float))]
    return f"up to {finite.max():.2g}" if finite.size else "unknown"


def radius_verdict(radius: float, error: float, tolerance: float, mesh: Any = NOT_ESTIMATED) -> tuple[str, str]:
    """``(status, message)`` of one spectral radius by its budget (time step ``error``, ``mesh`` its
    mesh term or words, linearisation not applicable): ``inaccurate`` where the total exceeds
    ``tolerance * radius`` or is unknown."""
    terms = {**RADIUS_TERMS, "mesh": mesh if isinstance(mesh, str) else float(mesh)}
    budget = ErrorBudget({"spectral_radius": {"time_step": float(error), **terms}})
    return verdict(budget, {"spectral_radius": float(radius)}, tolerance, quantity="spectral radius")


def stability_with_mesh(radius: float, error: float, mesh: float) -> tuple[str, str]:
    """``("marginal", message)`` where a spectral radius the time step alone judged stable (``1 - radius >
    error + periodic.STABILITY_TOL``, ``error`` its time-step bar) is within its bar widened by the mesh
    term ``mesh`` of 1: the stability is not decided at this mesh; else ``("ok", "")``."""
    import periodic

    margin = 1.0 - float(radius)
    if not (math.isfinite(margin) and math.isfinite(mesh)) or margin <= float(error) + periodic.STABILITY_TOL:
        return "ok", ""   # unstable or marginal already (the time step's own verdict), or no term
    if margin > float(error) + float(mesh) + periodic.STABILITY_TOL:
        return "ok", ""
    return "marginal", (f"marginal: the spectral radius {float(radius):.6g} is within its error bar of 1 once the "
                        f"mesh term counts (time step {float(error):.2g} + mesh {float(mesh):.2g}): stability not "
                        f"decided at this discretisation; refine the elastic links")


def radius_budget(error: Any, mesh: Any = None) -> dict[str, dict[str, Any]]:
    """{"spectral_radius": {term: value}}: the budget of a grid's spectral radius from its time-step
    error and its mesh term (arrays of the grid's shape; ``mesh`` None: not estimated, a result
    written before the term)."""
    return {"spectral_radius": {"time_step": error, **RADIUS_TERMS, **({} if mesh is None else {"mesh": mesh})}}


def headline_points(fields: Mapping[str, np.ndarray], points: Sequence[tuple[tuple, Mapping]],
                    scene_radius: float | None = None) -> dict[str, tuple[Mapping | None, float | None]]:
    """{words: (values or None for the scene's own point, the radius there or None)}: the headline
    points of a grid's mesh terms (the scene's point, the done cell of the largest radius and the one
    nearest radius 1; ``fields`` and ``points`` as :func:`grid_radius_mesh`'s)."""
    radius = np.asarray(fields.get("spectral_radius", np.full(1, np.nan)), dtype=float)
    done = np.asarray(fields.get("done", np.zeros(radius.shape, bool)), dtype=bool) & np.isfinite(radius)
    by_index = {tuple(index): values for index, values in points}
    headline: dict[str, tuple[Mapping | None, float | None]] = {"the scene's point": (None, scene_radius)}
    if done.any():
        flat = np.where(done, radius, np.nan)
        top = np.unravel_index(int(np.nanargmax(flat)), flat.shape)
        near = np.unravel_index(int(np.nanargmin(np.abs(flat - 1.0))), flat.shape)
        headline["the largest radius"] = (by_index[tuple(top)], float(radius[top]))
        headline["the radius nearest 1"] = (by_index[tuple(near)], float(radius[near]))
    return headline


def grid_radius_mesh(problem: Any, fields: dict[str, np.ndarray], points: Sequence[tuple[tuple, Mapping]], *,
                     n_steps: int, scheme: str, tolerance: float, scene_radius: float | None = None
                     ) -> tuple[np.ndarray | str, str]:
    """The mesh term of a grid's spectral radius (a stability chart's, a Campbell diagram's):
    ``studies._mesh_error.radius_mesh_error`` at its headline points (the scene's own point, the cell of the
    largest radius and the cell nearest radius 1), the largest relative error among them applied
    to every cell (error / radius times the cell's radius). ``fields``: the grid's collected
    fields (``spectral_radius``, ``spectral_radius_error``, ``done``, ``point_status``,
    ``point_message``), whose verdicts are judged again with the term (in place); ``points``:
    ``[(index, values)]`` of the grid. Returns ``(term of the grid's shape or NOT_APPLICABLE words,
    method)``. ``scene_radius``: the radius at the scene's own point where the caller has it (a sweep's)."""
    from ._mesh_error import radius_mesh_error
    from ._verdicts import combine

    radius = np.asarray(fields.get("spectral_radius", np.full(1, np.nan)), dtype=float)
    done = np.asarray(fields.get("done", np.zeros(radius.shape, bool)), dtype=bool) & np.isfinite(radius)
    headline = headline_points(fields, points, scene_radius)
    shares, found, method = [], [], ""
    for words, (values, known) in headline.items():
        estimate = radius_mesh_error(problem, values, n_steps=n_steps, scheme=scheme, radius=known)
        if not estimate.applicable:
            return NOT_APPLICABLE, estimate.method
        method = estimate.method
        share = estimate.error / max(abs(estimate.radius), 1e-300)
        found.append(f"{words} {100 * share:.2g} %")
        shares.append(share)
    # an unknown share leaves the term unknown (its cells inaccurate: not trustworthy), never the others'
    relative = math.nan if any(math.isnan(share) for share in shares) else max(shares)
    mesh = relative * np.abs(radius)
    # fixed-width str arrays would cut a longer message: judged as objects, stored back as str
    status_of, message_of = (np.asarray(fields[key]).astype(object) for key in ("point_status", "point_message"))
    for index in zip(*np.nonzero(done)):
        # the point's own verdict judged the time step alone: its message gives way to the total's
        _, alone = radius_verdict(radius[index], fields["spectral_radius_error"][index], tolerance)
        status, message = radius_verdict(radius[index], fields["spectral_radius_error"][index], tolerance,
                                         mesh=mesh[index])
        if str(status_of[index]) not in ("unstable", "marginal"):
            status, message = combine([(status, message), stability_with_mesh(
                radius[index], fields["spectral_radius_error"][index], mesh[index])])
        words = str(message_of[index])
        if status == "ok" or message in words:   # ok, or judged already (a resumed grid)
            continue
        if alone and alone in words:
            message_of[index] = words.replace(alone, message)
        else:
            status_of[index], message_of[index] = combine([(str(status_of[index]), words), (status, message)])
    fields["point_status"], fields["point_message"] = status_of.astype(str), message_of.astype(str)
    return mesh, (f"{method}; at the headline points ({', '.join(found)} of the radius), the largest "
                  f"applied to every cell relatively")


def grid_frequency_mesh(problem: Any, fields: Mapping[str, np.ndarray], points: Sequence[tuple[tuple, Mapping]],
                        characteristic: np.ndarray, band_mean: np.ndarray, *, n_steps: int, scheme: str,
                        unfolded_to: np.ndarray | None = None) -> tuple[np.ndarray | str, str]:
    """The mesh term of a Campbell diagram's characteristic frequencies ``characteristic`` (n, 2m)
    rad/s: ``studies._mesh_error.frequency_mesh_error`` at the radius's headline points
    (:func:`headline_points`), each mode's largest relative error among the points where it was
    matched applied to that mode's frequencies at every speed (a frequency's mode: the ascending rank
    of the mean frozen frequency ``band_mean`` (n, m) nearest it, the one it was unfolded to). A mode
    matched at no headline point is unknown (NaN). Returns ``(term (n, 2m) or NOT_APPLICABLE words,
    method)``."""
    from ._mesh_error import MATCHING_WORDS, frequency_mesh_error, nearest_rank

    characteristic = np.asarray(characteristic, dtype=float)
    n_modes = np.shape(band_mean)[1]
    shares = np.full(n_modes, np.nan)
    method, found = "", []
    for words, (values, _) in headline_points(fields, points).items():
        estimate = frequency_mesh_error(problem, values, n_steps=n_steps, scheme=scheme)
        if not estimate.applicable:
            return NOT_APPLICABLE, estimate.method
        method = estimate.method.split("; modes matched")[0]
        known = np.isfinite(estimate.error) & (estimate.mode >= 0) & (np.abs(estimate.frequencies) > 0)
        for mode in np.unique(estimate.mode[known]):
            pick = known & (estimate.mode == mode)
            share = float(np.max(estimate.error[pick] / np.abs(estimate.frequencies[pick])))
            if mode < n_modes:
                shares[mode] = share if np.isnan(shares[mode]) else max(share, shares[mode])
        found.append(f"{words} {int(known.sum())} of {estimate.error.size}")
    term = np.full(characteristic.shape, np.nan)
    for i in range(characteristic.shape[0]):
        mode = nearest_rank(characteristic[i] if unfolded_to is None else unfolded_to[i], band_mean[i])
        inside = mode >= 0
        term[i, inside] = shares[mode[inside]] * np.abs(characteristic[i, inside])
    return term, (f"{method}; {MATCHING_WORDS}; at the headline points ({', '.join(found)} frequencies matched), "
                  f"each mode's (by ascending mean frozen frequency) largest relative error applied to its "
                  f"frequencies at every speed, unknown for a mode matched at none")


# ---------------------------------------------------------------------------------------------------
# the budget of a linear steady state at one point
# ---------------------------------------------------------------------------------------------------
#: The three quantities a steady state reports per observable, each with its budget.
QUANTITIES = ("response", "peak", "peak_to_peak")


@dataclass(frozen=True)
class PointBudget:
    """The budgets of a linear steady state at one point: ``budgets`` {quantity: ErrorBudget} for
    each of ``QUANTITIES`` (the response samples' max abs error, the peak's, the peak-to-peak's);
    ``linearisation``: the ``linearize.LinearisationError`` (None where it does not apply)."""

    budgets: Mapping[str, ErrorBudget]
    linearisation: Any = None

    def totals(self, quantity: str) -> dict[str, float]:
        """{spec: total} of one quantity."""
        budget = self.budgets[quantity]
        return {spec: budget.total(spec) for spec in budget}


#: The linearisation term of a budget is the chord estimate widened by this factor: the estimate is
#: within 0.8x-1.4x of the nonlinear state's difference on the shipped scenes (tests/test_budget.py),
#: and a bar must cover the difference, not straddle it (docs/methods.md, "Error budget").
LINEARISATION_MARGIN = 1.5
#: Chord steps at a sweep's point (a steady state takes ``linearize``'s default, 5): three keep the
#: estimate within 0.5x-2x of the nonlinear state's difference on the shipped scenes
#: (tests/test_budget.py) for about half the cost.
GRID_CHORD_STEPS = 3


def linearisation_terms(linear: Any, steady: Any, scheme: Any, *, max_steps: int | None = None
                        ) -> tuple[dict[str, Any] | str, str, float, Any]:
    """The linearisation term of a linear steady state (``studies._numerics.Steady`` of ``linear``):
    ``({quantity: {spec: signed value}} or NOT_APPLICABLE, method, run time, the
    linearize.LinearisationError or None)``. It applies where ``linear.context`` is a linearised
    mechanism (a ``PeriodicProblem`` is linear by definition)."""
    import linearize

    from ._numerics import peak, peak_to_peak, study_scheme

    # the linearised mechanism at the point (a MechanismLinear's member; a periodic problem's
    # context is its parameters: nothing linearised)
    member = getattr(linear, "member", None)
    lin = member() if member is not None else linear.context
    if getattr(lin, "coefficients", None) is None:
        return NOT_APPLICABLE, "not applicable: the problem is linear as written", 0.0, None
    if not steady.is_stable:
        # the system does not reach the periodic solution: there is no nonlinear state near it to
        # estimate (the term is unknown, the point unstable)
        unknown = {name: {spec: math.nan for spec in linear.observables} for name in QUANTITIES}
        return unknown, "unknown: the periodic state is unstable", 0.0, None
    options = {} if max_steps is None else {"max_steps": max_steps}
    found = linearize.linearisation_error(lin, steady.state.x, system=linear.system,
                                          observe=linear.observe, scheme=study_scheme(scheme),
                                          monodromy=steady.state.monodromy, **options)
    response = steady.response
    terms: dict[str, dict[str, float]] = {name: {} for name in QUANTITIES}
    for k, spec in enumerate(linear.observables):
        change = found.change[:, k]
        if not np.isfinite(change).all():
            for name in QUANTITIES:
                terms[name][spec] = math.nan
            continue
        terms["response"][spec] = LINEARISATION_MARGIN * float(np.abs(change).max())
        terms["peak"][spec] = LINEARISATION_MARGIN * (peak(response[:, k] + change)[0]
                                                      - peak(response[:, k])[0])
        terms["peak_to_peak"][spec] = LINEARISATION_MARGIN * (peak_to_peak(response[:, k] + change)[0]
                                                              - peak_to_peak(response[:, k])[0])
    method = (f"{found.method}, widened {LINEARISATION_MARGIN:g}x" if found.trusted
              else f"unknown: {found.reason}")
    return terms, method, found.run_time, found


def mesh_terms(problem: Any, values: Mapping[str, float] | None, observables: Any, n_steps: int,
               scheme: str, response: Mapping[str, Any] | None = None) -> tuple[dict[str, Any] | str, str, float]:
    """The mesh term at one point (``studies._mesh_error.mesh_error``): ``({quantity: {spec:
    value}} or NOT_APPLICABLE, method, run time)``; ``response`` ({spec: (N+1,)}): the linear steady
    response of ``problem`` at these settings where the caller has it (not solved again)."""
    from ._mesh_error import mesh_error

    found = mesh_error(problem, dict(values or {}), observables=observables, n_steps=n_steps,
                       scheme=scheme, response=response)
    if not found.applicable:
        return NOT_APPLICABLE, found.method, found.run_time
    return ({"response": dict(found.response), "peak": dict(found.peak),
             "peak_to_peak": dict(found.peak_to_peak)}, found.method, found.run_time)


def reduction_terms(reduction: Any, specs: Any) -> tuple[dict[str, Any] | str, str]:
    """The modal-reduction term from a ``linearize.ReductionCheck`` (None or one without reduced
    links: not applicable): the response's largest difference, twice it for the peak-to-peak."""
    if reduction is None or not getattr(reduction, "modes", None):
        return NOT_APPLICABLE, "not applicable: no reduced link"
    difference = {spec: float(reduction.difference.get(spec, math.nan)) for spec in specs}
    return ({"response": difference, "peak": difference,
             "peak_to_peak": {spec: 2.0 * v for spec, v in difference.items()}},
            f"against the {reduction.reference} mode set")


def point_budget(specs: Any, time_step: Mapping[str, Mapping[str, float]], *, mesh: Any = NOT_APPLICABLE,
                 linearisation: Any = NOT_APPLICABLE, reduction: Any = None,
                 methods: Mapping[str, str] | None = None, run_times: Mapping[str, float] | None = None,
                 found: Any = None) -> PointBudget:
    """The budgets of one point from each term's {quantity: {spec: value}} (or ``NOT_APPLICABLE``);
    ``reduction`` None: the term is left out (a problem whose links cannot be reduced)."""
    budgets = {}
    for quantity in QUANTITIES:
        parts: dict[str, Any] = {"time_step": time_step[quantity], "mesh": _part(mesh, quantity),
                                 "linearisation": _part(linearisation, quantity)}
        if reduction is not None and reduction != NOT_APPLICABLE:
            parts["reduction"] = _part(reduction, quantity)
        budgets[quantity] = ErrorBudget(budget_of(specs, **parts), dict(methods or {}),
                                        dict(run_times or {}))
    return PointBudget(budgets, found)


def _part(term: Any, quantity: str) -> Any:
    return term if isinstance(term, str) else term[quantity]


def format2_budget(errors: Mapping[str, float]) -> dict[str, dict[str, Any]]:
    """The budget a result file of format 2 (written before the budget) reads as: its errors were the
    time step's alone, the other terms unknown."""
    return {spec: {"time_step": float(value), "mesh": math.nan, "linearisation": math.nan}
            for spec, value in errors.items()}


#: The methods a format-2 file's budget reads with.
FORMAT2_METHODS = {"time_step": "N against N/2 steps",
                   "mesh": "unknown: the file was written before the error budget (format 2)",
                   "linearisation": "unknown: the file was written before the error budget (format 2)"}


# ---------------------------------------------------------------------------------------------------
# the budget of a nonlinear run's steady peaks (a control comparison)
# ---------------------------------------------------------------------------------------------------
def nonlinear_run_budget(problem: Any, values: Mapping[str, float] | None, peaks: Mapping[str, float],
                         time_step: Mapping[str, float], meshed: Any, *, n_steps: int,
                         tolerance: float, scheme: str = "trapezoidal", quantity: str = "steady peak"
                         ) -> tuple[dict[str, dict[str, Any]], dict[str, str], tuple[str, str]]:
    """The budget of the steady peaks ``peaks`` {spec: value} of a run of the full nonlinear
    equations: ``(terms {spec: {term: value}}, methods, (status, message))``. Time step:
    ``time_step`` {spec: error}; mesh: the linear steady state's peak error at ``values``
    (``studies._mesh_error``) for the specs in ``meshed`` (observables of the scene's links), not
    estimated for the others; linearisation: not applicable (nothing is linearised)."""
    mesh, mesh_method, _ = mesh_terms(problem, values, tuple(meshed), n_steps, scheme)
    mesh_peaks = {} if mesh == NOT_APPLICABLE else mesh["peak"]
    terms = {spec: {"time_step": float(time_step.get(spec, math.nan)),
                    "mesh": (NOT_APPLICABLE if mesh == NOT_APPLICABLE
                             else float(mesh_peaks.get(spec, math.nan)) if spec in meshed else NOT_ESTIMATED),
                    "linearisation": NOT_APPLICABLE} for spec in peaks}
    methods = {"time_step": "N against N/2 steps (Richardson), over the last period",
               "mesh": (mesh_method if mesh == NOT_APPLICABLE else
                        f"{mesh_method}, of the linear steady state's peak at the point (the elastic "
                        f"quantities; the others not estimated)"),
               "linearisation": "not applicable: the runs integrate the full nonlinear equations"}
    budget = ErrorBudget(terms, methods)
    return terms, methods, verdict(budget, peaks, tolerance, quantity=quantity)
