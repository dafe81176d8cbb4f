"""``[studies.sensitivity]``: the derivative of every headline (each observable's peak-to-peak, peak and
RMS; the critical multiplier's modulus, the spectral radius) with respect to named parameters at one
point, each with its error estimate (N against N/2), normalised (d ln y / d ln p), and the first-order
band of each headline from tolerances on the parameters (the input term of the V&V split).  The
numerics: ``studies._derivatives`` (and ``periodic.response_derivative``, ``linearize.coefficient_derivative``).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Any, Mapping, Sequence

import numpy as np

from .._budget import INPUT, NOT_APPLICABLE, NOT_ESTIMATED, ErrorBudget, describe
from .._derivatives import HEADLINES, headline_errors, point_derivatives
from .._kind import StudyKind, register_kind
from .._mechanism import count_keys
from .._numerics import DEFAULT_SCHEME, peak_summary, study_scheme
from .._plots import Plot, axes_for, cost_line, drawn, plain
from .._result import StudyResult
from .._toolkit import (
    SPEED,
    Headline,
    StudiesError,
    Summary,
    check_n_steps,
    check_parameter,
    combine,
    cost,
    number,
    reject_unknown,
    speed_values,
    steps,
)

#: The fewest steps per period (N/4 = 4 steps is the error check's coarsest level, as a steady state's).
MIN_STEPS = 16
#: The headlines in words, for tables and figures.
HEADLINE_WORDS = {"peak_to_peak": "peak-to-peak", "peak": "peak", "rms": "RMS", "spectral_radius": "spectral radius"}


@dataclass(frozen=True, eq=False)
class SensitivityResult(StudyResult):
    """Derivatives of a steady state's headlines with respect to parameters at one point (the fields
    every result has: ``studies._result``).

    Attributes
    ----------
    problem, scene : str
        The problem's name and scene text.
    parameters : dict, {name: value}
        The point's parameter values (SI).
    names : tuple of str, (P,)
        The parameters differentiated with respect to.
    parameter_units : dict, {name: unit}
    units : dict, {spec: unit}
        Of each observable.
    derivative : dict, {spec: {name: float}}, units[spec] / parameter_units[name]
        d peak_to_peak / d parameter.
    derivative_error : dict, {spec: {name: float}}
        Its error estimate: ``error_factor`` times the difference of the N- and N/2-step derivatives.
    peak_derivative, peak_derivative_error, rms_derivative, rms_derivative_error : dict, {spec: {name: float}}
        The same for each observable's peak (largest magnitude) and RMS.
    radius_derivative, radius_derivative_error : dict, {name: float}, 1 / parameter_units[name]
        d |mu| / d parameter of the critical multiplier mu (the one that decides stability, whose modulus
        is ``critical_modulus``; NaN when it is repeated) and its error.
    normalised : dict, {headline: {spec: {name: float}}}, 1
        ``d ln y / d ln p = (p / y) dy/dp`` for headline "peak_to_peak", "peak", "rms" (and
        "spectral_radius" with the one spec "critical multiplier"); NaN where y or p is 0.
    tolerances : dict, {name: float}, parameter_units[name]
        The tolerances given (empty without).
    input_band : dict, {headline: {spec: float}}, units[spec]
        The first-order band of each headline from the tolerances, ``sqrt(sum (dy/dp tol)^2)`` (empty
        without tolerances); the peak-to-peak's and the peak's are the ``input`` term of their budgets.
    error_budget, peak_error_budget : dict, {spec: {term: float or str}}, units[spec]
        The error budgets (``studies._budget``) of the peak-to-peak and the peak: "time_step" (N against
        N/2), "mesh" and "linearisation" "not estimated" here (a mechanism's; "not applicable" for other
        problems), and with tolerances the input term "input" (the V&V split: reported apart, outside
        the numerical total, which is ``peak_to_peak_error`` / ``peak_error``).
    error_methods : dict, {term: str}
        How each term was estimated, in words.
    rms, rms_error : dict, {spec: float}, units[spec]
        Each observable's RMS over the period and its error.
    peak, peak_error, peak_to_peak, peak_to_peak_error : dict, {spec: float}, units[spec]
        The headlines themselves with their errors (not differentiated).
    critical_modulus : float, 1
        |critical multiplier|: the spectral radius over the resolved modes (``spectral_radius``, the
        largest modulus of all, also counts modes the step does not resolve; the message says when
        they differ).
    spectral_radius, spectral_radius_error : float, 1
        The steady state's spectral radius and its error (as ``steady_state`` reports them).
    methods : dict, {name: str}
        How each parameter's coefficient derivative was taken: "analytic" (a part carries it: a link's
        damping and Young's modulus, a controller's gains), "forward" (the kinematics do not move) or
        "central" difference of the linearisation's coefficients.
    steps : dict, {name: float}, parameter_units[name]
        The difference steps.
    status, message : str
        The steady state's verdict, and "inaccurate" where an extreme switches instant (two extremes
        within the response's error: the derivative is one-sided) or the critical multiplier is repeated.
    n_steps : int
    scheme : str
    run_time, steady_run_time, derivative_run_time : float, s
        The whole study; the point's linearisation and steady state; the derivatives (linearisations at
        the neighbouring values and the derivative runs).
    """

    problem: str
    parameters: Mapping[str, float]
    scene: str
    names: tuple[str, ...]
    parameter_units: Mapping[str, str]
    units: Mapping[str, str]
    derivative: Mapping[str, Mapping[str, float]]
    derivative_error: Mapping[str, Mapping[str, float]]
    peak_derivative: Mapping[str, Mapping[str, float]]
    peak_derivative_error: Mapping[str, Mapping[str, float]]
    rms_derivative: Mapping[str, Mapping[str, float]]
    rms_derivative_error: Mapping[str, Mapping[str, float]]
    radius_derivative: Mapping[str, float]
    radius_derivative_error: Mapping[str, float]
    normalised: Mapping[str, Mapping[str, Mapping[str, float]]]
    status: str
    message: str
    n_steps: int
    run_time: float
    spectral_radius: float = float("nan")
    spectral_radius_error: float = float("nan")
    critical_modulus: float = float("nan")
    tolerances: Mapping[str, float] = field(default_factory=dict)
    input_band: Mapping[str, Mapping[str, float]] = field(default_factory=dict)
    rms: Mapping[str, float] = field(default_factory=dict)
    rms_error: Mapping[str, float] = field(default_factory=dict)
    peak: Mapping[str, float] = field(default_factory=dict)
    peak_error: Mapping[str, float] = field(default_factory=dict)
    peak_to_peak: Mapping[str, float] = field(default_factory=dict)
    peak_to_peak_error: Mapping[str, float] = field(default_factory=dict)
    error_budget: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    peak_error_budget: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    error_methods: Mapping[str, str] = field(default_factory=dict)
    methods: Mapping[str, str] = field(default_factory=dict)
    steps: Mapping[str, float] = field(default_factory=dict)
    steady_run_time: float = float("nan")
    derivative_run_time: float = float("nan")
    scheme: str = DEFAULT_SCHEME

    @property
    def budget(self) -> ErrorBudget:
        """The peak-to-peak's ``error_budget`` as a ``studies._budget.ErrorBudget`` (total, input band)."""
        return ErrorBudget(self.error_budget, self.error_methods)

    def _filled(self, group: Any) -> dict[str, Any]:
        """A file written before the budgets: the time step's term and the input band it stored."""
        if "error_budget" in group.attrs:
            return {}
        return {name: _budget_terms(errors, NOT_ESTIMATED, self.input_band.get(headline))
                for name, errors, headline in (("error_budget", self.peak_to_peak_error, "peak_to_peak"),
                                               ("peak_error_budget", self.peak_error, "peak"))} | {
            "error_methods": _budget_methods(NOT_ESTIMATED, bool(self.tolerances))}

    def table(self, headline: str = "peak_to_peak") -> Mapping[str, Mapping[str, float]]:
        """{spec: {name: d y / d p}} of ``headline`` ("peak_to_peak", "peak", "rms")."""
        return {"peak_to_peak": self.derivative, "peak": self.peak_derivative, "rms": self.rms_derivative}[headline]

    def ranked(self, spec: str, headline: str = "peak_to_peak") -> list[tuple[str, float]]:
        """``[(name, d ln y / d ln p), ...]`` of one observable's headline, largest magnitude first."""
        row = self.normalised[headline][spec]
        return sorted(row.items(), key=lambda item: -abs(item[1]) if math.isfinite(item[1]) else 0.0)

    def plot(self, *, axes: Any = None) -> Plot:
        """The "tornado": per observable (and the spectral radius, last axes) the normalised sensitivities
        of its peak-to-peak, d ln y / d ln p, as horizontal bars ranked by size, with their error bars."""
        specs = list(self.derivative)
        axes = axes_for(len(specs) + 1, axes, height=max(1.6, 0.45 * len(self.names) + 1.0))
        artists: dict[str, list] = {}
        rows = [(spec, "peak_to_peak", self.derivative_error[spec], self.peak_to_peak.get(spec, math.nan))
                for spec in specs]
        rows.append(("critical multiplier", "spectral_radius", self.radius_derivative_error, self.critical_modulus))
        for ax, (spec, headline, errors, value) in zip(axes, rows):
            ranked = self.ranked(spec, headline)
            names = [name for name, _ in ranked][::-1]
            bars = [self.normalised[headline][spec][name] for name in names]
            spread = [errors[name] * abs(self.parameters[name] / value) if value else math.nan for name in names]
            colours = ["C3" if b > 0 else "C0" for b in bars]
            artists[spec] = [ax.barh(names, np.nan_to_num(bars), xerr=np.nan_to_num(spread), color=colours,
                                     capsize=3)]
            ax.axvline(0.0, color="0.4", lw=0.8)
            ax.set_xlabel(f"d ln({HEADLINE_WORDS[headline]}) / d ln(parameter)")
            unit = self.units.get(spec, "1")
            ax.set_title(f"{spec}: {HEADLINE_WORDS[headline]} {plain(value, 4)}{'' if unit == '1' else ' ' + unit}",
                         fontsize="small")
        axes[0].figure.suptitle(
            f"{self.problem}: sensitivities ({self.status})\n" + cost_line(
                "bars: normalised derivative, whiskers its error (N against N/2)", self.run_time),
            fontsize="medium", color="C3" if self.status != "ok" else "k")
        return drawn(axes, artists)


def _problem_with(problem: Any, names: Sequence[str], observables: Sequence[str] | None) -> Any:
    """The problem able to vary ``names`` and report ``observables`` (a mechanism problem is remade with
    them; any other must have them)."""
    if hasattr(problem, "parameter_paths") and hasattr(problem, "observable_specs"):
        changes = {}
        missing = tuple(n for n in names if n != SPEED and n not in problem.parameters)
        if missing:
            changes["parameter_paths"] = tuple(problem.parameter_paths) + missing
        if observables is not None and tuple(observables) != problem.observable_specs:
            changes["observable_specs"] = tuple(observables)
        if changes:
            problem = replace(problem, **changes)
    elif observables is not None:
        available = problem.describe().observables
        if tuple(observables) != tuple(available):
            raise StudiesError(f"observables: problem {problem.name!r} reports {', '.join(available)}; "
                               f"got {list(observables)} (its observables are fixed)")
    for name in names:
        check_parameter(problem, name)
    return problem


def _check_names(parameters: Any) -> tuple[str, ...]:
    if isinstance(parameters, str):
        parameters = (parameters,)
    if not isinstance(parameters, (list, tuple)) or not parameters or not all(isinstance(p, str) for p in parameters):
        raise StudiesError(f"parameters: expected a non-empty list of parameter names ('speed' or dotted scene "
                           f"paths, e.g. 'links.coupler.thickness'), got {parameters!r}")
    counts = count_keys()
    for name in parameters:
        if name.split(".")[-1] in counts:
            raise StudiesError(f"parameters: {name!r} is a count (it changes the number of coordinates), not a "
                               f"continuous parameter; differentiate with respect to continuous values only")
    if len(set(parameters)) != len(parameters):
        raise StudiesError(f"parameters: expected distinct names, got {list(parameters)}")
    return tuple(parameters)


def _check_tolerances(tolerances: Any, names: Sequence[str]) -> dict[str, float]:
    if tolerances is None:
        return {}
    if not isinstance(tolerances, Mapping):
        raise StudiesError(f"tolerances: expected a mapping of parameter names to tolerances (SI), e.g. "
                           f"{{'links.coupler.thickness': 5e-5}}, got {tolerances!r}")
    out = {}
    for name, value in tolerances.items():
        if name not in names:
            raise StudiesError(f"tolerances: {name!r} is not among the parameters differentiated "
                               f"({', '.join(names)}); add it to parameters")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
            raise StudiesError(f"tolerances[{name!r}]: expected a finite number >= 0 (the parameter's tolerance "
                               f"in its SI unit), got {value!r}")
        out[name] = float(value)
    return out


def _budget_terms(errors: Mapping[str, float], model_terms: str, band: Mapping[str, float] | None
                  ) -> dict[str, dict[str, Any]]:
    """{spec: {term: value}}: the time step's ``errors``, the mesh and linearisation ``model_terms``
    (not estimated, or not applicable), and the input ``band`` {spec: value} where tolerances gave one."""
    out = {}
    for spec, error in errors.items():
        out[spec] = {"time_step": float(error), "mesh": model_terms, "linearisation": model_terms}
        if band:
            out[spec][INPUT] = float(band[spec])
    return out


def _budget_methods(model_terms: str, tolerances: bool) -> dict[str, str]:
    words = ("not estimated at a sensitivity's point (run steady_state there for them)"
             if model_terms == NOT_ESTIMATED else "not applicable: the problem has no mesh and no linearisation")
    methods = {"time_step": "N against N/2 steps", "mesh": words, "linearisation": words}
    if tolerances:
        methods[INPUT] = ("first-order band sqrt(sum (dy/dp tol)^2) from the tolerances; apart from the "
                          "numerical total")
    return methods


def _normalised(derivative: float, parameter: float, value: float) -> float:
    return float(derivative * parameter / value) if value and parameter and math.isfinite(derivative) else math.nan


def sensitivity(problem: Any, values: Mapping[str, float] | None = None, *, parameters: Sequence[str],
                n_steps: int = 256, observables: Sequence[str] | None = None,
                tolerances: Mapping[str, float] | None = None, scheme: str = DEFAULT_SCHEME) -> SensitivityResult:
    """The derivatives of each headline of the steady state at ``values`` with respect to each of
    ``parameters`` ("speed" or dotted scene paths), by direct differentiation of the periodic problem
    (``studies._derivatives``), each with its N-against-N/2 error estimate; ``observables`` (specs)
    replace the problem's; ``tolerances`` {name: tolerance} give each headline's first-order band."""
    started = time.perf_counter()
    n_steps = check_n_steps(n_steps, minimum=MIN_STEPS, study="a sensitivity")
    study_scheme(scheme)
    names = _check_names(parameters)
    problem = _problem_with(problem, names, observables)
    tolerances = _check_tolerances(tolerances, names)
    point = point_derivatives(problem, values, names, n_steps=n_steps, scheme=scheme)
    steady, linear = point.steady, point.linear
    specs = tuple(linear.observables)
    fine, errors, switches = headline_errors(point)
    summary = peak_summary(steady.response, steady.response_error)
    rms = {spec: float(np.sqrt(np.mean(steady.response[:-1, k] ** 2))) for k, spec in enumerate(specs)}
    heads = {"peak_to_peak": {spec: float(summary["peak_to_peak"][k]) for k, spec in enumerate(specs)},
             "peak": {spec: float(summary["peak"][k]) for k, spec in enumerate(specs)}, "rms": rms}

    def table(array):
        return {spec: {name: float(array[j, k]) for j, name in enumerate(names)} for k, spec in enumerate(specs)}

    tables = {name: table(fine[name]) for name in HEADLINES}
    error_tables = {name: table(errors[name]) for name in HEADLINES}
    state = steady.state
    radius = {name: float(point.radius[j]) for j, name in enumerate(names)}
    radius_error = {name: float(point.radius_error[j]) for j, name in enumerate(names)}
    critical = abs(state.critical_multiplier)
    normalised = {headline: {spec: {name: _normalised(tables[headline][spec][name], point.values[name],
                                                      heads[headline][spec]) for name in names}
                             for spec in specs} for headline in HEADLINES}
    normalised["spectral_radius"] = {"critical multiplier": {
        name: _normalised(radius[name], point.values[name], critical) for name in names}}
    band = {}
    if tolerances:
        for headline in HEADLINES:
            band[headline] = {spec: float(math.sqrt(sum((tables[headline][spec][n] * t) ** 2
                                                        for n, t in tolerances.items()))) for spec in specs}
        band["spectral_radius"] = {"critical multiplier": float(math.sqrt(sum((radius[n] * t) ** 2
                                                                              for n, t in tolerances.items())))}
    parts = [(steady.status, steady.message)]
    for headline, k, instants in switches:
        parts.append(("inaccurate", f"the {HEADLINE_WORDS[headline]} of {specs[k]} has {instants} within the "
                      f"response's error: which instant holds it is not known, and its derivative is one-sided "
                      f"(the extreme switches instant)"))
    if point.repeated:
        parts.append(("inaccurate", point.radius_message))
    status, message = combine(parts)
    if not math.isclose(critical, state.spectral_radius, rel_tol=1e-12):
        note = (f"the radius derivative is that of the critical multiplier (|mu| = {critical:.6g}); the spectral "
                f"radius {state.spectral_radius:.6g} is that of a mode the step does not resolve")
        message = f"{message}; {note}" if message else note
    units = dict(zip(specs, linear.units))
    model_terms = NOT_ESTIMATED if callable(getattr(problem, "mechanism", None)) else NOT_APPLICABLE
    peak_to_peak_error = {spec: float(summary["peak_to_peak_error"][k]) for k, spec in enumerate(specs)}
    peak_error = {spec: float(summary["peak_error"][k]) for k, spec in enumerate(specs)}
    return SensitivityResult(
        problem=problem.name, parameters=point.values, scene=problem.text, names=names,
        parameter_units={name: problem.units[name] for name in names}, units=units,
        derivative=tables["peak_to_peak"], derivative_error=error_tables["peak_to_peak"],
        peak_derivative=tables["peak"], peak_derivative_error=error_tables["peak"],
        rms_derivative=tables["rms"], rms_derivative_error=error_tables["rms"],
        radius_derivative=radius, radius_derivative_error=radius_error, normalised=normalised,
        status=status, message=message, n_steps=n_steps, run_time=time.perf_counter() - started,
        spectral_radius=float(state.spectral_radius), spectral_radius_error=float(steady.spectral_radius_error),
        critical_modulus=float(critical),
        tolerances=tolerances, input_band=band, rms=rms,
        rms_error={spec: float(steady.response_error[k]) for k, spec in enumerate(specs)},
        peak={spec: float(summary["peak"][k]) for k, spec in enumerate(specs)},
        peak_error=peak_error, peak_to_peak=heads["peak_to_peak"], peak_to_peak_error=peak_to_peak_error,
        error_budget=_budget_terms(peak_to_peak_error, model_terms, band.get("peak_to_peak")),
        peak_error_budget=_budget_terms(peak_error, model_terms, band.get("peak")),
        error_methods=_budget_methods(model_terms, bool(tolerances)),
        methods=point.methods, steps=point.steps, steady_run_time=point.linear_run_time + steady.run_time,
        derivative_run_time=point.run_time, scheme=scheme)


# ---------------------------------------------------------------------------------------------------
# the [studies.sensitivity] table
# ---------------------------------------------------------------------------------------------------
TABLE_KEYS = ("speed", "parameters", "n_steps", "observables", "tolerances")


def _flatten(table: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """``{"links": {"coupler": {"thickness": 5e-5}}}`` (TOML's reading of an unquoted dotted key) as
    ``{"links.coupler.thickness": 5e-5}``."""
    flat = {}
    for key, value in table.items():
        if isinstance(value, Mapping):
            flat.update(_flatten(value, f"{prefix}{key}."))
        else:
            flat[f"{prefix}{key}"] = value
    return flat


def _check(where: str, table: Mapping[str, Any], n_steps: int) -> dict[str, Any]:
    reject_unknown(where, table, TABLE_KEYS)
    if "parameters" not in table:
        raise StudiesError(f"[{where}]: missing parameters (e.g. parameters = ['speed', 'links.coupler.thickness'])")
    try:
        names = _check_names(table["parameters"])
        tolerances = table.get("tolerances")
        if isinstance(tolerances, Mapping):
            tolerances = {path: number(where, f"tolerances.{path}", value)
                          for path, value in _flatten(tolerances).items()}
        tolerances = _check_tolerances(tolerances, names)
    except StudiesError as error:
        raise StudiesError(f"[{where}] {error}") from None
    observables = table.get("observables")
    if observables is not None and (not isinstance(observables, list) or not observables
                                    or not all(isinstance(s, str) for s in observables)):
        raise StudiesError(f"[{where}] observables: expected a non-empty list of observable specs, got "
                           f"{observables!r}")
    return {"values": speed_values(where, table), "parameters": list(names), "tolerances": tolerances,
            "observables": observables, "n_steps": steps(where, table, n_steps, minimum=MIN_STEPS)}


def _run(problem: Any, options: Mapping[str, Any], **_: Any) -> SensitivityResult:
    return sensitivity(problem, options["values"], parameters=options["parameters"], n_steps=options["n_steps"],
                       observables=options.get("observables"), tolerances=options.get("tolerances") or None,
                       scheme=options.get("scheme", DEFAULT_SCHEME))


def _varies(options: Mapping[str, Any]) -> tuple[str, ...]:
    return tuple(name for name in options["parameters"] if name != SPEED)


def _summary(result: SensitivityResult) -> str:
    parts = []
    for spec in result.derivative:
        top = result.ranked(spec)[:3]
        parts.append(f"{spec}: " + ", ".join(f"{name} {value:+.3g}" for name, value in top))
    words = f"{result.status}: {result.message}" if result.message else result.status
    budget = result.budget
    bands = [f"{spec} {describe(budget, spec, result.units[spec], terms=False)}" for spec in result.error_budget
             if not isinstance(budget.input_band(spec), str)]
    band_words = f"; peak-to-peak errors: {'; '.join(bands)}" if bands else ""
    return (f"{words}; d ln(peak-to-peak) / d ln(p): {'; '.join(parts)}{band_words}; "
            f"{result.run_time:.3g} s")


def _headlines(result: SensitivityResult) -> Summary:
    rows = []
    for spec in result.derivative:
        for name, value in result.ranked(spec)[:3]:
            rows.append(Headline(f"d ln p-p({spec}) / d ln {name}", float(value), "1",
                                 float(result.derivative_error[spec][name] * abs(
                                     result.parameters[name] / result.peak_to_peak[spec]))
                                 if result.peak_to_peak[spec] and result.parameters[name] else math.nan))
        band = result.budget.input_band(spec) if spec in result.error_budget else NOT_APPLICABLE
        if not isinstance(band, str):
            rows.append(Headline(f"input band of p-p({spec})", float(band), result.units[spec]))
    return Summary(status=result.status, run_time=result.run_time, rows=rows)


def _cost(name, problem, options, workers):
    """The point's steady state and, per parameter, up to two linearisations (a central difference) and
    the derivative runs (about a tenth of a periodic solve each)."""
    n_params = len(options["parameters"])
    found = cost.steady_solves(name, problem, [options["values"]], options["n_steps"])
    sizes = cost.sizes_at(problem, options["values"])
    _, build_seconds = cost.linearisation(options["n_steps"], sizes)
    solve = cost.solve_seconds(options["n_steps"], sizes)
    seconds = found.time + n_params * (2.0 * build_seconds + 0.5 * solve)
    return cost.Estimate(name, found.memory, seconds, f"1 steady state + {n_params} parameters x 2 linearisations "
                                                      f"x {options['n_steps']} steps x {sizes.m} coordinates")


def _warm_up(problem: Any) -> None:
    """The derivative runs' kernel (one forcing per column) on the warm-up's tiny grid."""
    sensitivity(problem, parameters=[SPEED], n_steps=32)


KIND = register_kind(StudyKind(
    name="sensitivity", result=SensitivityResult, keys=TABLE_KEYS, check=_check, run=_run, summary=_summary,
    varies=_varies, headlines=_headlines, cost=_cost, warm_up=_warm_up, schemes=True,
    demo={"parameters": ["speed", "damping_ratio", "epsilon"], "tolerances": {"damping_ratio": 0.002},
          "speed": 0.7}))
