"""``linearize.about``: a mechanism linearised about its nominal rigid motion, as a periodic system,
and ``linearize.speed_family``: the same with its coefficients as polynomials in the speed."""

from __future__ import annotations

import dataclasses
import functools
import logging
import math
import time
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

import mechanisms
import periodic

from ._core import (
    WARN_CONDITION,
    LinearCoefficients,
    LinearizationError,
    choose_independent,
    interpolate_periodic,
    linear_coefficients,
    spectral_tail,
)
from ._geometric import axial_forces, geometric_stiffness
from ._observe import ObservableMap, evaluate_maps, needs_multiplier_maps, observable_maps
from ._range import LinearRange, drive_probes, linear_range, link_probes, sample_abscissae

logger = logging.getLogger(__name__)

__all__ = ["LinearizedMechanism", "SpeedFamily", "about", "speed_family", "supports_speed_family",
           "default_observables", "ObservableMap"]


@dataclass(frozen=True)
class LinearizedMechanism:
    """A mechanism's elastic vibration about its nominal motion, ``M z'' + C z' + K z = f``.

    ``system``: the ``periodic.PeriodicSystem`` in the independent coordinates ``z`` (m,), labelled
    by ``labels``; ``nominal``: the ``mechanisms.NominalMotion`` it is linearised about (same grid);
    ``crank_angle`` (N+1,) rad: the first drive's angle on the grid; ``observables``: the specs that
    ``observe`` reports, ``observable_maps`` {spec: ``ObservableMap``} how each follows from ``z``
    (``linearize._observe``: deviations, or totals for forces, torques and stresses);
    ``coefficients``: the ``LinearCoefficients`` with the basis ``V`` (N+1, n, m)
    and the conditioning diagnostics; ``run_time`` (s) of the linearisation; ``range_probes``: what
    ``linear_range`` needs per elastic link (shape rows, the nominal axial force), computed on first
    use by ``range_source`` (a linearisation that is never asked for its linear range does not pay
    for the axial forces).
    """

    mechanism: Any
    nominal: Any
    system: periodic.PeriodicSystem
    labels: tuple[str, ...]
    crank_angle: np.ndarray
    observables: tuple[str, ...]
    observable_maps: dict
    coefficients: LinearCoefficients
    run_time: float
    range_source: Callable[[], tuple] | None = dataclasses.field(default=None, repr=False, compare=False)

    @functools.cached_property
    def range_probes(self) -> tuple:
        return () if self.range_source is None else self.range_source()

    def _history(self, z) -> np.ndarray:
        z = np.asarray(z, dtype=float)
        if z.shape != self.system.f.shape:
            raise LinearizationError(f"z must have shape {self.system.f.shape} (samples, independent "
                             f"coordinates); received shape {z.shape}")
        return z

    def observe(self, z: np.ndarray, zdot: np.ndarray | None = None,
                zddot: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """Each observable (N+1,) along the independent-coordinate history ``z`` (N+1, m): the
        deviation from its nominal value, or for forces, torques and stresses the total
        (``linearize._observe``). Joint forces and torques need ``zdot``, ``zddot`` (N+1, m); when
        not given they are the spectral derivatives of ``z`` as a periodic history (a steady
        state)."""
        z = self._history(z)
        return evaluate_maps(self.observable_maps, z, self.system.period, zdot=zdot, zddot=zddot)

    def linear_range(self, z: np.ndarray) -> LinearRange:
        """The linear-range measures (``linearize.LinearRange``) of the periodic solution ``z``
        (N+1, m) of ``system``: per elastic link, peak deflection over length and over section
        height, peak slope, peak nominal compression over the Euler load, peak bending stress over
        the yield strength; status ``"outside_linear_range"`` where one passes its
        ``LINEAR_RANGE_LIMITS`` entry."""
        return linear_range(self.range_probes, self._history(z))

    def full_state(self, z: np.ndarray, zdot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Full coordinates and rates (N+1, n): nominal motion plus ``x = V z``,
        ``x' = V z' + V' z``."""
        c = self.coefficients
        s = self.nominal.s + np.einsum("kni,ki->kn", c.V, z)
        sdot = self.nominal.sdot + np.einsum("kni,ki->kn", c.V, zdot) + np.einsum(
            "kni,ki->kn", c.Vdot, z)
        return s, sdot

    def start_state(self, z0: np.ndarray, zdot0: np.ndarray, *, sample: int = 0
                    ) -> tuple[np.ndarray, np.ndarray]:
        """A state (s, s') (n,) that satisfies the nonlinear constraints exactly, with the
        independent coordinates of ``z0, zdot0`` (m,) at grid sample ``sample``: to start a full
        nonlinear run from the linear solution.

        ``full_state`` is correct to first order only. Here, on top of it, (1) each link with
        geometric stiffening gets the second-order axial shortening that keeps its projected
        membrane strain what the linear state says (``u' = -P[w'^2/2]``: a bent link shortens its
        chord; without it the nonlinear model would read the bending as a large stretch), and (2) the
        dependent coordinates are solved from the position and velocity constraints by Newton with
        the independent ones held.
        """
        z0 = np.asarray(z0, dtype=float)
        zdot0 = np.asarray(zdot0, dtype=float)
        m = len(self.labels)
        if z0.shape != (m,) or zdot0.shape != (m,):
            raise LinearizationError(f"z0 and zdot0 must have shape ({m},) (independent coordinates "
                             f"{self.labels}); received {z0.shape} and {zdot0.shape}")
        c = self.coefficients
        model = self.nominal.model
        if getattr(model, "mechanism", None) != self.mechanism:
            # A speed family's member keeps the base speed's model, and a torque-driven mechanism's
            # nominal model has its drive prescribed: the constraints are this mechanism's.
            model = mechanisms.assemble(self.mechanism)
        t = float(self.nominal.t[sample])
        s = self.nominal.s[sample] + c.V[sample] @ z0
        sdot = self.nominal.sdot[sample] + c.V[sample] @ zdot0 + c.Vdot[sample] @ z0
        for layout in model.layouts.values():
            if layout.shapes is None or not layout.stiffening or layout.membrane is None:
                continue
            slopes = layout.shapes.evaluate(layout.shapes.quadrature[0]).dw  # (n_gauss, n_e)
            q, qdot = s[layout.elastic], sdot[layout.elastic]
            s[layout.elastic] = q - layout.membrane @ (0.5 * (slopes @ q) ** 2)
            sdot[layout.elastic] = qdot - layout.membrane @ ((slopes @ q) * (slopes @ qdot))
        dependent = np.setdiff1d(np.arange(model.n_coords), c.independent)
        for _ in range(20):
            phi = model.constraints(s, t)
            if np.abs(phi).max() < 1e-13:
                break
            s[dependent] -= np.linalg.solve(model.constraint_jacobian(s, t)[:, dependent], phi)
        else:
            raise mechanisms.ConvergenceError(
                f"no consistent state near the linear one at sample {sample}: Newton on the "
                f"dependent coordinates left a constraint residual {np.abs(phi).max():.3g}; the "
                f"deviation z0 is probably too large for the linkage")
        jac = model.constraint_jacobian(s, t)
        rhs = -model.constraint_rate(s, t) - jac[:, c.independent] @ sdot[c.independent]
        sdot[dependent] = np.linalg.solve(jac[:, dependent], rhs)
        return s, sdot


def default_observables(mechanism) -> tuple[str, ...]:
    """The observables ``about`` reports when none are asked for: ``mechanisms.default_observables``
    (midspan deflection of each pinned-pinned elastic link, tip deflection of each clamped-free
    one), the rule ``mechanisms.simulate`` uses too."""
    return mechanisms.default_observables(mechanism)


def _independent_coordinates(model, nominal) -> np.ndarray:
    """Elastic coordinates, plus the coordinates that the constraints leave free (the driven
    angle of each torque drive, chosen by pivoting on the rigid Jacobian)."""
    return choose_independent(model.constraint_jacobian(nominal.s[0], nominal.t[0]),
                              np.asarray(model.elastic_index, dtype=np.int64))


def _has_stiffening(model) -> bool:
    return any(lay.shapes is not None and lay.stiffening for lay in model.layouts.values())


# Coefficients of a smooth mechanism are smooth periodic functions of time: evaluating the model at
# every sample of a fine Newmark grid is wasted work. ``about`` evaluates them at every stride-th
# sample (at least COARSEST samples per period) and interpolates spectrally, refining until the
# highest resolved harmonics are below INTERPOLATION_TOL of the largest (so the interpolation error
# is at round-off level); near toggle positions the spectra decay slowly and it falls back to every
# sample.
COARSEST = 64
INTERPOLATION_TOL = 1e-12


def _coarsest_stride(n_steps: int) -> int:
    """The largest power of two dividing ``n_steps`` that leaves at least ``COARSEST`` samples."""
    stride = 1
    while n_steps % (2 * stride) == 0 and n_steps // (2 * stride) >= COARSEST:
        stride *= 2
    return stride


def _coefficients(model, t, s, sdot, sddot, lam, *, period, independent, label, stride=1,
                  multipliers=False):
    """``LinearCoefficients`` on the grid of ``t`` (N+1,), the model evaluated at every ``stride``-th
    sample (N divisible by ``stride``) and the results interpolated to the others."""
    pick = slice(None, None, stride)
    t_c, s_c, sdot_c, sddot_c, lam_c = t[pick], s[pick], sdot[pick], sddot[pick], lam[pick]
    extra = None
    if _has_stiffening(model):
        jacobian = mechanisms.constraint_terms_along(model, t_c, s_c).jacobian
        extra = geometric_stiffness(model, t_c, s_c, sdot_c, sddot_c, lam_c, jacobian=jacobian)
    coarse = linear_coefficients(model, t_c, s_c, sdot_c, sddot_c, lam_c, period=period,
                                 independent=independent, extra_stiffness=extra,
                                 time_label=lambda k: label(k * stride), multipliers=multipliers)
    if stride == 1:
        return coarse
    n_steps = len(t) - 1
    # The interpolation error that matters is that of the system's coefficients and of the basis;
    # the tails of V' and V'' are those of V weighted by k and k^2, and they reach the coefficients
    # only through M V'' and the like, which the tails of C and K already measure.
    tail = max(spectral_tail(getattr(coarse, name)) for name in ("M", "C", "K", "f", "V"))
    fine = {name: interpolate_periodic(getattr(coarse, name), n_steps) for name in "MCKf"}
    fine["multiplier_maps"] = tuple(interpolate_periodic(a, n_steps) for a in coarse.multiplier_maps)
    # V is the identity on the independent rows (and V', V'' zero there): interpolate the others.
    dependent = np.setdiff1d(np.arange(coarse.V.shape[1]), coarse.independent)
    for name in ("V", "Vdot", "Vddot"):
        values = getattr(coarse, name)
        full = np.repeat(values[:1], n_steps + 1, axis=0)
        full[:, dependent] = interpolate_periodic(values[:, dependent], n_steps)
        fine[name] = full
    return dataclasses.replace(
        coarse, t=t, stride=stride, interpolation_error=tail,
        dependent_condition=np.repeat(coarse.dependent_condition, stride)[:n_steps + 1], **fine)


def _adaptive_coefficients(model, t, s, sdot, sddot, lam, *, period, independent, label,
                           multipliers=False):
    """``_coefficients`` with the largest stride (a power of two dividing N, leaving at least
    ``COARSEST`` samples) whose coefficients the coarse samples resolve to ``INTERPOLATION_TOL``."""
    n_steps = len(t) - 1
    stride = _coarsest_stride(n_steps)
    while True:
        coeffs = _coefficients(model, t, s, sdot, sddot, lam, period=period,
                               independent=independent, label=label, stride=stride,
                               multipliers=multipliers)
        if stride == 1 or coeffs.interpolation_error < INTERPOLATION_TOL:
            return coeffs
        stride //= 2


def _crank_angle(mechanism, t, period):
    if not mechanism.drives:
        return np.zeros_like(t)
    return np.asarray(mechanisms.drive_law(mechanism.drives[0], period, np.asarray(t))[0],
                      dtype=float)


def _finish(mechanism, model, nominal, coeffs, specs, angle, started):
    if coeffs.dependent_condition.max() > WARN_CONDITION:
        k = int(np.argmax(coeffs.dependent_condition))
        logger.warning("constraint Jacobian poorly conditioned (%.3g) at crank angle %.4g rad: "
                       "close to a toggle position", coeffs.dependent_condition[k], angle[k])
    # Sample N is sample 0 one period later; they differ only by the nominal motion's closure error
    # (reported by the nominal motion), so make the coefficients exactly periodic.
    for array in (coeffs.M, coeffs.C, coeffs.K, coeffs.f):
        array[-1] = array[0]
    system = periodic.PeriodicSystem(nominal.period, coeffs.M, coeffs.C, coeffs.K, coeffs.f)
    labels = tuple(model.coord_labels[i] for i in coeffs.independent) + tuple(
        f"lag.{name}" for name in getattr(model, "lag_names", ()))  # linearize._lag
    return LinearizedMechanism(
        mechanism=mechanism, nominal=nominal, system=system, labels=labels,
        crank_angle=angle, observables=tuple(specs),
        observable_maps=_nominal_maps(model, specs, nominal, coeffs), coefficients=coeffs,
        run_time=time.perf_counter() - started,
        range_source=functools.partial(_range_probes, model, nominal, coeffs))


def _nominal_maps(model, specs, nominal, coeffs, *, sdot=None, sddot=None, lam=None):
    """``observable_maps`` along ``nominal`` (its rates, accelerations and multipliers unless
    given: a speed family passes them at other speeds)."""
    return observable_maps(
        model, specs, t=nominal.t, s=nominal.s,
        sdot=nominal.sdot if sdot is None else sdot,
        sddot=nominal.sddot if sddot is None else sddot,
        lam=_multipliers_of(model, nominal) if lam is None else lam, coefficients=coeffs,
        drive_torque=nominal.drive_torque)


def _range_probes(model, nominal, coeffs) -> tuple:
    """The ``LinearizedMechanism.range_probes`` of a linearisation about ``nominal``."""
    axial = _nominal_axial_forces(model, nominal.t, nominal.s, nominal.sdot, nominal.sddot,
                                  _multipliers_of(model, nominal), stride=coeffs.stride)
    return link_probes(model, coeffs.independent, axial) + drive_probes(
        model, nominal.t, nominal.s, nominal.sdot, coeffs, nominal.period)


def _nominal_axial_forces(model, t, s, sdot, sddot, lam, *, stride=1):
    """Axial force (N+1, n_x) of every elastic link along the rigid motion, at the abscissae of
    the linear-range measures (``linearize._range.sample_abscissae``): computed on every
    ``stride``-th sample and interpolated like the coefficients (it is a combination of the
    multipliers and accelerations that the coefficients' spectral check already resolves)."""
    abscissae = {name: sample_abscissae(layout.link) for name, layout in model.layouts.items()
                 if layout.shapes is not None}
    if not abscissae:
        return {}
    pick = slice(None, None, stride)
    coarse = axial_forces(model, t[pick], s[pick], sdot[pick], sddot[pick], lam[pick], abscissae)
    return {name: None if force is None else interpolate_periodic(force, len(t) - 1)
            for name, force in coarse.items()}


def about(mechanism, *, n_steps: int = 512, observables=None, kinematics=None) -> LinearizedMechanism:
    """Linearise ``mechanism`` about its nominal rigid motion over one period of ``n_steps`` steps.

    ``observables``: specs of ``model.observable`` (e.g. ``"coupler.deflection@0.5"``), default
    ``default_observables``. ``kinematics``: a ``mechanisms.NominalMotion`` on that grid whose
    linkage ``mechanism`` shares (it differs in what does not move it: sections, masses, damping,
    gains), reused with only the inverse dynamics recomputed (``mechanisms.nominal_dynamics``).
    Raises ``LinearizationError`` (a ``ValueError``) at a toggle position
    (naming the crank angle), the nominal motion's ``mechanisms.MechanismError`` (a ``ValueError``)
    or ``mechanisms.ConvergenceError`` (a ``RuntimeError``).
    """
    started = time.perf_counter()
    if not isinstance(mechanism, mechanisms.Mechanism):
        raise TypeError(f"mechanism must be a mechanisms.Mechanism; received "
                        f"{type(mechanism).__name__}")
    specs = default_observables(mechanism) if observables is None else tuple(observables)
    if kinematics is None:
        nominal = _nominal_motion(mechanism, n_steps)
    elif kinematics.n_steps != n_steps:
        raise LinearizationError(f"kinematics: a motion of {kinematics.n_steps} steps, but n_steps is {n_steps}")
    else:
        nominal = mechanisms.nominal_dynamics(mechanism, kinematics)
    model = _model_with_feedforward(mechanism, nominal)
    independent = _independent_coordinates(model, nominal)
    angle = _crank_angle(mechanism, nominal.t, nominal.period)
    coeffs = _adaptive_coefficients(
        model, nominal.t, nominal.s, nominal.sdot, nominal.sddot,
        _multipliers_of(model, nominal),
        period=nominal.period, independent=independent,
        label=lambda k: f"crank angle {angle[k]:.6g} rad (t = {nominal.t[k]:.6g} s)",
        multipliers=needs_multiplier_maps(model, specs))
    return _finish(mechanism, model, nominal, coeffs, specs, angle, started)


def _nominal_motion(mechanism, n_steps):
    """``mechanisms.nominal_motion`` on the grid of ``n_steps``, computed on a coarser grid (every
    stride-th sample, at least ``COARSEST`` per period) and interpolated spectrally when that is
    exact to round-off: the coarse samples must resolve the motion to ``INTERPOLATION_TOL`` and the
    interpolated motion must meet the constraints at every fine sample as the direct computation
    does (positions 1e-12, rates and accelerations to 1e-9 of their scale); otherwise, or for a
    hand-written model, the direct computation on the fine grid."""
    stride = _coarsest_stride(n_steps)
    if stride == 1:
        return mechanisms.nominal_motion(mechanism, n_steps=n_steps)
    started = time.perf_counter()
    coarse = mechanisms.nominal_motion(mechanism, n_steps=n_steps // stride)
    # Angles of links that turn fully grow by whole turns over the period: interpolate the
    # periodic remainder.
    drift = coarse.s[-1] - coarse.s[0]
    phase = coarse.t / coarse.period
    periodic_part = coarse.s - np.outer(phase, drift)
    arrays = {"sdot": coarse.sdot, "sddot": coarse.sddot, "lam": coarse.lam,
              "drive_torque": coarse.drive_torque}
    if max(spectral_tail(a) for a in [periodic_part, *arrays.values()]) > INTERPOLATION_TOL:
        return mechanisms.nominal_motion(mechanism, n_steps=n_steps)
    t = np.linspace(0.0, coarse.period, n_steps + 1)
    s = interpolate_periodic(periodic_part, n_steps) + np.outer(t / coarse.period, drift)
    fine = {name: interpolate_periodic(a, n_steps) for name, a in arrays.items()}
    terms = mechanisms.constraint_terms_along(coarse.model, t, s, fine["sdot"], values=True)
    jacobian, rate, gamma, phi = terms.jacobian, terms.rate, terms.gamma, terms.values
    velocity = np.abs(np.einsum("krn,kn->kr", jacobian, fine["sdot"]) + rate).max()
    acceleration = np.abs(np.einsum("krn,kn->kr", jacobian, fine["sddot"]) - gamma).max()
    position = np.abs(phi).max()
    scale_v = max(np.abs(rate).max(), np.abs(fine["sdot"]).max())
    scale_a = max(np.abs(gamma).max(), np.abs(fine["sddot"]).max())
    if not (position <= 1e-12 and velocity <= 1e-9 * scale_v and acceleration <= 1e-9 * scale_a):
        return mechanisms.nominal_motion(mechanism, n_steps=n_steps)
    return dataclasses.replace(
        coarse, t=t, s=s, constraint_residual=float(position), velocity_residual=float(velocity),
        acceleration_residual=float(acceleration),
        jacobian_condition=np.repeat(coarse.jacobian_condition, stride)[:n_steps + 1],
        run_time=time.perf_counter() - started, **fine)


def _multipliers_of(model, nominal):
    """The nominal multipliers (N+1, r) of ``model``'s constraints. The nominal motion prescribes
    every drive; the model with feedforward has no row for a torque drive (its torque is in Q), so
    that drive's multiplier is left out (rows matched by their labels)."""
    if model is nominal.model:
        return nominal.lam
    labels = list(nominal.model.constraint_labels)
    return nominal.lam[:, [labels.index(label) for label in model.constraint_labels]]


def _model_with_feedforward(mechanism, nominal):
    """The model whose torque drives apply the nominal inverse-dynamics torque (interpolated
    periodically on the grid), so that the nominal motion is a solution of the full equations."""
    if not mechanism.torque_drives:
        return nominal.model
    return mechanisms.assemble(mechanism,
                               feedforward=mechanisms.feedforward_torques(mechanism, nominal))


# ---------------------------------------------------------------------------------------------------
# Polynomial dependence on the speed (2 pi / period)
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SpeedFamily:
    """The linearised coefficients of a mechanism with prescribed drives as polynomials in its speed.

    The speed ``Omega`` is the motion's fundamental angular frequency ``2 pi / period`` (rad/s),
    signed like the first drive's rate (positive if it has none): for a crank turning once per
    period at constant rate, its rate. Every prescribed drive's angle is a function of the phase
    ``Omega t`` alone (its rate is a whole number of turns per period, its harmonics multiples of
    ``2 pi / period``), so with the phase as the independent variable the nominal configuration does
    not depend on ``Omega``, its rates scale with ``Omega`` and its accelerations and inertia
    multipliers with ``Omega^2``; so, exactly,

        M = M0,  C = C0 + Omega C1,  K = K0 + Omega K1 + Omega^2 K2,  f = f0 + Omega^2 f2

    on the phase grid ``Omega t_k = 2 pi k / N`` (``f0`` is the gravity load, ``C0`` the material
    damping, ``K1`` couples damping with the moving basis). Each array has the grid as its first
    axis. ``at_speed(Omega)`` returns the ``LinearizedMechanism`` at any speed of the same sign as
    the base mechanism's (every drive's rate scaled by ``Omega / rate``, the period by its inverse),
    for the cost of a few array operations. The nominal axial force of
    each elastic link is likewise ``N0 + Omega^2 N2`` (``axial0``, ``axial2``: link name ->
    (N+1, n_x) at the linear-range abscissae): ``linear_range(Omega, z)`` uses it. The maps of
    the observables that depend on the speed (forces, torques, the nominal axial stress: their
    arrays are polynomials of degree two at most in ``Omega``) are kept at ``Omega = 0`` and
    ``2 rate`` (``speed_maps``) besides the base's; ``observable_maps_at(Omega)`` interpolates.
    So are the maps of the multipliers' change (``LinearCoefficients.multiplier_maps``: ``A_a`` the
    same at every speed, ``A_v`` linear and ``A_x`` quadratic in ``Omega``), kept at ``Omega = 0``
    and ``2 rate`` (``speed_multiplier_maps``) and interpolated by ``at_speed``.
    ``rate``: the base mechanism's speed (rad/s).
    """

    mechanism: Any
    base: LinearizedMechanism
    rate: float
    M: np.ndarray
    C0: np.ndarray
    C1: np.ndarray
    K0: np.ndarray
    K1: np.ndarray
    K2: np.ndarray
    f0: np.ndarray
    f2: np.ndarray
    lam0: np.ndarray
    lam2: np.ndarray
    run_time: float
    axial0: dict = dataclasses.field(default_factory=dict, repr=False, compare=False)
    axial2: dict = dataclasses.field(default_factory=dict, repr=False, compare=False)
    speed_maps: tuple = dataclasses.field(default=(), repr=False, compare=False)
    speed_multiplier_maps: tuple = dataclasses.field(default=(), repr=False, compare=False)

    def _speed_weights(self, rate: float) -> tuple[float, float, float]:
        """Lagrange weights of the quadratic through speeds 0, ``self.rate`` and ``2 self.rate``
        at speed ``rate``."""
        u = rate / self.rate
        return 0.5 * (u - 1.0) * (u - 2.0), -u * (u - 2.0), 0.5 * u * (u - 1.0)

    def multiplier_maps_at(self, rate: float) -> tuple:
        """``(A_x, A_v, A_a)`` at speed ``rate`` (rad/s), each (N+1, r, m) on the phase grid: the
        quadratic through the maps at speeds 0, ``self.rate`` and ``2 self.rate`` (exact: each is a
        polynomial of degree <= 2 in the speed); ``()`` when the base has none."""
        self._check_rate(rate)
        base = self.base.coefficients.multiplier_maps
        if not base:
            return ()
        weights = self._speed_weights(rate)
        at_zero, at_double = self.speed_multiplier_maps
        return tuple(weights[0] * a0 + weights[1] * a1 + weights[2] * a2
                     for a0, a1, a2 in zip(at_zero, base, at_double))

    def observable_maps_at(self, rate: float) -> dict[str, ObservableMap]:
        """The observable maps at speed ``rate`` (rad/s): the base's for the observables of
        the configuration; for the others the quadratic through their arrays at speeds 0,
        ``self.rate`` and ``2 self.rate`` (exact: each is a polynomial of degree <= 2)."""
        self._check_rate(rate)
        maps = dict(self.base.observable_maps)
        if not self.speed_maps:
            return maps
        weights = self._speed_weights(rate)
        at_zero, at_double = self.speed_maps
        for spec in at_zero:
            samples = (at_zero[spec].arrays(), maps[spec].arrays(), at_double[spec].arrays())
            maps[spec] = maps[spec].with_arrays({
                name: sum(w * arrays[name] for w, arrays in zip(weights, samples))
                for name in samples[1]})
        return maps

    def _range_probes(self, rate: float) -> tuple:
        return tuple(probe if getattr(probe, "axial", None) is None else dataclasses.replace(
            probe, axial=self.axial0[probe.link.name] + rate**2 * self.axial2[probe.link.name])
            for probe in self.base.range_probes)

    def linear_range(self, rate: float, z: np.ndarray) -> LinearRange:
        """``at_speed(rate).linear_range(z)`` for the cost of a few array operations: the measures
        of the periodic solution ``z`` (N+1, m) of ``system_at(rate)``."""
        self._check_rate(rate)
        return linear_range(self._range_probes(rate), self.base._history(z))

    def _check_rate(self, rate) -> None:
        if not (isinstance(rate, (int, float, np.floating)) and math.isfinite(rate)
                and rate * self.rate > 0):
            raise LinearizationError(f"rate must be a finite speed (rad/s, the motion's 2 pi / period) "
                                     f"of the same sign as the scene's ({self.rate:g}); received "
                                     f"{rate!r}")

    def system_at(self, rate: float) -> periodic.PeriodicSystem:
        """Only the periodic system at speed ``rate`` (rad/s): what a grid point of a sweep
        or chart needs, without the nominal motion and mechanism of ``at_speed``."""
        self._check_rate(rate)
        w = rate
        return periodic.PeriodicSystem(self.base.nominal.period * self.rate / w, self.M,
                                       self.C0 + w * self.C1,
                                       self.K0 + w * self.K1 + w**2 * self.K2,
                                       self.f0 + w**2 * self.f2)

    def at_speed(self, rate: float, *, rebuild: bool = True) -> LinearizedMechanism:
        """The linearised mechanism at speed ``rate`` (rad/s, same sign as the base).
        ``rebuild=False`` keeps the base's ``mechanism`` (not rebuilt at ``rate``): enough for the
        residual of the full equations (``linearize.linearisation_error``), whose prescribed drives
        enter only through the motion, not for a nonlinear run."""
        started = time.perf_counter()
        system = self.system_at(rate)
        scale = rate / self.rate
        base = self.base
        lam = self.lam0 + rate**2 * self.lam2
        nominal = dataclasses.replace(
            base.nominal, t=base.nominal.t / scale, sdot=base.nominal.sdot * scale,
            sddot=base.nominal.sddot * scale**2, lam=lam,
            drive_torque=-lam[:, base.nominal.model.drive_rows], period=system.period)
        coeffs = dataclasses.replace(
            base.coefficients, t=nominal.t, C=system.C, K=system.K, f=system.f,
            Vdot=base.coefficients.Vdot * scale, Vddot=base.coefficients.Vddot * scale**2,
            multiplier_maps=self.multiplier_maps_at(rate))
        mechanism = _at_speed(self.mechanism, self.rate, rate) if rebuild else self.mechanism
        return dataclasses.replace(base, mechanism=mechanism, nominal=nominal, system=system,
                                   coefficients=coeffs,
                                   observable_maps=self.observable_maps_at(rate),
                                   range_source=functools.partial(self._range_probes, rate),
                                   run_time=time.perf_counter() - started)


def supports_speed_family(mechanism) -> bool:
    """Whether ``speed_family`` applies to ``mechanism``: it has drives and every one imposes its
    joint's motion (``IMPOSES_MOTION``: a ``mechanisms.PrescribedDrive``, the motion a function of the
    phase 2 pi t / period)."""
    return bool(mechanism.drives) and all(d.IMPOSES_MOTION for d in mechanism.drives)


def speed_family(mechanism, *, n_steps: int = 512, observables=None) -> SpeedFamily:
    """Linearise once, with the coefficients' exact dependence on the speed (see ``SpeedFamily``).
    Needs every drive prescribed (a torque drive's feedforward and PD law are not polynomial in
    the speed: linearise it at each speed with ``about``)."""
    started = time.perf_counter()
    drives = mechanism.drives
    if not supports_speed_family(mechanism):
        raise LinearizationError(
            "speed_family needs every drive to be a PrescribedDrive (the motion a function of the "
            f"phase 2 pi t / period); received drives {drives!r}. Use linearize.about() at each "
            "speed instead.")
    base = about(mechanism, n_steps=n_steps, observables=observables)
    nominal = base.nominal
    model = nominal.model
    # 2 pi / period signed like the first drive (exactly its rate when it sets the period)
    rate = (drives[0].rate if mechanism.period_is_default
            else math.copysign(2.0 * math.pi / mechanism.period, drives[0].rate or 1.0))
    # Phase derivatives of the nominal configuration: s' = sdot / rate, s'' = sddot / rate^2.
    ds, dds = nominal.sdot / rate, nominal.sddot / rate**2
    lam_static = _static_multipliers(model, nominal)
    lam2 = (nominal.lam - lam_static) / rate**2
    independent = base.coefficients.independent

    def at(w):
        # t only enters the model through the prescribed drives' rheonomic constraints, whose
        # Jacobian does not depend on it, so the phase grid is what matters.
        return _coefficients(model, nominal.t, nominal.s, w * ds, w**2 * dds,
                             lam_static + w**2 * lam2,
                             period=nominal.period * rate / w if w else math.inf,
                             independent=independent, label=lambda k: f"sample {k}",
                             stride=base.coefficients.stride,
                             multipliers=bool(base.coefficients.multiplier_maps))

    # Three speeds fix a quadratic exactly: 0, rate, 2 rate.
    c0, c1, c2 = at(0.0), base.coefficients, at(2.0 * rate)

    def split(p0, p1, p2):
        lin = (4.0 * p1 - p2 - 3.0 * p0) / (2.0 * rate)
        quad = (p2 - 2.0 * p1 + p0) / (2.0 * rate**2)
        return lin, quad

    C1, C2 = split(c0.C, c1.C, c2.C)
    K1, K2 = split(c0.K, c1.K, c2.K)
    f1, f2 = split(c0.f, c1.f, c2.f)
    scale_C = max(np.abs(c1.C).max(), 1e-300)
    if np.abs(C2).max() * rate**2 > 1e-8 * scale_C or np.abs(f1).max() * abs(rate) > 1e-8 * max(
            np.abs(c1.f).max(), 1e-300):
        raise LinearizationError("the coefficients are not polynomial in the speed as "
                                 "expected (speed-dependent forces?); use linearize.about() per "
                                 "speed")
    # The axial force is linear in s'^2, s'' and lam: its part at rest plus rate^2 times the rest.
    zero = np.zeros_like(nominal.s)
    axial0 = _nominal_axial_forces(model, nominal.t, nominal.s, zero, zero, lam_static,
                                   stride=base.coefficients.stride)
    at_rate = {probe.link.name: probe.axial for probe in base.range_probes}
    axial2 = {name: None if force is None else (at_rate[name] - force) / rate**2
              for name, force in axial0.items()}
    # Observables whose maps change with the speed, at speeds 0 and 2 rate (SpeedFamily).
    varying = [spec for spec, m in base.observable_maps.items() if m.total or m.needs_derivatives]
    speed_maps = ()
    if varying:
        speed_maps = tuple(
            _nominal_maps(model, varying, nominal, c, sdot=w * ds, sddot=w**2 * dds,
                          lam=lam_static + w**2 * lam2)
            for w, c in ((0.0, c0), (2.0 * rate, c2)))
    return SpeedFamily(mechanism=mechanism, base=base, rate=rate, M=c1.M, C0=c0.C, C1=C1,
                       K0=c0.K, K1=K1, K2=K2, f0=c0.f, f2=f2, lam0=lam_static, lam2=lam2,
                       run_time=time.perf_counter() - started, axial0=axial0, axial2=axial2,
                       speed_maps=speed_maps,
                       speed_multiplier_maps=(c0.multiplier_maps, c2.multiplier_maps))


def _at_speed(mechanism, base_speed: float, speed: float):
    """``mechanism`` (at speed ``base_speed``) at ``speed`` (same sign, rad/s): every drive's rate
    scaled by ``speed / base_speed``, an explicit period by the inverse (a default period,
    ``2 pi / |rate|``, follows the rate)."""
    period = None if mechanism.period_is_default else mechanism.period * base_speed / speed
    # d.rate / base_speed is a whole number (exactly 1 for a crank that sets the period)
    rates = {d.joint: d.rate / base_speed * speed for d in mechanism.drives}
    if mechanism.spec is None:
        return mechanism.replace(period=period, drives=tuple(
            dataclasses.replace(d, rate=rates[d.joint]) for d in mechanism.drives))
    # a scene has one [drive] table or [drives.<joint>] tables
    rate_path = "drive.rate" if "drive" in mechanism.spec else "drives.{}.rate"
    changes = {rate_path.format(joint): rate for joint, rate in rates.items() if rate}
    if period is not None:
        changes["period"] = period
    return mechanism.with_parameters(changes)


def _static_multipliers(model, nominal) -> np.ndarray:
    """Multipliers of the rigid mechanism held at rest in each nominal configuration (gravity and
    other static loads only): the rigid rows of ``Phi_s^T lam = Q(s, 0, t)``."""
    rigid = np.asarray(model.rigid_index, dtype=np.int64)
    zero = np.zeros_like(nominal.s)
    # Q(s, 0, t) = -(M 0 - Q(s, 0, t))
    forces = -mechanisms.inertia_residual_along(model, nominal.t, nominal.s, zero, zero)
    Phi_r = mechanisms.constraint_terms_along(model, nominal.t, nominal.s).jacobian[:, :, rigid]
    return np.linalg.solve(np.swapaxes(Phi_r, 1, 2), forces[:, rigid, None])[..., 0]
