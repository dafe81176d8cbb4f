"""The mesh term of the error budget: how far a steady response is from the one of a converged
discretisation of the elastic links.

Every elastic link's discretisation is refined one level (``refined()``: ``Fem`` twice the
elements, ``Ritz`` two more bending and axial modes; ``mechanisms/_parts/discretisations.py``) and
the steady state solved again on the same time grid with the same scheme, so that the difference
of the two responses is the spatial error (their time-step errors nearly cancel). Where every link
declares the order ``p`` of its error for an observable (``convergence_order``, for refinements
that halve the element size), the error of the user's response is

    e = SAFETY_FACTOR * |o_0 - o_1| * 2^p / (2^p - 1)

(``o_0`` the response, ``o_1`` the refined one; ``p`` the smallest order among the links). Where a
link declares none (a refinement that adds modes, a user's discretisation), a second refinement
gives the observed ratio ``r = |o_0 - o_1| / |o_1 - o_2|`` of successive differences and

    e = SAFETY_FACTOR * |o_0 - o_1| * r / (r - 1)

(a geometric series of differences), trusted for ``r >= MIN_OBSERVED_RATIO``; below it the levels
do not show a geometric convergence and the response's error is bounded by ``2 (|o_0 - o_1| +
|o_1 - o_2|)`` instead, its peak's and peak-to-peak's by the response's (``|max f - max g| <=
max |f - g|``). The safety factor is Roache's of the grid convergence index: at two elements the
six-bar is not yet in the asymptotic range (error ratio 14.7 against 16 for order 4).

Each of the response (max abs over the period), the peak and the peak-to-peak is estimated from its
own differences, in the observable's unit. ``applicable`` is False for a problem without elastic
links (a ``PeriodicProblem``, a mechanism of rigid links): no mesh, not a zero error. An
elastic link that declares no refinement, a refinement past a limit, or a refined solve that fails
leaves the term unknown (NaN) with the reason in ``method``.
"""

from __future__ import annotations

import math
import time
import warnings
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from ._numerics import DEFAULT_SCHEME, peak, peak_to_peak, study_scheme
from ._problem import SPEED

#: Roache's safety factor of the grid convergence index for an estimate with a known or observed
#: order (1.25): the coarse levels a user runs are not always in the asymptotic range.
SAFETY_FACTOR = 1.25
#: Below this ratio of successive differences three levels do not show geometric convergence.
MIN_OBSERVED_RATIO = 2.0
#: Differences below this fraction of the response's size are round-off.
_ROUNDOFF = 1e-12


@dataclass(frozen=True)
class MeshError:
    """The mesh term of one steady state: each a ``{spec: float}`` in the observable's unit, NaN
    where unknown.

    Attributes
    ----------
    response : dict
        The estimated max abs error of the response samples over the period.
    peak, peak_to_peak : dict
        The estimated error of the peak (largest magnitude) and of the peak-to-peak.
    method : str
        How it was estimated, in words ("one refinement (...), known order 4, ..." / "observed
        order from three levels ..." / "not applicable: ..." / "unknown: ...").
    applicable : bool
        False for a problem without elastic links (no mesh: not a zero error).
    run_time : float, s
        The refined linearisations and solves.
    """

    response: dict[str, float]
    peak: dict[str, float]
    peak_to_peak: dict[str, float]
    method: str
    applicable: bool
    run_time: float


def mesh_error(problem: Any, values: Mapping[str, float] | None, *, observables: Sequence[str] | None = None,
               n_steps: int, scheme: str = DEFAULT_SCHEME,
               response: Mapping[str, np.ndarray] | None = None) -> MeshError:
    """The mesh term of the steady state of ``problem`` at ``values`` on ``n_steps`` steps with
    ``scheme`` (module notes). ``observables``: the specs to estimate (default the problem's);
    ``response``: {spec: (N+1,)} the steady response the caller already has at these settings (else
    it is solved here too). A problem is refinable when it has a ``mechanism(values)`` (the
    mechanism problem); others are "not applicable"."""
    start = time.perf_counter()
    study_scheme(scheme)
    specs = tuple(problem.describe(values).observables if observables is None else observables)
    make_mechanism = getattr(problem, "mechanism", None)
    if make_mechanism is None:
        return _not_applicable(specs, "not applicable: the problem has no elastic links (no mesh)", start)
    params = problem.resolve(values)
    nominal = problem.parameters
    mechanism = make_mechanism({k: v for k, v in params.items() if k != SPEED and v != nominal[k]})
    elastic = [link for link in mechanism.links if getattr(link, "discretisation", None) is not None]
    if not elastic:
        return _not_applicable(specs, "not applicable: the mechanism has no elastic link (no mesh)", start)
    speed = {SPEED: params[SPEED]}
    unknown = _unrefinable(elastic)
    if unknown:
        return _unknown(specs, f"unknown: {unknown}", start)
    orders = {spec: _order(elastic, spec) for spec in specs}
    observed = any(order is None for order in orders.values())
    try:
        levels = [_refined_links(elastic)]
        if observed:
            levels.append(_refined_links(levels[0]))
    except ValueError as error:    # a count past its limit (MechanismError)
        return _unknown(specs, f"unknown: the discretisation cannot be refined: {error}", start)
    others = tuple(sorted((k, v) for k, v in params.items() if k != SPEED))
    try:
        base = (dict(response) if response is not None and all(s in response for s in specs)
                else _response(_problem_at(problem, others, specs, 0, lambda: mechanism), speed, n_steps,
                               scheme))
        base = {spec: np.asarray(base[spec], dtype=float) for spec in specs}
        finer = [_response(_problem_at(problem, others, specs, level + 1,
                                       lambda links=links: _with_links(mechanism, links)),
                           speed, n_steps, scheme) for level, links in enumerate(levels)]
    except (RuntimeError, ValueError) as error:   # a refined model that fails to solve
        return _unknown(specs, f"unknown: a refined model did not solve ({type(error).__name__}: {error})",
                        start)
    out: dict[str, dict[str, float]] = {"response": {}, "peak": {}, "peak_to_peak": {}}
    irregular: list[str] = []
    for spec in specs:
        series = [base[spec]] + [level[spec] for level in finer]
        estimates, regular = _estimates(series, orders[spec])
        for name, value in estimates.items():
            out[name][spec] = value
        if not regular:
            irregular.append(spec)
    method = _method(mechanism, elastic, levels, orders, irregular)
    return MeshError(response=out["response"], peak=out["peak"], peak_to_peak=out["peak_to_peak"],
                     method=method, applicable=True, run_time=time.perf_counter() - start)


@dataclass(frozen=True)
class RadiusMeshError:
    """The mesh term of a spectral radius at one point: ``error`` (1; NaN where unknown), ``radius``
    the user's discretisation's and ``refined`` the once-refined one's (the finest level's with
    three), ``method`` in words, ``applicable`` False without elastic links, ``run_time`` (s)."""

    error: float
    radius: float
    refined: float
    method: str
    applicable: bool
    run_time: float


#: The quantity whose ``convergence_order`` a discretisation declares for the Floquet multipliers
#: (and the natural frequencies): Hermite cubics converge in the eigenvalues at order 2(p + 1 - m) = 4
#: (p = 3 the polynomial degree, m = 2 the order of the bending energy's derivatives).
MULTIPLIERS = "multipliers"


@dataclass(frozen=True)
class _MultiplierPlan:
    """The refinements of a multipliers' mesh term at one point: the point's ``mechanism`` and its
    ``elastic`` links, the multipliers' declared ``order`` (None: observed from two refinements),
    ``levels`` (the refined links of each), the problem's ``specs``, the non-speed parameters
    ``others`` (sorted pairs) and ``speed`` {SPEED: rad/s}."""

    mechanism: Any
    elastic: list
    order: float | None
    levels: list
    specs: tuple
    others: tuple
    speed: dict


def _multiplier_plan(problem: Any, values: Mapping[str, float] | None
                     ) -> tuple[_MultiplierPlan | None, tuple[str, bool]]:
    """``(plan, ("", True))``, or ``(None, (words, applicable))`` where no mesh term of the multipliers can
    be had (no mechanism or elastic link: not applicable; a discretisation that cannot be refined:
    unknown); shared by the radius's and the frequencies' terms."""
    make_mechanism = getattr(problem, "mechanism", None)
    if make_mechanism is None:
        return None, ("not applicable: the problem has no elastic links (no mesh)", False)
    params = problem.resolve(values)
    nominal = problem.parameters
    mechanism = make_mechanism({k: v for k, v in params.items() if k != SPEED and v != nominal[k]})
    elastic = [link for link in mechanism.links if getattr(link, "discretisation", None) is not None]
    if not elastic:
        return None, ("not applicable: the mechanism has no elastic link (no mesh)", False)
    unknown = _unrefinable(elastic)
    if unknown:
        return None, (f"unknown: {unknown}", True)
    order = _order(elastic, f"{elastic[0].name}.{MULTIPLIERS}", every=MULTIPLIERS)
    try:
        levels = [_refined_links(elastic)]
        if order is None:
            levels.append(_refined_links(levels[0]))
    except ValueError as error:
        return None, (f"unknown: the discretisation cannot be refined: {error}", True)
    return _MultiplierPlan(mechanism, elastic, order, levels, tuple(problem.describe(values).observables),
                           tuple(sorted((k, v) for k, v in params.items() if k != SPEED)),
                           {SPEED: params[SPEED]}), ("", True)


def radius_mesh_error(problem: Any, values: Mapping[str, float] | None, *, n_steps: int,
                      scheme: str = DEFAULT_SCHEME, radius: float | None = None) -> RadiusMeshError:
    """The mesh term of the spectral radius of the monodromy of ``problem`` at ``values`` on
    ``n_steps`` steps with ``scheme``: as :func:`mesh_error` (the same refined models, from the same
    cache), the multipliers' declared order (``convergence_order("multipliers")``) with one refinement,
    else an observed rate from three levels. ``radius``: the caller's radius at these settings (else
    solved here)."""
    start = time.perf_counter()
    study_scheme(scheme)

    def answer(error: float, method: str, applicable: bool = True, levels: Sequence[float] = ()) -> RadiusMeshError:
        levels = list(levels) + [math.nan] * (2 - len(levels))
        return RadiusMeshError(float(error), float(levels[0]), float(levels[-1] if math.isfinite(levels[-1])
                                                                   else levels[1]),
                               method, applicable, time.perf_counter() - start)

    plan, why = _multiplier_plan(problem, values)
    if plan is None:
        return answer(math.nan, *why)
    mechanism, elastic, order, levels = plan.mechanism, plan.elastic, plan.order, plan.levels
    specs, others, speed = plan.specs, plan.others, plan.speed
    try:
        radii = [float(radius) if radius is not None else
                 _radius(_problem_at(problem, others, specs, 0, lambda: mechanism), speed, n_steps, scheme)]
        radii += [_radius(_problem_at(problem, others, specs, level + 1,
                                      lambda links=links: _with_links(mechanism, links)), speed, n_steps, scheme)
                  for level, links in enumerate(levels)]
    except (RuntimeError, ValueError) as error:
        return answer(math.nan, f"unknown: a refined model did not solve ({type(error).__name__}: {error})")
    error, regular = _scalar_estimate(radii, order)
    method = _method(mechanism, elastic, levels, {"spectral_radius": order},
                     [] if regular else ["the spectral radius"])
    return answer(error, method, True, radii)


def _scalar_estimate(levels: Sequence[float], order: float | None) -> tuple[float, bool]:
    """``(error, regular)`` of a scalar on the user's level from its values on the refined levels
    (one with a known ``order``, two otherwise): the rules of :func:`_estimates` for the response."""
    found, regular = _estimates([np.full(2, value) for value in levels], order, extremes=False)
    return found["response"], regular


def _radius(problem: Any, speed: Mapping[str, float], n_steps: int, scheme: str) -> float:
    """The spectral radius of a mechanism ``problem``'s monodromy at ``speed`` (no error estimate)."""
    return _floquet_at(problem, speed, n_steps, scheme, frozen=False).spectral_radius


@dataclass(frozen=True)
class _Floquet:
    """What the radius's and the frequencies' mesh terms need of one level's monodromy at one speed:
    ``multipliers`` (2m,) and ``resolved`` (2m,) bool (``periodic.floquet``), ``spectral_radius``,
    ``period`` (s), ``targets`` (m,) rad/s the mean frozen natural frequencies, ascending, and
    ``unfold_to`` (2m,) rad/s the one of the mode each multiplier belongs to
    (``studies._numerics.multiplier_modes``; NaN unassigned) (both None where not asked for: the
    radius's term needs none)."""

    multipliers: np.ndarray
    resolved: np.ndarray
    spectral_radius: float
    period: float
    targets: np.ndarray | None
    unfold_to: np.ndarray | None = None


#: Frozen-time samples per period of the mean frozen frequencies the characteristic frequencies of
#: the mesh term are unfolded to (only the nearest mean matters: a coarse mean does).
MESH_FROZEN_SAMPLES = 16


def _floquet_at(problem: Any, speed: Mapping[str, float], n_steps: int, scheme: str, *,
                frozen: bool = True) -> _Floquet:
    """The monodromy's multipliers and (``frozen``) the mean frozen frequencies of a mechanism
    ``problem`` at ``speed``, cached per process beside the refined problems: the radius's and the
    frequencies' terms of a Campbell diagram share each solve."""
    import periodic

    from ._numerics import frozen_modes, mode_targets, multiplier_modes

    key = (id(problem), tuple(sorted(speed.items())), int(n_steps), scheme)
    cached = _FLOQUETS.get(key)
    if cached is not None and cached[0] is problem and (cached[1].targets is not None or not frozen):
        _FLOQUETS.move_to_end(key)
        return cached[1]
    linear = problem.linearize(speed, n_steps=n_steps, context=False)
    result = periodic.floquet(linear.system, scheme=study_scheme(scheme))
    targets = unfold_to = None
    if frozen:
        _, frequencies, shapes = frozen_modes(linear.system, MESH_FROZEN_SAMPLES)
        means = frequencies.mean(axis=0)
        modes, _ = multiplier_modes(result.eigenvectors, shapes)
        targets, unfold_to = np.sort(means), mode_targets(modes, means)
    found = _Floquet(np.asarray(result.multipliers), np.asarray(result.resolved, dtype=bool),
                     float(result.spectral_radius), float(linear.system.period), targets, unfold_to)
    _FLOQUETS[key] = (problem, found)   # the problem held: its id cannot be reused while cached
    if len(_FLOQUETS) > 4 * _CACHE_SIZE:
        _FLOQUETS.popitem(last=False)
    return found


_FLOQUETS: OrderedDict = OrderedDict()


# ---------------------------------------------------------------------------------------------------
# the characteristic frequencies' mesh term (a Campbell diagram's)
# ---------------------------------------------------------------------------------------------------
#: A multiplier is matched to the nearest refined one only where that one is nearer than this
#: fraction of its distance to the next distinct refined multiplier (else: unmatched).
MATCH_FRACTION = 0.25
#: Multipliers closer than this are one (a real multiplier's conjugate).
_SAME_MULTIPLIER = 1e-12

MATCHING_WORDS = (f"modes matched by their multipliers: each resolved multiplier (of the upper half plane, "
                  f"a conjugate pair's one) to the nearest resolved refined one, accepted where that one is "
                  f"nearer than {MATCH_FRACTION:g} of its distance to the next; the frequency's change is the "
                  f"change of the multiplier's argument over the period (the unfolding kept). A frequency "
                  f"whose multiplier cannot be matched (two refined ones about as near, an unresolved stiff "
                  f"mode) or whose term reaches a quarter of the speed (the unfolding ambiguous) is unknown")


@dataclass(frozen=True)
class FrequencyMeshError:
    """The mesh term of the Floquet characteristic frequencies at one point: ``error`` (2m,) rad/s
    (NaN where unknown: unmatched or unresolved), ``frequencies`` (2m,) rad/s the user's
    discretisation's (``studies._numerics.characteristic_frequencies``, each unfolded to the mean
    frozen frequency of its mode), ``refined`` (2m,) the matched once-refined ones (NaN unmatched), ``mode`` (2m,) int
    the ascending rank of the mean frozen frequency each is unfolded to, ``method`` in words,
    ``applicable`` False without elastic links, ``run_time`` (s)."""

    error: np.ndarray
    frequencies: np.ndarray
    refined: np.ndarray
    mode: np.ndarray
    method: str
    applicable: bool
    run_time: float


def frequency_mesh_error(problem: Any, values: Mapping[str, float] | None, *, n_steps: int,
                         scheme: str = DEFAULT_SCHEME) -> FrequencyMeshError:
    """The mesh term of the characteristic frequencies of ``problem`` at ``values`` on ``n_steps``
    steps with ``scheme``: the refined models of :func:`radius_mesh_error` (the same cache, the
    same solves), each frequency matched to the refined model's (``MATCHING_WORDS``), the
    multipliers' declared order (``convergence_order("multipliers")``: natural frequencies converge
    at the eigenvalues' order) with one refinement, else an observed rate from three levels."""
    start = time.perf_counter()
    study_scheme(scheme)
    empty = np.full(0, np.nan)

    def answer(method: str, applicable: bool = True, found: tuple = ()) -> FrequencyMeshError:
        error, frequencies, refined, mode = found or (empty, empty, empty, np.full(0, -1))
        return FrequencyMeshError(error, frequencies, refined, mode, method, applicable,
                                  time.perf_counter() - start)

    plan, why = _multiplier_plan(problem, values)
    if plan is None:
        return answer(*why)
    mechanism, elastic, order, levels = plan.mechanism, plan.elastic, plan.order, plan.levels
    specs, others, speed = plan.specs, plan.others, plan.speed
    try:
        solved = [_floquet_at(_problem_at(problem, others, specs, 0, lambda: mechanism), speed, n_steps, scheme)]
        solved += [_floquet_at(_problem_at(problem, others, specs, level + 1,
                                           lambda links=links: _with_links(mechanism, links)), speed, n_steps, scheme)
                   for level, links in enumerate(levels)]
    except (RuntimeError, ValueError) as error:
        return answer(f"unknown: a refined model did not solve ({type(error).__name__}: {error})")
    from ._numerics import characteristic_frequencies

    coarse = solved[0]
    frequencies = characteristic_frequencies(coarse.multipliers, coarse.period, coarse.unfold_to)
    mode = nearest_rank(coarse.unfold_to, coarse.targets)   # the ascending rank of each one's mode
    upper = [np.where(s.resolved, _upper(s.multipliers), np.nan) for s in solved]
    matched = [upper[0]]
    for found in upper[1:]:
        matched.append(match_multipliers(matched[-1], found))
    # the argument's change over the period is the frequency's (|arg mu| / T + k Omega, k kept)
    shifts = [np.angle(level) / coarse.period for level in matched]
    error = np.full(frequencies.shape, np.nan)
    irregular = False
    for k in range(error.size):
        chain = [float(level[k]) for level in shifts]
        if all(math.isfinite(value) for value in chain):
            estimate, regular = _scalar_estimate(chain, order)
            if estimate < 0.25 * 2.0 * math.pi / coarse.period:
                error[k] = estimate
                irregular = irregular or not regular
    method = _method(mechanism, elastic, levels, {"characteristic frequencies": order},
                     ["the characteristic frequencies"] if irregular else [])
    unmatched = int(np.count_nonzero(np.isnan(error)))
    method += f"; {MATCHING_WORDS}" + (f" ({unmatched} of {error.size} unknown here)" if unmatched else "")
    refined = np.where(np.isfinite(error), frequencies + (shifts[1] - shifts[0]) * _unfolding_sign(coarse, frequencies),
                       np.nan)
    return answer(method, True, (error, frequencies, refined, mode))


def _upper(multipliers: np.ndarray) -> np.ndarray:
    """Each multiplier or its conjugate, whichever lies in the upper half plane (the characteristic
    frequency takes ``|arg mu|``)."""
    multipliers = np.asarray(multipliers, dtype=complex)
    return np.where(multipliers.imag < 0.0, multipliers.conj(), multipliers)


def _unfolding_sign(coarse: Any, frequencies: np.ndarray) -> np.ndarray:
    """+1 where a characteristic frequency is ``|arg mu| / T + k Omega``, -1 where ``-|arg mu| / T + k
    Omega`` (the sign a change of the argument moves it by)."""
    omega = 2.0 * math.pi / coarse.period
    base = np.abs(np.angle(coarse.multipliers)) / coarse.period
    plus = np.abs(np.remainder(frequencies - base + 0.5 * omega, omega) - 0.5 * omega)
    minus = np.abs(np.remainder(frequencies + base + 0.5 * omega, omega) - 0.5 * omega)
    return np.where(plus <= minus, 1.0, -1.0)


def match_multipliers(multipliers: np.ndarray, candidates: np.ndarray) -> np.ndarray:
    """Each of ``multipliers`` (k,) matched to the nearest of ``candidates`` (q,) in the complex plane
    (NaN left out), accepted where that candidate is nearer than ``MATCH_FRACTION`` of its distance to
    the next distinct candidate; (k,) complex, the matched candidates, NaN where none is accepted."""
    finite = np.asarray(candidates, dtype=complex)[np.isfinite(candidates)]
    distinct: list[complex] = []
    for value in finite:
        if all(abs(value - seen) > _SAME_MULTIPLIER for seen in distinct):
            distinct.append(complex(value))
    pool = np.asarray(distinct, dtype=complex)
    out = np.full(np.shape(multipliers), np.nan, dtype=complex)
    if pool.size == 0:
        return out
    for k, value in enumerate(np.asarray(multipliers, dtype=complex)):
        if not np.isfinite(value):
            continue
        best = int(np.argmin(np.abs(pool - value)))
        others = np.delete(pool, best)
        gap = float(np.abs(others - pool[best]).min()) if others.size else math.inf
        if abs(pool[best] - value) < MATCH_FRACTION * gap:
            out[k] = pool[best]
    return out


def nearest_rank(frequencies: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """(k,) int: the rank among the finite ``targets`` (ascending) of the one nearest each of
    ``frequencies`` (k,) (the mode a characteristic frequency was unfolded to), -1 where NaN."""
    ordered = np.sort(np.asarray(targets, dtype=float)[np.isfinite(targets)])
    out = np.full(np.shape(frequencies), -1, dtype=int)
    if ordered.size == 0:
        return out
    for k, value in enumerate(np.asarray(frequencies, dtype=float)):
        if math.isfinite(value):
            out[k] = int(np.argmin(np.abs(ordered - value)))
    return out


def _estimates(series: list[np.ndarray], order: float | None, *, extremes: bool = True
               ) -> tuple[dict[str, float], bool]:
    """``({"response", "peak", "peak_to_peak"}: error, regular)`` from the responses on the user's
    and the refined levels (each (N+1,)); ``order`` known (one refinement) or None (three levels);
    ``regular`` False where three levels did not converge geometrically. ``extremes`` False: the
    response's alone (a scalar repeated)."""
    measures = [{"response": s, **({"peak": peak(s)[0], "peak_to_peak": peak_to_peak(s)[0]} if extremes else {})}
                for s in series]
    scale = max(float(np.abs(series[0]).max()), 1e-300)

    def difference(name: str, i: int) -> float:
        a, b = measures[i][name], measures[i + 1][name]
        return float(np.abs(np.asarray(a) - np.asarray(b)).max())

    if order is not None:
        factor = SAFETY_FACTOR * 2.0**order / (2.0**order - 1.0)
        return {name: factor * difference(name, 0) for name in measures[0]}, True
    found, regular = {}, True
    for name in measures[0]:
        first, second = difference(name, 0), difference(name, 1)
        if max(first, second) <= _ROUNDOFF * scale:
            found[name] = first
        elif second > 0.0 and first / second >= MIN_OBSERVED_RATIO:
            ratio = first / second
            found[name] = SAFETY_FACTOR * first * ratio / (ratio - 1.0)
        elif name == "response":
            found[name] = 2.0 * (first + second)
            regular = False
        else:  # the extremes of two functions differ by at most the largest difference of the functions
            found[name] = found["response"] * (2.0 if name == "peak_to_peak" else 1.0)
            regular = False
    return found, regular


def _order(links: list, spec: str, every: str = "") -> float | None:
    """The smallest convergence order the links declare for ``spec`` (its quantity on its own link,
    ``every`` on the others: ``""`` a quantity elsewhere); None where one declares none."""
    head = spec.partition("@")[0]
    owner, _, quantity = head.rpartition(".")
    orders = []
    for link in links:
        declared = getattr(link.discretisation, "convergence_order", None)
        order = None if declared is None else declared(quantity if owner == link.name else every)
        if order is None:
            return None
        orders.append(float(order))
    return min(orders)


def _unrefinable(links: list) -> str:
    """Words naming the elastic links whose discretisation declares no ``refined()``, or ``""``."""
    missing = [f"link {link.name!r} ({type(link.discretisation).__name__}, type "
               f"{getattr(link.discretisation, 'TYPE', '?')!r})" for link in links
               if getattr(link.discretisation, "refined", None) is None]
    if not missing:
        return ""
    return (f"{', '.join(missing)} declares no refinement (a discretisation's refined(), "
            f"mechanisms/_parts/discretisations.py), so its mesh error cannot be estimated")


def _refined_links(links: list) -> list:
    import dataclasses

    return [dataclasses.replace(link, discretisation=link.discretisation.refined()) for link in links]


def _with_links(mechanism: Any, links: list) -> Any:
    by_name = {link.name: link for link in links}
    return mechanism.replace(links=tuple(by_name.get(link.name, link) for link in mechanism.links))


def _problem_at(problem: Any, others: tuple, specs: tuple[str, ...], level: int, make: Any) -> Any:
    """The mechanism problem of ``problem`` at the scene values ``others`` with its elastic links
    refined ``level`` times (``make()`` builds that mechanism), for ``specs``: cached per process, so
    that a sweep's points share one refined model (and its speed family) per level."""
    from ._mechanism import MechanismProblem

    key = (problem.text, others, specs, level)
    if key not in _PROBLEMS:
        _PROBLEMS[key] = MechanismProblem.from_mechanism(make(), observables=specs)
        if len(_PROBLEMS) > _CACHE_SIZE:
            _PROBLEMS.popitem(last=False)
    _PROBLEMS.move_to_end(key)
    return _PROBLEMS[key]


_CACHE_SIZE = 8
_PROBLEMS: OrderedDict = OrderedDict()


def _response(problem: Any, speed: Mapping[str, float], n_steps: int, scheme: str) -> dict[str, np.ndarray]:
    """{spec: (N+1,)} the steady response of a mechanism ``problem`` at ``speed`` without error
    estimates (the time-step error is another term; near-resonance warnings are the user's solve's
    to give)."""
    import periodic

    linear = problem.linearize(speed, n_steps=n_steps, context=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", periodic.NearResonanceWarning)
        state = periodic.steady_state(linear.system, scheme=study_scheme(scheme), estimate_error=False)
    observed = linear.observe(state.x)
    return {spec: observed[:, k] for k, spec in enumerate(linear.observables)}


def _method(mechanism: Any, links: list, levels: list, orders: Mapping[str, float | None],
            irregular: list[str]) -> str:
    """The method in words: what was refined, with which order or observed rate."""
    changes = []
    for k, link in enumerate(links):
        before = link.discretisation.to_table()
        after = [level[k].discretisation.to_table() for level in levels]
        keys = [key for key in before if any(table.get(key) != before[key] for table in after)]
        steps = ", ".join(f"{key} {' -> '.join(str(t.get(key)) for t in [before] + after)}" for key in keys)
        changes.append(f"{link.name}: {before.get('type', '?')} {steps}")
    refined = "; ".join(changes)
    known = sorted({order for order in orders.values() if order is not None})
    if len(levels) == 1:
        text = (f"one refinement ({refined}), known order {', '.join(f'{o:g}' for o in known)}, "
                f"safety factor {SAFETY_FACTOR:g}")
    else:
        text = (f"observed order from three levels ({refined}), safety factor {SAFETY_FACTOR:g}"
                + (f"; known order {', '.join(f'{o:g}' for o in known)} where declared" if known else ""))
    if irregular:
        text += (f"; no geometric convergence over the levels for {', '.join(irregular)}: bounded by "
                 f"twice the differences instead")
    return text


def _not_applicable(specs: tuple[str, ...], words: str, start: float) -> MeshError:
    nan = {spec: float("nan") for spec in specs}
    return MeshError(dict(nan), dict(nan), dict(nan), words, False, time.perf_counter() - start)


def _unknown(specs: tuple[str, ...], words: str, start: float) -> MeshError:
    nan = {spec: float("nan") for spec in specs}
    return MeshError(dict(nan), dict(nan), dict(nan), words, True, time.perf_counter() - start)
