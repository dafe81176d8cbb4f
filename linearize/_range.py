"""Linear-range measures: how far a periodic solution of the linearised mechanism is from the
small-deformation, pre-buckling, elastic regime the linearisation assumes.

Per elastic link, over one period and along the link (at ``4 n + 1`` abscissae for ``n`` Hermite
elements, both sides of each node, 33 for Ritz or user shapes): the peak transverse deflection ``w``
in the link's frame over its length and over its section height, the peak slope ``w'`` (rad), the
peak compressive axial force of the nominal motion over the link's Euler load, and the peak bending
stress ``E h |w''| / 2`` (``M c / I`` with ``M = E I w''``, ``c = h / 2``) over the yield strength.
The thresholds are ``LINEAR_RANGE_LIMITS`` (docs/methods.md gives their reasons). A link without
geometric stiffening has a model-form verdict besides (``LinkRange.model_form``): where its
compression is a sizeable part of its Euler load or its deflection several section heights, the
model leaves out what then matters, and the message names the fix (enable geometric_stiffening).

Per torque drive with a torque limit or a motor: the peak torque the unsaturated law demands
along the solution against ``torque_limit``, and the motor's peak command (torque plus back EMF,
``tau + c theta'``) against the supply voltage's ``G stall_torque``: beyond either the drive
saturates, which the linearisation (of the unsaturated law) does not see.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

import mechanisms

__all__ = ["LINEAR_RANGE_LIMITS", "LinkRange", "LinearRange", "DriveRange"]

# The thresholds beyond which a solution is ``outside_linear_range`` (docs/methods.md, linearize).
LINEAR_RANGE_LIMITS = MappingProxyType({
    # Floating-frame small deflection: the frame's rigid motion carries the large motion and the
    # deflection must stay small against the length (small angles: sin and tan of 0.3 rad are
    # within 1.5 % and 3 % of it). Measured: four_bar_thesis at 100 rad/s (deflection / length
    # 0.057, slope 0.18 rad) follows its nonlinear run to 0.02 %.
    "deflection_over_length": 0.1,
    "slope": 0.3,
    # Stiffened links linearise the membrane strain u' + P[w'^2/2]; the stretching that neglects
    # grows with (deflection / section height)^2. Measured peak-to-peak differences, nonlinear
    # periodic state against linear (256 steps, docs/methods.md): six_bar 1.5-1.8 % at 100 rad/s,
    # four_bar_fem4 -8.9 % at 5.1 (100 rad/s), -9.5 % at 13.5 (150 rad/s). The error budget's
    # linearisation term (linearize.linearisation_error) estimates the difference at every point.
    "deflection_over_height": 6.0,
    # Compression against the Euler load: the bending frequency falls as sqrt(1 - P / P_E), at
    # half the Euler load by 29 %. A link without geometric stiffening does not see this drop.
    "compression_over_euler": 0.5,
    # Linear elasticity: the bending stress of the outer fibre against the yield strength.
    "stress_over_yield": 1.0,
    # Model form of a link without geometric stiffening (seed eq. 2.13): its bending does not feel
    # the axial force, which shifts the bending frequency as sqrt(1 - P / P_E); measured against
    # the stiffened model of the same machine (four_bar_thesis against four_bar_ritz, peak
    # deflection): 3 % at 0.027 of the Euler load (30 rad/s), 11 % at 0.107 (60 rad/s), 93 % at
    # 0.30 (100 rad/s, where the machine does 14.2 mm against the unstiffened 29.2 mm).
    "unstiffened_compression_over_euler": 0.1,
    # ... and it leaves out the membrane stretching of large deflections, which its own nonlinear
    # runs leave out too (so no nonlinear check can show it): a few section heights.
    "unstiffened_deflection_over_height": 2.0,
})

#: The fix a model-form verdict names.
STIFFENING_FIX = "enable geometric_stiffening (links.<name>.geometric_stiffening = true)"

_MEASURES = (("peak_deflection_over_length", "deflection_over_length", "peak deflection / length"),
             ("peak_deflection_over_height", "deflection_over_height",
              "peak deflection / section height"),
             ("peak_slope", "slope", "peak slope (rad)"),
             ("peak_compression_over_euler", "compression_over_euler",
              "peak compressive axial force / Euler load"),
             ("peak_stress_over_yield", "stress_over_yield", "peak bending stress / yield strength"))


@dataclass(frozen=True)
class LinkRange:
    """The linear-range measures of one elastic link over one period (all dimensionless except
    ``peak_slope``, rad). ``peak_compression_over_euler`` is 0 when the link is never compressed
    and NaN when its load cannot be computed (a joint that is not a point force);
    ``peak_stress_over_yield`` is NaN without a ``yield_strength``; ``stiffened``: the link has
    geometric stiffening (its model sees the compression's effect on its bending)."""

    link: str
    peak_deflection_over_length: float
    peak_deflection_over_height: float
    peak_slope: float
    peak_compression_over_euler: float
    peak_stress_over_yield: float
    stiffened: bool

    def exceeded(self) -> list[str]:
        """The measures above their ``LINEAR_RANGE_LIMITS``, each in words."""
        found = []
        for field, limit_name, words in _MEASURES:
            value, limit = getattr(self, field), LINEAR_RANGE_LIMITS[limit_name]
            if limit_name == "deflection_over_height" and not self.stiffened:
                continue  # the unstiffened strain has no membrane term to neglect
            if not value > limit:
                continue
            text = f"link {self.link!r}: {words} {value:.3g} > {limit:g}"
            if limit_name == "compression_over_euler" and not self.stiffened:
                text += (" (this link has no geometric stiffening: the model cannot see buckling "
                         "there; turn geometric_stiffening on)")
            found.append(text)
        return found + self.model_form()

    def model_form(self) -> list[str]:
        """What a link without geometric stiffening leaves out, in words, where its compression or
        deflection passes the ``unstiffened_*`` limits (empty for a stiffened link)."""
        if self.stiffened:
            return []
        parts = []
        compression, limit = self.peak_compression_over_euler, LINEAR_RANGE_LIMITS[
            "unstiffened_compression_over_euler"]
        if compression > limit:
            parts.append(f"its peak compression is {compression:.3g} of its Euler load (> {limit:g}), "
                         f"whose effect on its bending it does not see")
        height, limit = self.peak_deflection_over_height, LINEAR_RANGE_LIMITS[
            "unstiffened_deflection_over_height"]
        if height > limit:
            parts.append(f"its peak deflection is {height:.3g} section heights (> {limit:g}), whose "
                         f"membrane stretching it leaves out (its own nonlinear runs too)")
        if not parts:
            return []
        return [f"model form: link {self.link!r} has no geometric stiffening: " + "; ".join(parts)
                + f"; {STIFFENING_FIX.replace('<name>', self.link)}"]


@dataclass(frozen=True)
class DriveRange:
    """The saturation measures of one torque drive over one period (N m): the peak demanded
    torque (unsaturated law) against ``torque_limit`` and the motor's peak command ``|tau + c
    theta'|`` against ``command_limit = G stall_torque`` (``inf`` where there is no such limit)."""

    joint: str
    peak_demanded_torque: float
    torque_limit: float
    peak_command: float
    command_limit: float

    def exceeded(self) -> list[str]:
        found = []
        if self.peak_demanded_torque > self.torque_limit:
            found.append(f"drive {self.joint!r}: peak demanded torque {self.peak_demanded_torque:.4g} "
                         f"N m > torque_limit {self.torque_limit:.4g} N m (the drive saturates)")
        if self.peak_command > self.command_limit:
            found.append(f"drive {self.joint!r}: peak motor command {self.peak_command:.4g} N m > "
                         f"G stall_torque {self.command_limit:.4g} N m (the supply voltage "
                         f"saturates)")
        return found


@dataclass(frozen=True)
class LinearRange:
    """``links``: one ``LinkRange`` per elastic link; ``drives``: one ``DriveRange`` per torque
    drive with a torque limit or a motor; ``status``: ``"ok"`` or ``"outside_linear_range"``;
    ``message``: each measure above its threshold (link or drive, measure, value, threshold), or
    that all are within."""

    links: tuple[LinkRange, ...]
    status: str
    message: str
    drives: tuple[DriveRange, ...] = ()


@dataclass(frozen=True)
class _LinkProbe:
    """What the measures of one elastic link need, fixed by the configuration on the grid:
    ``columns`` (n_e,) of the link's elastic coordinates in ``z``; ``x`` (n_x,) the sample
    abscissae (m, ``sample_abscissae``); ``w, dw, ddw`` (n_x, n_e) the shape rows there; ``axial`` (N+1, n_x) the
    nominal axial force (N, tension
    positive) there, or ``None``; and the link's constants."""

    link: mechanisms.ElasticLink
    columns: np.ndarray
    x: np.ndarray
    w: np.ndarray
    dw: np.ndarray
    ddw: np.ndarray
    axial: np.ndarray | None
    stiffened: bool

    def measures(self, z: np.ndarray) -> LinkRange:
        link = self.link
        q = z[:, self.columns].T                                     # (n_e, N+1)
        deflection = np.abs(self.w @ q).max()
        slope = np.abs(self.dw @ q).max()
        if link.yield_strength is None:
            stress = math.nan
        else:
            # sigma = M c / I with M = E I w'' and c = h / 2
            stress = (link.youngs_modulus * link.section_height / 2 * np.abs(self.ddw @ q).max()
                      / link.yield_strength)
        compression = (math.nan if self.axial is None
                       else max(0.0, -float(self.axial.min())) / link.euler_load)
        return LinkRange(link=link.name, peak_deflection_over_length=float(deflection / link.length),
                         peak_deflection_over_height=float(deflection / link.section_height),
                         peak_slope=float(slope), peak_compression_over_euler=compression,
                         peak_stress_over_yield=float(stress), stiffened=self.stiffened)


@dataclass(frozen=True)
class _DriveProbe:
    """What the saturation measures of one torque drive need: the unsaturated torque along the
    nominal motion ``tau`` (N+1,) and its gains on ``z``, ``z'`` (N+1, m); the crank rate
    ``rate`` (N+1,) and its gains ``rate_position``, ``rate_rate`` (N+1, m); the motor's back-EMF
    damping ``back_emf`` (N m s/rad) and the limits (N m); ``period`` (s) for ``z'``."""

    joint: str
    tau: np.ndarray
    position: np.ndarray
    rate_gain: np.ndarray
    rate: np.ndarray
    rate_position: np.ndarray
    rate_rate: np.ndarray
    back_emf: float
    torque_limit: float
    command_limit: float
    period: float

    def measures(self, z: np.ndarray) -> DriveRange:
        from ._core import spectral_derivatives

        zdot = spectral_derivatives(z, self.period)[0]
        tau = self.tau + np.einsum("ki,ki->k", self.position, z) + np.einsum(
            "ki,ki->k", self.rate_gain, zdot)
        rate = self.rate + np.einsum("ki,ki->k", self.rate_position, z) + np.einsum(
            "ki,ki->k", self.rate_rate, zdot)
        return DriveRange(self.joint, float(np.abs(tau).max()), self.torque_limit,
                          float(np.abs(tau + self.back_emf * rate).max()), self.command_limit)


def drive_probes(model, t, s, sdot, coefficients, period) -> tuple[_DriveProbe, ...]:
    """One ``_DriveProbe`` per torque drive of ``model`` (with feedforward) that has a torque
    limit or a motor, along the nominal motion ``t, s, sdot``."""
    from ._observe import torque_law_map

    probes = []
    for drive in model.mechanism.drives:
        if drive.IMPOSES_MOTION:
            continue
        motor = drive.motor
        if motor is None and not math.isfinite(drive.torque_limit):
            continue
        tau, position, rate_gain = torque_law_map(model, drive.joint, t, s, sdot, coefficients,
                                                  saturate=False)
        h = model.drive_gradient(drive.joint)
        probes.append(_DriveProbe(
            joint=drive.joint, tau=tau, position=position, rate_gain=rate_gain, rate=sdot @ h,
            rate_position=np.einsum("n,kni->ki", h, coefficients.Vdot),
            rate_rate=np.einsum("n,kni->ki", h, coefficients.V),
            back_emf=motor.back_emf_damping if motor is not None else 0.0,
            torque_limit=float(drive.torque_limit),
            command_limit=motor.peak_command if motor is not None else math.inf,
            period=float(period)))
    return tuple(probes)


def sample_abscissae(link) -> np.ndarray:
    """Abscissae (m) where the measures look: ``4 n + 1`` evenly spaced for a discretisation whose
    shapes' curvature may jump at ``n + 1`` evenly spaced ``breakpoints(link)`` (the nodes of
    Hermite elements, among the abscissae), 33 otherwise, each interior one also just to its left
    (the shapes take the element to the right at a node)."""
    breakpoints = getattr(link.discretisation, "breakpoints", None)
    nodes = breakpoints(link) if breakpoints is not None else ()
    n = 4 * (len(nodes) - 1) if len(nodes) > 1 else 32
    x = np.linspace(0.0, link.length, n + 1)
    return np.sort(np.concatenate([x, x[1:] - 1e-9 * link.length]))


def link_probes(model, independent, axial) -> tuple[_LinkProbe, ...]:
    """One ``_LinkProbe`` per elastic link of ``model``; ``independent`` (m,) the indices of ``z``
    in ``s``; ``axial``: link name -> (N+1, n_x) axial force at ``sample_abscissae``."""
    column = {int(i): k for k, i in enumerate(independent)}
    probes = []
    for name, layout in model.layouts.items():
        if layout.shapes is None:
            continue
        x = sample_abscissae(layout.link)
        values = layout.shapes.evaluate(x)
        columns = np.array([column[i] for i in range(layout.elastic.start, layout.elastic.stop)])
        probes.append(_LinkProbe(link=layout.link, columns=columns, x=x, w=values.w, dw=values.dw,
                                 ddw=values.ddw, axial=axial[name], stiffened=layout.stiffening))
    return tuple(probes)


def linear_range(probes, z: np.ndarray) -> LinearRange:
    """The ``LinearRange`` of the independent-coordinate history ``z`` (N+1, m); a non-finite
    history raises ``mechanisms.ArgumentError`` (no verdict can be read from it)."""
    z = np.asarray(z, dtype=float)
    if not np.isfinite(z).all():
        raise mechanisms.ArgumentError(
            f"z: expected a finite history of the independent coordinates; received "
            f"{int((~np.isfinite(z)).sum())} non-finite entries of {z.size}")
    links = tuple(probe.measures(z) for probe in probes if isinstance(probe, _LinkProbe))
    drives = tuple(probe.measures(z) for probe in probes if isinstance(probe, _DriveProbe))
    exceeded = [text for part in links + drives for text in part.exceeded()]
    # a measure that could not be computed is said, never passed over as within its limit
    unknown = [f"link {link.link!r}: compression not computed (a joint is not a point force)"
               for link in links if np.isnan(link.peak_compression_over_euler)]
    if exceeded:
        return LinearRange(links, "outside_linear_range",
                           "outside the linear range: " + "; ".join(exceeded + unknown), drives)
    return LinearRange(links, "ok", "; ".join(["every computed measure within the linear range"] + unknown)
                       if unknown else "every elastic link within the linear range", drives)
