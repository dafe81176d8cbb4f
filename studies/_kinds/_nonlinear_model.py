"""The model a nonlinear periodic state is computed on: the elastic links reduced to the fewest modes
the reduction check accepts (the default), a given mode count, or the full element models.

A nonlinear period costs about the square of the coordinates per step (the step's Newton, the
monodromy's columns), and an element model's coordinates mostly carry modes far above the response:
``six_bar`` with 8 elements per elastic link has 48 independent coordinates, reduced to 4 modes (plus
the static corrections of ``mechanisms.Fem``'s reduction) 24, at 0.02 % of the peak-to-peak (issue
24). The reduction error is stated with the result: ``linearize.reduction_error`` of the linear
steady state against the next larger mode set (``modes + 2``), on ``CHECK_STEPS`` steps per period
(a modelling error: the difference of two models on the same grid hardly depends on the grid).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from .._toolkit import StudiesError

#: Modes per reducible link where the default reduction starts: on ``six_bar`` (8 elements per link)
#: 2 modes leave 0.21 % of the peak-to-peak, 4 modes 0.015 % (linear check against the full model).
START_MODES = 4
#: The modes added per round while the check refuses (``linearize``'s ``NEXT_MODES``).
MODES_STEP = 2
#: Steps per period of the reduction check's linear steady states.
CHECK_STEPS = 32
#: The reduction error the default accepts, relative to each observable's peak-to-peak (the
#: reduction check's own default, ``linearize.REDUCTION_TOL``: 0.1 %).
REDUCTION_TOL = 1e-3
#: The stated reduction error is the check's difference times this: the check compares linear
#: steady states with two more modes, and on ``six_bar`` (8 elements per link, 4 modes, 100 rad/s) the
#: nonlinear orbit's peak-to-peak moved by up to 1.6 times that difference against the full model.
SAFETY = 2.0
#: Values of the ``modes`` option besides a mode count.
AUTO, FULL = "auto", "full"


@dataclass(frozen=True)
class ModelChoice:
    """The model a nonlinear study shoots on: ``problem`` and ``values`` to solve (the given ones, or
    a reduced mechanism's problem at the given speed), ``modes`` {link: modes} the study reduced ({}
    for the full model), ``error`` {spec: max abs difference over the period, unit of the spec} the
    reduction check's error (0 without a reduction), ``relative`` its largest ratio to a peak-to-peak,
    ``message`` the check in words ("" without one), ``run_time`` s of the choice; ``error`` and
    ``relative`` are ``SAFETY`` times the check's."""

    problem: Any
    values: Mapping[str, float] | None
    modes: Mapping[str, int]
    error: Mapping[str, float]
    relative: float
    message: str
    run_time: float


def check_modes(modes: Any) -> Any:
    """``modes`` as given when it is ``"auto"``, ``"full"``, None (the full models) or a mode count >= 1;
    else ``StudiesError`` naming the choices."""
    if modes is None or modes in (AUTO, FULL):
        return FULL if modes is None else modes
    if isinstance(modes, bool) or not isinstance(modes, (int, np.integer)) or modes < 1:
        raise StudiesError(f"modes: expected 'auto' (the elastic links reduced to the fewest modes the "
                           f"reduction check accepts), 'full' (the element models) or a mode count >= 1, "
                           f"got {modes!r}")
    return int(modes)


def choose_model(problem: Any, values: Mapping[str, float] | None, modes: Any) -> ModelChoice:
    """The model of a nonlinear study of ``problem`` at ``values`` for the ``modes`` option
    (``check_modes``): ``"full"`` the problem itself; a count every reducible link (an elastic link
    whose discretisation offers ``with_modes`` and is not reduced by the scene) reduced to it; ``"auto"``
    to ``START_MODES``, raised by ``MODES_STEP`` until the reduction check accepts (``REDUCTION_TOL``) or
    the links are back to their full models. A problem without a mechanism is returned as given."""
    import linearize

    started = time.perf_counter()
    modes = check_modes(modes)
    unchanged = ModelChoice(problem, values, {}, {}, 0.0, "", 0.0)
    if modes == FULL or not callable(getattr(problem, "mechanism", None)):
        return unchanged
    parameters = problem.resolve(values)
    nominal = problem.parameters
    mechanism = problem.mechanism({k: v for k, v in parameters.items()
                                   if k != "speed" and v != nominal.get(k)})
    sizes = _reducible(mechanism)
    if not sizes:
        return unchanged
    count = START_MODES if modes == AUTO else modes
    while True:
        # a link is reduced where the reduced model (modes and static corrections) is smaller than its
        # element model, and checked against two more modes where that set is smaller still (else
        # against the full model: a basis as large as the element model is rank-deficient)
        chosen = {name: count for name, size in sizes.items() if _reduced_size(mechanism, name, count) < size}
        if not chosen:
            return dataclasses.replace(unchanged, run_time=time.perf_counter() - started, message=(
                f"full element models: {count} modes and their static corrections are as many coordinates"))
        reference = ("next" if all(_reduced_size(mechanism, name, count + MODES_STEP) < sizes[name]
                                   for name in chosen) else "full")
        candidate = _reduced(mechanism, chosen)
        check = None
        for against in dict.fromkeys((reference, "full")):
            try:
                check = linearize.reduction_error(candidate, n_steps=CHECK_STEPS, reference=against,
                                                  observables=problem.observable_specs, tolerance=REDUCTION_TOL)
                break
            except (ValueError, RuntimeError) as error:  # a degenerate reference (or candidate): the full one
                failure = error
        if check is None:
            return dataclasses.replace(unchanged, run_time=time.perf_counter() - started, message=(
                f"full element models: the reduction check of {count} modes failed ({failure})"))
        if check.status == "ok" or modes != AUTO:
            break
        count += MODES_STEP
    # the reduced mechanism carries the values already (it is evaluated at the speed alone); the scene's
    # parameter paths are kept where its written spec still has them (a section written as its
    # thickness becomes area and second moment, a damping ratio Rayleigh's alpha and beta)
    paths = tuple(getattr(problem, "parameter_paths", ()))
    try:
        reduced = type(problem).from_mechanism(candidate, parameter_paths=paths, observables=problem.observable_specs)
    except StudiesError:
        reduced = type(problem).from_mechanism(candidate, observables=problem.observable_specs)
    error = {spec: SAFETY * value for spec, value in check.difference.items()}
    return ModelChoice(reduced, {"speed": parameters["speed"]} if "speed" in parameters else None, chosen,
                       error, SAFETY * float(check.error),
                       f"{check.message}; stated reduction error {SAFETY:g} times that",
                       time.perf_counter() - started)


def _reducible(mechanism: Any) -> dict[str, int]:
    """{link: its element model's elastic coordinates} of the links a reduction may reduce: elastic,
    a discretisation with ``with_modes`` and no ``modes`` of its own."""
    import mechanisms

    sizes = {}
    for link in mechanism.links:
        disc = getattr(link, "discretisation", None)
        if callable(getattr(disc, "with_modes", None)) and getattr(disc, "modes", 0) is None:
            sizes[link.name] = int(mechanisms.beam_shapes(link).n_elastic)
    return sizes


def _reduced_size(mechanism: Any, name: str, modes: int) -> int:
    """The elastic coordinates of link ``name`` reduced to ``modes`` modes (with its static corrections;
    its element model's where it has fewer than ``modes``)."""
    import mechanisms

    link = mechanism.link(name)
    try:
        return int(mechanisms.beam_shapes(dataclasses.replace(
            link, discretisation=link.discretisation.with_modes(modes))).n_elastic)
    except ValueError:      # more modes than the element model has (MechanismError): no reduction
        return int(mechanisms.beam_shapes(link).n_elastic)


def _reduced(mechanism: Any, modes: Mapping[str, int]) -> Any:
    links = tuple(dataclasses.replace(link, discretisation=link.discretisation.with_modes(modes[link.name]))
                  if link.name in modes else link for link in mechanism.links)
    return mechanism.replace(links=links)
