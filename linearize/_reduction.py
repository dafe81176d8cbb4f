"""The error of a modal reduction (``mechanisms.Fem(n_elements, modes=k)``), reported like every
other error: the steady state of the reduced mechanism against that of a reference, the next larger
mode set (``modes + 2`` on every reduced link) or, on request, the full element model.

The difference of each observable over the period, relative to the reference's peak-to-peak, is the
reduction's error estimate; above ``tolerance`` the verdict is ``inaccurate``, naming the links and
the fix (more modes). Modal truncation errors fall fast with the mode count (the static corrections
carry the quasi-static part of the response, the truncated modes only their dynamic amplification),
so the next larger set bounds the error of the smaller one in practice; the full model is the
unambiguous, costlier reference.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import Mapping

import numpy as np

import mechanisms
import periodic

from ._about import about
from ._core import LinearizationError

__all__ = ["ReductionCheck", "reduction_error", "REDUCTION_TOL", "reduced_links", "reference_mechanism"]

#: Default tolerance of the reduction error: 0.1 % of each observable's peak-to-peak.
REDUCTION_TOL = 1e-3
#: Modes added on every reduced link for the default reference.
NEXT_MODES = 2
_REFERENCES = ("next", "full")


@dataclass(frozen=True)
class ReductionCheck:
    """The check of a modal reduction: the reduction error of a mechanism's steady state against a
    reference, with its verdict (a result, not an exception; ``reduction_error`` returns it).

    Attributes
    ----------
    reference : str
        ``"next"`` (every reduced link with ``modes + 2``) or ``"full"``.
    modes : dict
        {link: (modes, reference modes or None for the full model)}.
    difference : dict, {spec: float}, unit of each observable
        The largest difference of each observable over the period.
    relative : dict, {spec: float}, 1
        That over the reference's peak-to-peak.
    error : float, 1
        The largest relative difference.
    tolerance : float, 1
        The relative tolerance deciding the status.
    status : str
        ``"ok"`` or ``"inaccurate"`` (``periodic.STATUSES``).
    message : str
        The verdict in words, naming the links and the fix.
    run_time : float, s
        Both steady states.
    """

    reference: str
    modes: Mapping[str, tuple[int, int | None]]
    difference: Mapping[str, float]
    relative: Mapping[str, float]
    error: float
    tolerance: float
    status: str
    message: str
    run_time: float


def reduced_links(mechanism) -> tuple[str, ...]:
    """Names of the elastic links of ``mechanism`` with a reduced model: a discretisation that
    declares the optional modal reduction (``modes`` and ``with_modes``, ``mechanisms.Fem`` or a
    registered one) with ``modes`` set."""
    return tuple(link.name for link in mechanism.links if _is_reduced(getattr(link, "discretisation", None)))


def _is_reduced(discretisation) -> bool:
    return (callable(getattr(discretisation, "with_modes", None))
            and getattr(discretisation, "modes", None) is not None)


def reference_mechanism(mechanism, reference: str = "next"):
    """``mechanism`` with every reduced link's ``modes`` raised by ``NEXT_MODES`` (capped at its
    element model's coordinates, where it becomes the full model) or, with ``reference="full"``,
    removed; returns ``(mechanism, {link: (modes, reference modes or None)})``."""
    if reference not in _REFERENCES:
        raise LinearizationError(f"reference must be one of {_REFERENCES}; received {reference!r}")
    links, modes = [], {}
    for link in mechanism.links:
        disc = getattr(link, "discretisation", None)
        if link.name in reduced_links(mechanism):
            n_coordinates = mechanisms.beam_shapes(dataclasses.replace(
                link, discretisation=disc.with_modes(None))).n_elastic
            larger = disc.modes + NEXT_MODES if reference == "next" else None
            if larger is not None and larger >= n_coordinates:
                larger = None
            modes[link.name] = (disc.modes, larger)
            link = dataclasses.replace(link, discretisation=disc.with_modes(larger))
        links.append(link)
    return mechanism.replace(links=tuple(links)), modes


def reduction_error(mechanism, *, n_steps: int = 256, observables=None, reference: str = "next",
                    tolerance: float = REDUCTION_TOL,
                    response: Mapping[str, np.ndarray] | None = None,
                    scheme: str | object = "trapezoidal") -> ReductionCheck:
    """The reduction error of the steady state of ``mechanism`` (``about(mechanism, n_steps=...,
    observables=...)``, ``periodic.steady_state``) against ``reference`` (``"next"``: modes + 2 on
    every reduced link; ``"full"``: the element models unreduced). A mechanism without reduced links
    has error 0 at once. ``tolerance`` (relative to each observable's peak-to-peak) decides the
    status. ``response`` {spec: (n_steps + 1,)}: the mechanism's own steady response when the caller
    already has it (a study's steady state, same steps and scheme), so only the reference is solved;
    it must hold every observable the reference reports. ``scheme``: the periodic scheme of both
    steady states (a name in ``periodic.SCHEMES`` or a scheme), the one ``response`` was computed
    with, so that the difference is the reduction's and not the schemes'."""
    if not (isinstance(tolerance, (int, float)) and np.isfinite(tolerance) and tolerance > 0):
        raise LinearizationError(f"tolerance must be a positive number (relative to the "
                                 f"peak-to-peak); received {tolerance!r}")
    started = time.perf_counter()
    if not reduced_links(mechanism):
        return ReductionCheck(reference, {}, {}, {}, 0.0, float(tolerance), "ok",
                              "no reduced link", time.perf_counter() - started)
    other, modes = reference_mechanism(mechanism, reference)
    exact = _steady_response(other, n_steps, observables, scheme)
    reduced = (_steady_response(mechanism, n_steps, observables, scheme) if response is None
               else _checked_response(response, exact))
    difference = {spec: float(np.abs(reduced[spec] - exact[spec]).max()) for spec in exact}
    relative = {spec: difference[spec] / max(float(np.ptp(exact[spec])), np.finfo(float).tiny)
                for spec in exact}
    error = max(relative.values(), default=0.0)
    against = ", ".join(f"{name}: {k} modes against {'the full model' if ref is None else ref}"
                        for name, (k, ref) in modes.items())
    if error > tolerance:
        worst = max(relative, key=relative.get)
        status = "inaccurate"
        message = (f"modal reduction error {error:.3g} of the peak-to-peak of {worst} > "
                   f"{tolerance:g} ({against}); raise modes on the reduced links")
    else:
        status = "ok"
        message = f"modal reduction error {error:.3g} <= {tolerance:g} ({against})"
    return ReductionCheck(reference, modes, difference, relative, float(error), float(tolerance),
                          status, message, time.perf_counter() - started)


def _checked_response(response, exact) -> dict[str, np.ndarray]:
    """The caller's ``response`` as arrays, checked against the reference's specs and samples."""
    missing = [spec for spec in exact if spec not in response]
    if missing:
        raise LinearizationError(f"response must hold every observable of the steady state "
                                 f"({sorted(exact)}); missing {missing}")
    found = {spec: np.asarray(response[spec], dtype=float) for spec in exact}
    for spec, values in found.items():
        if values.shape != exact[spec].shape:
            raise LinearizationError(f"response[{spec!r}] must have shape {exact[spec].shape} (the "
                                     f"n_steps + 1 samples); received shape {values.shape}")
    return found


def _steady_response(mechanism, n_steps, observables, scheme) -> dict[str, np.ndarray]:
    """The observables (N+1,) of the steady state of ``mechanism`` over one period."""
    linear = about(mechanism, n_steps=n_steps, observables=observables)
    state = periodic.steady_state(linear.system, scheme=scheme, estimate_error=False)
    return {spec: np.asarray(values) for spec, values in linear.observe(state.x).items()}
