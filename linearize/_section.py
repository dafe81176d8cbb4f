"""Exact derivatives of a linearisation with respect to a link's section (``links.<link>.density``,
``.width``, ``.thickness``, ``.area``, ``.second_moment``): what ``linearize.analytic_derivative`` gives
for the section parameters that move the mass, with no truncation error.

On fixed kinematics (every drive prescribed: the nominal motion is the drives' and does not move with
the mass) the link enters the linearisation through its mass per length ``rho A`` (and ``rho I`` with
rotary inertia), its stiffness ``K_ee = E A Gu + E I Gw`` (the shapes' Gram matrices of ``u'`` and
``w''``, ``mechanisms.beam_matrices``) and its damping matrix ``D_ee``.  The mass enters affinely: ``M``,
the nominal multipliers (linear in the masses for a prescribed motion: one linear solve of the rigid
inverse dynamics), the geometric stiffness (the axial force of that inverse dynamics), the load ``f``
and the multipliers' maps are all affine in ``rho A`` at fixed ``K_ee`` and ``D_ee``, ``K_ee`` is linear in
``A`` and ``I``, and every observable's gradient is linear in ``A``, ``I`` and the fibre distance ``c``
(stresses ``E c``, moments ``E I``, axial forces ``E A``).  A section parameter ``p`` moves ``ln rho, ln A,
ln I`` at the rates ``r_rho, r_A, r_I`` its link declares (``ElasticLink.section_rates``: ``A = b h``,
``I = b h^3 / 12`` for width and thickness).  Along its tangent,

    rho A (1 + (r_rho + r_A) t),   A (1 + r_A t),   I (1 + r_I t),   c (1 + r_c t)   (r_c = (r_I - r_A) / 2),

all of these are linear in ``t``, so with ``L(t)`` the coefficients (and maps) of the mechanism whose link
is moved so and has no damping, linearised on the point's kinematics (``mechanisms.nominal_dynamics``),

    d coef / dp = (L(t) - [coef - P(D_ee)]) / t + P(dD_ee)            for any t (``TANGENT_STEP``),

exactly, to rounding: the point's coefficients less their own damping are ``L(0)``, ``P(D) = (V^T D V,
V^T D V')`` the projection of a damping matrix on the elastic block (``_projection``), and ``dD_ee`` the
damping kind's ``section_derivative`` for ``dM_ee = (r_rho + r_A) M_ee``, ``dK_ee = r_A E A Gu + r_I E I Gw``
(Rayleigh: ``alpha dM + beta dK``, and a ratio's ``beta = 2 ratio / omega_1`` moving with
``d ln omega_1 = (r_I - r_rho - r_A) / 2``); ``d ln T = 0``.  The maps are ``(maps(t) - maps) / t`` (the
multipliers' part, joint forces and drive torques, and the gradients' part), but for an axially rigid
link's nominal stress ``N / A``, not linear in ``t`` (``N`` is, ``1 / A`` is not): its difference is
``(dN - r_A N) / (A (1 + r_A t))``, corrected by the factor.

Where this is not exact the route declines (None) and the caller keeps the forward difference of
linearisations on reused kinematics: a torque drive (its nominal law and feedforward move with the
mass), a reduced link (its modal basis depends on the section), rotary inertia with ``r_A != r_I``
(thickness, area, second moment: ``rho I`` would move apart from ``rho A``), a damping kind without
``section_derivative`` (modal ratios: their matrix is not affine in ``M_ee``, ``K_ee``).
"""

from __future__ import annotations

import dataclasses
from collections import OrderedDict

import numpy as np

import mechanisms
import periodic

from ._about import about, supports_speed_family
from ._observe import ObservableMap, _ChangeRoute, _Route

__all__ = ["TANGENT_STEP", "section_derivative", "section_map_derivatives", "section_route"]

#: Largest relative change of ``rho A``, ``A``, ``I`` or ``c`` along the tangent (any value is exact: the
#: coefficients and maps are linear along it; a large one keeps the difference at their own rounding).
TANGENT_STEP = 0.5
# The massless-damping neighbours of the last few points (a point's coefficients and its maps both
# need the same one): keyed by the linearisation's id, holding it so the id is not reused.
_NEIGHBOURS: OrderedDict = OrderedDict()
_KEPT = 4


@dataclasses.dataclass(frozen=True)
class SectionRoute:
    """What the exact route needs of a section parameter: the ``link``, its ``layout``, the rates
    ``rates`` (d ln rho, d ln A, d ln I per unit p) and ``mass_rate = r_rho + r_A``."""

    link: object
    layout: object
    rates: dict
    mass_rate: float


def section_route(linearized, parts) -> SectionRoute | None:
    """The ``SectionRoute`` of the path ``links.<link>.<key>`` (split) on ``linearized``, or None where
    the exact route does not apply (module docstring: the caller differences)."""
    mechanism = linearized.mechanism
    link = next((item for item in mechanism.links if item.name == parts[1]), None)
    rule = getattr(link, "section_rates", None)
    rates = None if rule is None else rule(parts[2])
    layout = linearized.nominal.model.layouts.get(parts[1]) if rates is not None else None
    if layout is None or layout.shapes is None or not supports_speed_family(mechanism):
        return None
    if getattr(link.discretisation, "modes", None) is not None:
        return None                     # a reduced link: its modes follow M_ee and K_ee
    if link.rotary_inertia and rates["area"] != rates["second_moment"]:
        return None                     # rho I would move apart from rho A
    damping = link.damping
    if damping is not None and getattr(damping, "section_derivative", None) is None:
        return None
    return SectionRoute(link, layout, rates, rates["density"] + rates["area"])


def _neighbour(linearized, route: SectionRoute):
    """``(L(t), t)``: ``linearized``'s mechanism with ``route``'s link moved along the parameter's tangent by
    ``t`` (its unit) and its damping removed, linearised on ``linearized``'s kinematics (module docstring;
    remembered for the maps)."""
    key = (id(linearized), route.link.name, tuple(route.rates.values()))
    found = _NEIGHBOURS.get(key)
    if found is not None and found[0] is linearized:
        return found[1]
    link, rates = route.link, route.rates
    # rho A, A, I and c, each linear in t at the parameter's rates (c = sqrt(12 I / A) / 2 unless the
    # scene gives it, then fixed: set explicitly, so that it too is linear)
    fibre = 0.5 * (rates["second_moment"] - rates["area"]) if link.outer_fibre is None else 0.0
    t = TANGENT_STEP / max(abs(route.mass_rate), abs(rates["area"]), abs(rates["second_moment"]), abs(fibre))
    area = link.area * (1.0 + rates["area"] * t)
    changed = dataclasses.replace(
        link, area=area, second_moment=link.second_moment * (1.0 + rates["second_moment"] * t),
        density=link.density * link.area * (1.0 + route.mass_rate * t) / area,
        outer_fibre=link.fibre_distance * (1.0 + fibre * t), damping=None)
    mechanism = linearized.mechanism.replace(links=tuple(
        changed if item.name == link.name else item for item in linearized.mechanism.links))
    nominal = linearized.nominal
    neighbour = about(mechanism, n_steps=len(nominal.t) - 1, observables=linearized.observables,
                      kinematics=nominal)
    _NEIGHBOURS[key] = (linearized, (neighbour, t))
    while len(_NEIGHBOURS) > _KEPT:
        _NEIGHBOURS.popitem(last=False)
    return neighbour, t


def _projection(linearized, layout, d_damping, d_stiffness):
    """``(V^T dD V, V^T (dD V' + dK V))`` (N+1, m, m) of changes of one link's elastic block (the
    elastic coordinates are independent: ``V`` is a selection there)."""
    c = linearized.coefficients
    basis, rate = c.V[:, layout.elastic, :], c.Vdot[:, layout.elastic, :]
    transposed = np.swapaxes(basis, 1, 2)
    damping = transposed @ d_damping @ basis
    stiffness = transposed @ d_damping @ rate
    if d_stiffness is not None:
        stiffness = stiffness + transposed @ d_stiffness @ basis
    return damping, stiffness


def _stiffness_parts(layout):
    """``(E A Gu, E I Gw)`` (n_e, n_e): the axial and bending parts of ``K_ee`` (``beam_matrices``)."""
    shapes = layout.shapes
    link = shapes.link
    x, weights = shapes.quadrature
    v = shapes.evaluate(x)

    def gram(a):
        block = a.T @ (weights[:, None] * a)
        return 0.5 * (block + block.T)

    return (link.youngs_modulus * link.area * gram(v.du),
            link.youngs_modulus * link.second_moment * gram(v.ddw))


def section_derivative(linearized, route: SectionRoute) -> periodic.SystemDerivative | None:
    """The coefficients' derivative per unit of the section parameter of ``route`` (module docstring);
    None where the damping kind has no closed form for this change."""
    link, layout, rates = route.link, route.layout, route.rates
    m_ee, k_ee = mechanisms.beam_matrices(layout.shapes)
    axial, bending = _stiffness_parts(layout)
    d_stiffness = rates["area"] * axial + rates["second_moment"] * bending
    d_damping = np.zeros_like(k_ee)
    if link.damping is not None:
        # omega_1 ~ sqrt(E I / (rho A)) (ElasticLink.first_bending_frequency)
        d_log_frequency = 0.5 * (rates["second_moment"] - rates["density"] - rates["area"])
        d_damping = link.damping.section_derivative(link, m_ee, k_ee, route.mass_rate * m_ee, d_stiffness,
                                                    d_log_frequency)
        if d_damping is None:
            return None
    neighbour, t = _neighbour(linearized, route)
    own = np.zeros_like(k_ee) if link.damping is None else link.damping.constant_matrix(
        link.name, m_ee, k_ee, strain_rate_beta=False)
    # L(0) = the point's coefficients less its own damping; L is linear in t (K_ee's change included)
    own_damping, own_stiffness = _projection(linearized, layout, own, None)
    damping, stiffness = _projection(linearized, layout, d_damping, None)
    system, other = linearized.system, neighbour.system
    return periodic.SystemDerivative(
        M=_nonzero((other.M - system.M) / t), C=_nonzero(damping + (other.C - (system.C - own_damping)) / t),
        K=_nonzero(stiffness + (other.K - (system.K - own_stiffness)) / t), f=_nonzero((other.f - system.f) / t),
        log_period=0.0)


def _nonzero(array):
    return None if array is None or not np.any(array) else array


def _change(upper: ObservableMap, lower: ObservableMap, scale: float) -> ObservableMap:
    """The map whose arrays are ``scale (upper - lower)`` (a missing array is zero; components too)."""
    mine, theirs = upper.arrays(), lower.arrays()
    fields = {}
    for name in ("nominal", "position", "rate", "acceleration"):
        if name in mine or name in theirs:
            fields[name] = scale * (mine.get(name, 0.0) - theirs.get(name, 0.0))
    components = tuple(_change(a, b, scale) for a, b in zip(upper.components, lower.components))
    return ObservableMap(upper.unit, components=components, **fields)


def _sum(a: ObservableMap, b: ObservableMap) -> ObservableMap:
    """The map whose arrays are the sums of ``a``'s and ``b``'s (a missing array is zero)."""
    fields = {}
    for name in ("nominal", "position", "rate", "acceleration"):
        x, y = getattr(a, name), getattr(b, name)
        if x is not None or y is not None:
            fields[name] = (0.0 if x is None else x) + (0.0 if y is None else y)
    return ObservableMap(a.unit, components=tuple(_sum(x, y) for x, y in zip(a.components, b.components)),
                         **fields)


def section_map_derivatives(linearized, route: SectionRoute) -> dict:
    """d(map)/dp {spec: ``ObservableMap``} of every observable map of ``linearized`` per unit of the
    section parameter of ``route``: the difference of the tangent neighbour's maps (multipliers, linear
    in the mass; gradients, linear in ``A``, ``I``, ``c``), and for an axially rigid link's nominal stress
    ``N / A``, which is not linear in ``t``, the difference's correction to ``(dN - r_A N) / A``: exact to
    rounding (module docstring)."""
    neighbour, t = _neighbour(linearized, route)
    maps = {spec: _change(neighbour.observable_maps[spec], found, 1.0 / t)
            for spec, found in linearized.observable_maps.items()}
    layout = route.layout
    if np.any(layout.shapes.evaluate(layout.shapes.quadrature[0]).du):
        return maps             # axial coordinates: a stress's axial force is EA eps, linear in t
    nominal, r_area = linearized.nominal, route.rates["area"]
    point = _Route(nominal.model, nominal.t, nominal.s, nominal.sdot, nominal.sddot, nominal.lam,
                   linearized.coefficients, None)
    moved = neighbour.nominal
    other = _Route(moved.model, moved.t, moved.s, moved.sdot, moved.sddot, moved.lam, neighbour.coefficients, None)

    def axial(name, x):
        # (N(t) / A(t) - N / A) / t = (dN - r_A N) / (A (1 + r_A t)): add r_A t times it (A times it here,
        # the observable dividing by its A)
        if name != route.link.name:
            return np.zeros(len(nominal.t))
        force = point.axial_force(name, x)
        slope = (other.axial_force(name, x) - force) / t
        return r_area * t * (slope - r_area * force) / (1.0 + r_area * t)

    correction = _ChangeRoute(len(nominal.t), axial=axial)
    for spec in maps:
        maps[spec] = _sum(maps[spec], nominal.model.observable(spec).linear_map(correction))
    return maps
