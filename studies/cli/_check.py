"""``flexvib check``: extreme cases, what the tool says about each, and the independent reference it
is held to.

Each case builds a problem at the edge of what the method covers, runs the study a user would run,
and compares the status, message and numbers with a reference that does not come from the same
computation (a closed form, another discretisation, the full nonlinear model, a scaling law, the
same mechanism in other units). Settings are small so the whole table runs in about a minute.
"""

from __future__ import annotations

import copy
import math
import time
import warnings
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

import periodic

from .._kinds.nonlinear_check import nonlinear_check
from .._kinds.steady_state import steady_state
from .._mechanism import MechanismProblem
from .._problem import mathieu_problem

#: The four-bar every mechanism case starts from: the thesis four-bar with geometric stiffening.
BASE_SCENE = "four_bar_ritz"
OBSERVABLE = "coupler.deflection@0.5"


@dataclass(frozen=True)
class CaseOutcome:
    """One row of the check: ``case`` name, ``status`` and ``message`` the tool gave, ``numbers`` what
    it computed, ``reference`` the independent reference and its value, ``expected`` the outcome
    that counts as right, ``passed``, ``run_time`` s."""

    case: str
    status: str
    message: str
    numbers: str
    reference: str
    expected: str
    passed: bool
    run_time: float


def _scene(changes: dict[str, Any] | None = None, *, drop: tuple[str, ...] = ()) -> Any:
    """The base four-bar with scene values changed (dotted paths) and keys dropped."""
    import mechanisms

    spec = copy.deepcopy(mechanisms.load(BASE_SCENE).spec)
    spec.pop("studies", None)
    for path in drop:
        *head, last = path.split(".")
        table = spec
        for key in head:
            table = table[key]
        table.pop(last, None)
    for path, value in (changes or {}).items():
        *head, last = path.split(".")
        table = spec
        for key in head:
            table = table.setdefault(key, {})
        table[last] = value
    return mechanisms.build(spec, source=f"{BASE_SCENE} with {changes or {}}")


def _steady(mechanism: Any, speed: float | None = None, n_steps: int = 128, *, budget: bool = True):
    problem = MechanismProblem.from_mechanism(mechanism, observables=[OBSERVABLE])
    return steady_state(problem, None if speed is None else {"speed": speed}, n_steps=n_steps, budget=budget)


def _ptp(result: Any) -> float:
    return float(np.ptp(result.response[OBSERVABLE]))


def _error(result: Any) -> float:
    return float(result.response_error[OBSERVABLE])


# ---------------------------------------------------------------------------------------------------
# the cases: each returns (status, message, numbers, reference, expected, passed)
# ---------------------------------------------------------------------------------------------------
def stiff_axial():
    """The axial mode 1e4 times the crank frequency: the step does not resolve it, and must not need
    to (it follows quasi-statically); reference: the same link axially rigid."""
    from .._numerics import frozen_modes

    base = _scene()
    linear = MechanismProblem.from_mechanism(base).linearize(None, n_steps=64)
    axial = float(np.abs(frozen_modes(linear.system, 8)[1]).max())
    speed = axial / 1e4
    stiff = _steady(base, speed, n_steps=64)
    rigid = _steady(_scene({"links.coupler.axial": False}), speed, n_steps=64)
    gap = abs(_ptp(stiff) - _ptp(rigid))
    allowed = _error(stiff) + _error(rigid) + 0.02 * _ptp(rigid)
    return (stiff.status, stiff.message,
            f"axial mode {axial:.4g} rad/s, crank {speed:.4g} rad/s; peak to peak {_ptp(stiff):.4g} m",
            f"axially rigid coupler: {_ptp(rigid):.4g} m (difference {gap:.2g} m, allowed {allowed:.2g})",
            "ok or unresolved_stiff_mode, and the axially rigid result",
            stiff.status in ("ok", "unresolved_stiff_mode") and gap <= allowed)


def many_elements():
    """64 Hermite elements on the coupler (bending only, 128 coordinates: the axial ones would only add
    unresolved stiff modes); reference: the Ritz discretisation, bending only too.

    The 64-element steady state carries its time step's error only (``budget=False``): its mesh
    term would solve the coupler again on 128 elements (256 coordinates: 9 of the 11 s CPU of this
    case, two thirds of the whole check). Its error bar is then the smaller one (2.8e-5 m against
    7.1e-5 m with the mesh term), so the comparison is the stricter; the Ritz reference keeps its
    whole budget (its mesh term is the error of two modes, the one that counts here)."""
    bending = {"links.coupler.axial": False}
    fine = _steady(_scene({"links.coupler.discretisation": {"type": "fem", "n_elements": 64}, **bending}),
                   60.0, n_steps=128, budget=False)
    ritz = _steady(_scene(bending), 60.0, n_steps=128)
    gap = abs(_ptp(fine) - _ptp(ritz))
    allowed = _error(fine) + _error(ritz) + 0.01 * _ptp(ritz)
    return (fine.status, fine.message,
            f"{len(fine.labels)} independent coordinates; peak to peak {_ptp(fine):.5g} m at 60 rad/s "
            f"(+- {_error(fine):.2g} m, the time step's error)",
            f"Ritz, 2 bending modes: {_ptp(ritz):.5g} m (difference {gap:.2g}, allowed {allowed:.2g})",
            "ok, unresolved_stiff_mode or inaccurate (the stiff modes spoil the N/4 level), or the unstiffened "
            "coupler's model form, and the Ritz result",
            (fine.status in ("ok", "unresolved_stiff_mode", "inaccurate")
             or (fine.status == "outside_linear_range" and "model form" in fine.message)) and gap <= allowed)


def zero_damping():
    """No damping: multipliers on the unit circle (Liouville: det Phi = 1); the verdict is marginal,
    neither stable with margin nor unstable."""
    result = _steady(_scene({"links.coupler.damping.ratio": 0.0}), 30.0, n_steps=256)
    log_det = float(np.sum(np.log(np.abs(result.multipliers))))
    return (result.status, result.message,
            f"spectral radius {result.spectral_radius:.8f} +- {result.spectral_radius_error:.2g}",
            f"Liouville (no damping): |det Phi| = 1, so no multiplier inside the circle without "
            f"another outside; computed log|det Phi| = {log_det:.2g}",
            "marginal, and |log det Phi| < 1e-4 (Liouville)",
            result.status == "marginal" and abs(log_det) < 1e-4)


def exact_resonance():
    """An undamped oscillator forced at its natural frequency has no periodic response (it grows as
    t sin t): said so, not a number."""
    problem = mathieu_problem(speed=1.0, natural_frequency=1.0, damping_ratio=0.0, epsilon=0.0)
    try:
        result = steady_state(problem, n_steps=64)
    except periodic.ShootingError as error:  # refusing is also right: there is nothing to compute
        return ("failed", f"{type(error).__name__}: {error}", "no result",
                "closed form: x = t sin(t) / 2 grows without bound; no periodic solution",
                "near_resonance or failed", "resonance" in str(error))
    # the discrete multipliers sit on the unit circle a phase error away from +1: the tool must say
    # resonance, and must not trust the "periodic" solution it finds (near_resonance, inaccurate)
    return (result.status, result.message, f"spectral radius {result.spectral_radius:.8f}",
            "closed form: x = t sin(t) / 2 grows without bound; no periodic solution",
            "near_resonance or failed, saying there is no periodic solution",
            result.status in ("near_resonance", "failed") and "no periodic solution" in result.message)


def parametric_instability():
    """Past the first parametric instability (185 rad/s, period doubling of the first bending mode);
    reference: the full nonlinear model started on the linear solution does not settle."""
    problem = MechanismProblem.from_mechanism(_scene(), observables=[OBSERVABLE])
    check = nonlinear_check(problem, {"speed": 185.0}, n_steps=128, n_periods=5)
    linear = steady_state(problem, {"speed": 185.0}, n_steps=128)
    return (linear.status, linear.message,
            f"spectral radius {linear.spectral_radius:.5f} +- {linear.spectral_radius_error:.2g}, "
            f"{linear.instability_kind or 'no kind'}",
            f"full nonlinear model: {check.verdict} (periodicity defect "
            f"{check.periodicity_defect[OBSERVABLE] / np.ptp(check.linear[OBSERVABLE]):.2g} of the peak to peak)",
            "unstable (period doubling); nonlinear not_periodic",
            linear.status == "unstable" and linear.instability_kind == "period_doubling"
            and check.verdict == "not_periodic")


def euler_load():
    """The thesis's model without geometric stiffening at 200 rad/s: the coupler's inertial compression
    reaches its Euler load, which that model cannot see; it must say so."""
    import mechanisms

    mechanism = mechanisms.load("four_bar_thesis")
    result = _steady(mechanism, 200.0, n_steps=128)
    coupler = mechanism.link("coupler")
    euler = math.pi ** 2 * coupler.youngs_modulus * coupler.second_moment / coupler.length ** 2
    ratio = result.linear_range.get("coupler.peak_compression_over_euler", float("nan"))
    return (result.status, result.message,
            f"peak compression / Euler load {ratio:.3g} (tool's Euler load {coupler.euler_load:.4g} N); "
            f"spectral radius {result.spectral_radius:.4f}",
            f"Euler load pi^2 E I / L^2 = {euler:.4g} N (closed form); the stiffened model "
            f"({BASE_SCENE}) is unstable beyond 183 rad/s",
            "outside_linear_range, compression above half the closed-form Euler load, saying the model "
            "cannot see buckling",
            result.status == "outside_linear_range" and ratio > 0.5 and "cannot see buckling" in result.message
            and math.isclose(coupler.euler_load, euler, rel_tol=1e-12))


def near_toggle():
    """A rocker of 78 mm: s + l is 1.8 mm short of p + q, the transmission angle comes near 180 deg
    and the rocker's accelerations explode; the tool must not call the result ok."""
    length = 0.078
    mechanism = _scene({"links.rocker.length": length})
    result = _steady(mechanism, None, n_steps=128)
    crank, coupler, ground = 0.0508, 0.2794, 0.254
    # transmission angle at crank angles 0 and pi (law of cosines; thesis Fig. 2.5 geometry)
    angles = [math.degrees(math.acos((coupler ** 2 + length ** 2 - d ** 2) / (2 * coupler * length)))
              for d in (ground - crank, ground + crank)]
    return (result.status, result.message, f"peak to peak {_ptp(result):.3g} m on a 0.2794 m coupler",
            f"closed form: transmission angle from {min(angles):.1f} to {max(angles):.1f} deg "
            f"(0 or 180 deg is a toggle)", "not ok (outside_linear_range or inaccurate)", result.status != "ok")


def quasi_static():
    """At 2 and 4 rad/s the inertial loads are quasi-static: the response scales as speed^2."""
    slow, faster = _steady(_scene(), 2.0, n_steps=128), _steady(_scene(), 4.0, n_steps=128)
    ratio = _ptp(faster) / _ptp(slow)
    return (slow.status, slow.message, f"peak to peak {_ptp(slow):.4g} m at 2 rad/s, {_ptp(faster):.4g} m at 4",
            f"quasi-static scaling: ratio 4 (computed {ratio:.4f})",
            "ok or unresolved_stiff_mode (no mode resolved: the radius is the scheme's), ratio 4 within 1 %",
            {slow.status, faster.status} <= {"ok", "unresolved_stiff_mode"} and abs(ratio - 4.0) <= 0.04)


def units():
    """The same mechanism in metres and in millimetres (mm, kg, s: density x 1e-9, E x 1e-3): the same
    verdict, deflections 1000 times larger, the same multipliers."""
    import mechanisms

    spec = copy.deepcopy(mechanisms.load(BASE_SCENE).spec)
    spec.pop("studies", None)
    for link in spec["links"].values():
        for key in ("length", "width", "thickness"):
            if key in link:
                link[key] *= 1e3
        if "density" in link:
            link["density"] *= 1e-9
        if "youngs_modulus" in link:
            link["youngs_modulus"] *= 1e-3
    for joint in spec["joints"].values():
        for key in ("point_a", "point_b"):
            if isinstance(joint.get(key), list):
                joint[key] = [1e3 * v for v in joint[key]]
    millimetres = _steady(mechanisms.build(spec, source="four_bar_ritz in mm"), None, n_steps=256)
    metres = _steady(_scene(), None, n_steps=256)
    ratio = _ptp(millimetres) / _ptp(metres)
    radius_gap = abs(millimetres.spectral_radius - metres.spectral_radius)
    return (millimetres.status, millimetres.message,
            f"mm: peak to peak {_ptp(millimetres):.6g} mm, spectral radius {millimetres.spectral_radius:.8f}",
            f"m: {_ptp(metres):.6g} m ({metres.status}), ratio {ratio:.6f}, radius difference {radius_gap:.1g}",
            "ok in both, ratio 1000 within 1e-6, same radius",
            millimetres.status == metres.status == "ok" and abs(ratio / 1000.0 - 1.0) <= 1e-6 and radius_gap <= 1e-9)


CASES: dict[str, Callable[[], tuple]] = {
    "stiff axial mode (1e4 x crank)": stiff_axial,
    "64 elements": many_elements,
    "zero damping": zero_damping,
    "exact resonance": exact_resonance,
    "past the first parametric instability": parametric_instability,
    "inertial compression near the Euler load": euler_load,
    "near-toggle geometry": near_toggle,
    "quasi-static speed": quasi_static,
    "metres and millimetres": units,
}


def run_check(names: list[str] | None = None) -> list[CaseOutcome]:
    """Run the cases (all, or those named) and return their outcomes; a case that raises is a row
    with the status ``failed`` and does not stop the others."""
    outcomes = []
    for name in names or list(CASES):
        start = time.perf_counter()
        try:
            with warnings.catch_warnings():  # what they say is in the status and message
                warnings.simplefilter("ignore")
                status, message, numbers, reference, expected, passed = CASES[name]()
        except Exception as error:  # the check reports every case, whatever one of them does
            status, message, numbers, reference, expected, passed = (
                "failed", f"{type(error).__name__}: {error}", "", CASES[name].__doc__.split(";")[-1].strip(),
                "see the case", False)
        outcomes.append(CaseOutcome(name, status, message, numbers, reference, expected, bool(passed),
                                    time.perf_counter() - start))
    return outcomes


def table(outcomes: list[CaseOutcome], *, width: int = 140) -> str:
    """The outcomes as a Markdown table (as in the README's Robustness section)."""
    def cell(text: str) -> str:
        text = " ".join(str(text).split()).replace("|", "/")
        return text if len(text) <= width else text[:width - 3] + "..."

    rows = ["| case | expected | status | message | numbers | reference | verdict |",
            "| --- | --- | --- | --- | --- | --- | --- |"]
    for o in outcomes:
        rows.append(f"| {o.case} | {cell(o.expected)} | {o.status} | {cell(o.message) or '-'} | "
                    f"{cell(o.numbers)} | {cell(o.reference)} | "
                    f"{'as expected' if o.passed else 'NOT AS EXPECTED'} ({o.run_time:.2g} s) |")
    return "\n".join(rows)
