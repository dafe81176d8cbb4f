"""The revolutions of a run-up (``studies.run_up``): the phase a run turned, each whole revolution's
ends and mean speed, each observable's peak-to-peak and peak over it, and the observables as the
linear route reports them (changes from the rigid motion at the same crank angle)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._mechanism import deviation_from_nominal


class Phase:
    """The revolutions of a run: ``phase`` (n_t,) rad the motion's angle turned since t = 0 (the first
    drive's relative angle over its turns per revolution), ``speed`` (n_t,) rad/s its rate."""

    def __init__(self, model, drive, start, run):
        gradient = model.drive_gradient(drive.joint)
        turns = drive.rate / start            # drive radians per radian of the motion's phase
        self.phase = (run.s @ gradient - float(run.s[0] @ gradient)) / turns
        self.speed = (run.sdot @ gradient) / turns
        self.t = run.t

    def reversal(self) -> int:
        """The index of the last sample before the phase first turns back (a crank that stopped and
        swings back: a coast under gravity, a braked crank's overshoot), the last sample without one."""
        scale = max(1.0, float(np.abs(self.phase).max()))
        back = np.flatnonzero(np.diff(self.phase) < -1e-12 * scale)
        return int(back[0]) if back.size else self.phase.size - 1

    def revolutions(self):
        """(times (n_rev + 1,) s where each whole revolution begins and the last ends, their mean
        speeds (n_rev,) rad/s): the whole revolutions turned before the phase first turns back."""
        end = self.reversal() + 1
        phase, speed, t = self.phase[:end], self.speed[:end], self.t[:end]
        n_rev = int(np.floor(phase[-1] / (2.0 * math.pi) + 1e-12)) if phase.size > 1 else 0
        if n_rev < 1:
            return np.zeros(1), np.zeros(0)
        marks = 2.0 * math.pi * np.arange(n_rev + 1)
        # the crossing inside its step from the phase's second-order expansion there (its rate at both
        # ends known): exact for a speed linear over the step, where linear interpolation is O(h^2)
        i = np.clip(np.searchsorted(phase, marks, side="right") - 1, 0, phase.size - 2)
        h = t[i + 1] - t[i]
        w0, acc = speed[i], (speed[i + 1] - speed[i]) / h
        rest = marks - phase[i]
        tau = np.where(np.abs(acc) * h > 1e-12 * np.abs(w0),
                       2.0 * rest / (w0 + np.sqrt(np.maximum(w0 * w0 + 2.0 * acc * rest, 0.0))),
                       rest / np.where(w0 != 0.0, w0, 1.0))
        times = t[i] + tau
        return times, 2.0 * math.pi / np.diff(times)


def _refined(values: np.ndarray, i: np.ndarray, sign: float) -> np.ndarray:
    """The extreme at samples ``i`` refined by the parabola through it and its two neighbours."""
    inner = (i > 0) & (i < values.size - 1)
    out = values[i].astype(float)
    j = i[inner]
    left, centre, right = values[j - 1], values[j], values[j + 1]
    curvature = left - 2.0 * centre + right
    # a sampled extreme of the whole series (not one cut off at a revolution's end): its vertex lies
    # within half a step
    ok = (sign * (centre - left) >= 0.0) & (sign * (centre - right) >= 0.0) & (sign * curvature < 0.0)
    shift = np.where(ok, 0.5 * (left - right) / np.where(ok, curvature, 1.0), 0.0)
    out[inner] = centre - 0.25 * (left - right) * shift
    return out


def _at(values: np.ndarray, t: np.ndarray, times: np.ndarray) -> np.ndarray:
    """``values`` (n_t,) on the uniform grid ``t`` at ``times`` by the parabola through the three
    nearest samples (error O(h^3), where linear interpolation's O(h^2) would show in a peak-to-peak
    whose extreme is a revolution's end)."""
    h = t[1] - t[0]
    j = np.clip(np.rint((times - t[0]) / h).astype(int), 1, t.size - 2)
    u = (times - t[j]) / h
    left, centre, right = values[j - 1], values[j], values[j + 1]
    return centre + 0.5 * u * (right - left) + 0.5 * u * u * (right - 2.0 * centre + left)


def per_revolution(values: np.ndarray, t: np.ndarray, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(peak-to-peak, peak) (n_rev,) of ``values`` (n_t,) on the uniform grid ``t`` over each
    revolution ``times[k] .. times[k + 1]`` (s): its extremes inside refined by the parabola through
    their neighbours, and its values at both ends."""
    n_rev = times.size - 1
    if n_rev < 1:
        return np.zeros(0), np.zeros(0)
    ends = _at(values, t, times)
    first = np.searchsorted(t, times, side="right")        # the first sample after each end
    high_at, low_at = np.zeros(n_rev, dtype=int), np.zeros(n_rev, dtype=int)
    for k in range(n_rev):
        lo, hi = first[k], max(first[k] + 1, int(np.searchsorted(t, times[k + 1], side="left")))
        part = values[lo:hi]
        high_at[k] = lo + int(np.argmax(part))
        low_at[k] = lo + int(np.argmin(part))
    high = np.maximum(_refined(values, high_at, 1.0), np.maximum(ends[:-1], ends[1:]))
    low = np.minimum(_refined(values, low_at, -1.0), np.minimum(ends[:-1], ends[1:]))
    return high - low, np.maximum(np.abs(high), np.abs(low))


def observed(model, linear, specs, run, phase):
    """{spec: (n_t,)} along ``run``: each observable's change from its value on the rigid motion at
    the run's crank angle (the nominal motion at ``start``, periodic in the phase, by a periodic
    cubic spline through its samples)."""
    from scipy.interpolate import CubicSpline

    nominal = linear.context.nominal
    period_phase = 2.0 * math.pi * np.arange(nominal.s.shape[0]) / (nominal.s.shape[0] - 1)
    out = {}
    for spec in specs:
        observable = model.observable(spec)
        on_nominal = np.array([observable.value(sk) for sk in nominal.s])
        if np.ptp(on_nominal) == 0.0:
            reference = np.full(phase.size, on_nominal[0])
        else:
            if observable.unit == "rad":   # a turning link's angle: its change over the period removed
                drift = on_nominal[-1] - on_nominal[0]
                on_nominal = on_nominal - drift * period_phase / (2.0 * math.pi)
            else:
                drift = 0.0
            on_nominal[-1] = on_nominal[0]
            spline = CubicSpline(period_phase, on_nominal, bc_type="periodic")
            reference = spline(np.mod(phase, 2.0 * math.pi)) + drift * phase / (2.0 * math.pi)
        out[spec] = deviation_from_nominal(run.observables[spec], reference, observable.unit)
    return out


@dataclass(frozen=True)
class Analysis:
    """One run of a run-up and its revolutions: ``run`` (``mechanisms.simulate``'s result),
    ``phase`` (``Phase``), ``response`` {spec: (n_t,)}, ``times`` (n_rev + 1,) s the whole
    revolutions' ends, ``speed`` (n_rev,) rad/s their mean speeds, ``peak_to_peak`` and ``peak``
    {spec: (n_rev,)}; ``tail_peak_to_peak`` {spec: float} over what follows the last whole revolution
    (a crank slowing to a stop or swinging back: no whole revolution), ``tail_start`` (s) its start."""

    run: Any
    phase: Phase
    response: dict
    times: np.ndarray
    speed: np.ndarray
    peak_to_peak: dict
    peak: dict
    tail_peak_to_peak: dict
    tail_start: float


def analysed(model, linear, drive, start, specs, dt, options) -> Analysis:
    """One run of the ramped ``model`` on the step ``dt`` and its analysis (``Analysis``)."""
    import mechanisms

    run = mechanisms.simulate(model, dt=dt, **options)
    phase = Phase(model, drive, start, run)
    response = observed(model, linear, specs, run, phase.phase)
    times, speed = phase.revolutions()
    tail_start = float(times[-1]) if speed.size else float(run.t[0])
    ptp, peak, tail = {}, {}, {}
    for spec in specs:
        ptp[spec], peak[spec] = per_revolution(response[spec], run.t, times)
        rest = response[spec][run.t >= tail_start]
        tail[spec] = float(np.ptp(rest)) if rest.size > 1 else 0.0
    return Analysis(run, phase, response, times, speed, ptp, peak, tail, tail_start)


def torques(model, run, joint=None) -> np.ndarray:
    """The first drive's torque (n_t,) N m along ``run``: a prescribed drive's at ``joint`` is minus
    its multiplier (its constraint row ``drive:<joint>``, ``mechanisms.ConstrainedModel``), read off
    the run's at once; otherwise each sample's ``drive_torques`` (the law as applied, the lags' states)."""
    label = f"drive:{joint}"
    lagged = run.lag_states is not None and run.lag_states.size and joint in getattr(model, "lag_joints", ())
    if joint is not None and label in model.constraint_labels and not lagged:
        return -np.asarray(run.lam, dtype=float)[:, list(model.constraint_labels).index(label)]
    lags = run.lag_states if run.lag_states is not None and run.lag_states.size else [None] * len(run.t)
    return np.array([model.drive_torques(sk, vk, tk, lk, lag_states=yk)[0]
                     for sk, vk, tk, lk, yk in zip(run.s, run.sdot, run.t, run.lam, lags)])
