"""The run-up's steady-state curve (``studies.run_up``): the linear steady states at speeds of the
ramp's range, their stability and, on request, the nonlinear periodic states; the resonances where a
harmonic of the speed meets a mean frozen natural frequency; the time step those frequencies bound."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .._numerics import frozen_modes, solve_steady
from .._toolkit import SPEED, is_numerical_failure
from ._nonlinear_model import choose_model


def steady_curve(problem, values, speeds, specs, n_steps, nonlinear):
    """(ptp, error, status, nonlinear ptp, stable: 1, 0 or NaN) of the steady states at ``speeds``."""
    from .nonlinear_steady_state import nonlinear_steady_state

    ptp = {spec: np.full(speeds.size, np.nan) for spec in specs}
    error = {spec: np.full(speeds.size, np.nan) for spec in specs}
    nl = {spec: np.full(speeds.size, np.nan) for spec in specs}
    status = np.full(speeds.size, "failed", dtype=object)
    stable = np.full(speeds.size, np.nan)
    for i, speed in enumerate(speeds):
        point = dict(values, **{SPEED: float(speed)})
        try:
            steady = solve_steady(problem.linearize(point, n_steps=n_steps, context=False))
        except Exception as failure:
            if not is_numerical_failure(failure):
                raise
            continue
        status[i] = steady.status
        stable[i] = 1.0 if steady.is_stable else 0.0
        for k, spec in enumerate(specs):
            ptp[spec][i] = float(np.ptp(steady.response[:, k]))
            error[spec][i] = 2.0 * float(steady.response_error[k])
        if nonlinear:   # on the run's (full) model, as the start: the curve is the run's steady limit
            orbit = nonlinear_steady_state(problem, point, n_steps=n_steps, modes="full")
            if orbit.status != "failed":
                for spec in specs:
                    nl[spec][i] = orbit.peak_to_peak[spec]
    return ptp, error, status.astype(str), nl, stable


def resonances(problem, values, low, high, n_modes, max_harmonic, n_speeds=17):
    """(speeds, harmonics k, modes j) (n_res,) where ``k speed`` meets the mean frozen natural
    frequency of mode j, which changes with the speed (centrifugal and geometric stiffening): found
    between ``n_speeds`` coarse linearisations over [low, high] by linear interpolation."""
    speeds = np.linspace(max(low, 0.02 * high), high, n_speeds)
    table = np.full((n_speeds, n_modes), np.nan)
    for i, speed in enumerate(speeds):
        linear = problem.linearize(dict(values, **{SPEED: float(speed)}), n_steps=32, context=False)
        mean = np.mean(frozen_modes(linear.system, 16)[1], axis=0)
        mean = np.sort(mean[mean > 0.0])[:n_modes]
        table[i, :mean.size] = mean
    found = []
    for j in range(n_modes):
        for k in range(1, max_harmonic + 1):
            gap = table[:, j] - k * speeds
            for i in np.flatnonzero(np.sign(gap[:-1]) * np.sign(gap[1:]) < 0):
                u = gap[i] / (gap[i] - gap[i + 1])
                found.append((float(speeds[i] + u * (speeds[i + 1] - speeds[i])), k, j))
    found.sort()
    return (np.array([f[0] for f in found], dtype=float), np.array([f[1] for f in found], dtype=int),
            np.array([f[2] for f in found], dtype=int))


@dataclass(frozen=True)
class Reduction:
    """The reduced model a run-up integrates: ``modes`` {link: modes}, ``relative`` the stated
    reduction error (twice the largest ratio of the reduction check's difference to a peak to peak
    over the speeds checked), ``words`` what was checked where."""

    modes: dict
    relative: float
    words: str


def reduced_model(problem, values, speeds, modes):
    """(problem, values, ``Reduction`` or None) of a run-up on the reduced model ``modes`` asks for
    (``nonlinear_steady_state``'s choice at ``speeds[0]``, the start), its reduction check repeated at
    the other ``speeds`` (rad/s: the ramp's other end, its resonances) with the same modes: the check
    is one of linear steady states, so a ramp through resonances is checked where they are."""
    speeds = [float(speed) for speed in speeds if speed > 0.0]
    choice = choose_model(problem, dict(values, **{SPEED: speeds[0]}), modes)
    if not choice.modes:
        return problem, values, None
    count = max(choice.modes.values())
    relative, worst = choice.relative, speeds[0]
    for speed in dict.fromkeys(speeds[1:]):
        again = choose_model(problem, dict(values, **{SPEED: speed}), count)
        if again.relative > relative:
            relative, worst = again.relative, speed
    links = ", ".join(f"{name} {n} modes" for name, n in choice.modes.items())
    words = (f"on the reduced model ({links} with their static corrections; the start too, the curve on "
             f"the full models): its reduction check at {len(dict.fromkeys(speeds))} speeds (the ramp's ends "
             f"and resonances) stated as {relative:.3g} of each peak to peak (twice the largest, at "
             f"{worst:.4g} rad/s) in reduction_error")
    return choice.problem, {}, Reduction(dict(choice.modes), float(relative), words)


def time_step(problem, values, start, stop, n_steps, mode_steps, max_harmonic):
    """(dt, reason, natural frequencies (n_modes,) rad/s at ``start`` of the modes that matter): the
    largest step that takes ``n_steps`` per revolution at the fastest speed and ``mode_steps`` per
    period of the highest natural frequency that matters (every mode up to ``max_harmonic`` times the
    fastest speed, and the lowest one always) at both ends of the ramp (the frequencies move with
    the speed; a run-down to 0 at 2 % of ``start``, near the standstill's), so that slow speeds stay
    as resolved as fast ones."""
    top = max(start, stop)
    highest, at, count, relevant_at_start = 0.0, start, 0, None
    for speed in (start, max(stop, 0.02 * top)):
        linear = problem.linearize(dict(values, **{SPEED: speed}), n_steps=32, context=False)
        _, frequencies, _ = frozen_modes(linear.system, 16)
        mean = np.mean(frequencies, axis=0)
        mean = np.sort(mean[mean > 0.0])
        relevant = mean[: max(1, int(np.searchsorted(mean, max_harmonic * top, side="right")))]
        if relevant_at_start is None:
            relevant_at_start = relevant
        if relevant.size and relevant[-1] > highest:
            highest, at, count = float(relevant[-1]), speed, relevant.size
    by_revolution = 2.0 * math.pi / top / n_steps
    by_mode = 2.0 * math.pi / highest / mode_steps if highest > 0.0 else math.inf
    if by_mode < by_revolution:
        reason = (f"{mode_steps} steps per period of mode {count} ({highest:.4g} rad/s at "
                  f"{at:.4g} rad/s), the highest up to {max_harmonic} x the fastest speed")
        return by_mode, reason, relevant_at_start
    return by_revolution, f"{n_steps} steps per revolution at the fastest speed {top:.4g} rad/s", relevant_at_start
