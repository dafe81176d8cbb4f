"""Exact derivatives of a linearisation with respect to a link's section (``links.<link>.density``,
``.width``, ``.thickness``, ``.area``, ``.second_moment``): what ``linearize.analytic_derivative`` gives
for the section parameters that move the mass, with no truncation error.

On fixed kinematics (every drive prescribed: the nominal motion is the drives' and does not move with
the mass) the link enters the linearisation through its mass per length ``rho A`` (and ``rho I`` with
rotary inertia), its stiffness ``K_ee = E A Gu + E I Gw`` (the shapes' Gram matrices of ``u'`` and
``w''``, ``mechanisms.beam_matrices``) and its damping matrix ``D_ee``.  The mass enters affinely: ``M``,
the nominal multipliers (linear in the masses for a prescribed motion: one linear solve of the rigid
inverse dynamics), the geometric stiffness (the axial force of that inverse dynamics), the load ``f``
and the multipliers' maps are all affine in ``rho A`` at fixed ``K_ee`` and ``D_ee``.  So, with
``L(rho)`` the coefficients of the mechanism whose link has density ``rho`` and no damping (on the
point's kinematics, ``mechanisms.nominal_dynamics``), and ``P(D) = (V^T D V, V^T D V')`` the projection
of a damping matrix on the elastic block (``_elastic_projection``),

    d coef / d ln(rho A) = (L(rho (1 + s)) - [coef - P(D_ee)]) / s      for any s (here ``MASS_STEP`` = 1)

exactly, to rounding (the point's coefficients less its own damping are ``L(rho)``).  A section
parameter ``p`` moves ``ln rho, ln A, ln I`` at the rates ``r_rho, r_A, r_I`` its link declares
(``ElasticLink.section_rates``: ``A = b h``, ``I = b h^3 / 12`` for width and thickness), and by the
chain rule

    d coef / dp = (r_rho + r_A) d coef / d ln(rho A) + P(dD, dK),
    dK_ee = r_A E A Gu + r_I E I Gw,
    dD_ee = the damping kind's ``section_derivative`` (Rayleigh: ``alpha dM + beta dK``, and a ratio's
            ``beta = 2 ratio / omega_1`` moving with ``d ln omega_1 = (r_I - r_rho - r_A) / 2``),

with ``dM_ee = (r_rho + r_A) M_ee``; ``d ln T = 0``.  The observables' maps move the same way: the
multipliers' part (joint forces, drive torques, the nominal axial force of a stress) by the same
difference of ``L`` (affine, exact), and the section's own part (the fibre distance ``c = h / 2``, ``A``
and ``I`` in stresses, moments and axial forces) by the difference of the observables' gradients on a
link with ``A, I, c`` moved linearly at the parameter's rates and ``rho A`` held, exact since every
gradient is linear in them (``E c``, ``E I``, ``E A``, ``E``), and an axially rigid link's nominal stress
``N / A`` by ``-r_A N / A``.

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

__all__ = ["MASS_STEP", "section_derivative", "section_map_derivatives", "section_route"]

#: Relative change of the link's density for the mass part (any value is exact: the coefficients are
#: affine in the mass; a doubling keeps the difference at the coefficients' own rounding).
MASS_STEP = 1.0
#: Largest relative change of ``A``, ``I`` or ``c`` for the section's own part of the maps (any value is
#: exact: the gradients are linear in them; a large one keeps the difference at their own rounding).
GEOMETRY_STEP = 0.5
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


def _neighbour(linearized, link):
    """``L(rho (1 + MASS_STEP))``: ``linearized``'s mechanism with ``link``'s density raised and its
    damping removed, linearised on ``linearized``'s kinematics (remembered for the maps)."""
    key = (id(linearized), link.name)
    found = _NEIGHBOURS.get(key)
    if found is not None and found[0] is linearized:
        return found[1]
    changed = dataclasses.replace(link, density=link.density * (1.0 + MASS_STEP), damping=None)
    mechanism = linearized.mechanism.replace(links=tuple(
        changed if item.name == link.name else item for item in linearized.mechanism.links))
    nominal = linearized.nominal
    neighbour = about(mechanism, n_steps=len(nominal.t) - 1, observables=linearized.observables,
                      kinematics=nominal)
    _NEIGHBOURS[key] = (linearized, neighbour)
    while len(_NEIGHBOURS) > _KEPT:
        _NEIGHBOURS.popitem(last=False)
    return neighbour


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
    damping, stiffness = _projection(linearized, layout, d_damping, d_stiffness)
    system = linearized.system
    mass = force = None
    if route.mass_rate != 0.0:
        neighbour = _neighbour(linearized, link).system
        own_damping, own_stiffness = np.zeros_like(damping), np.zeros_like(stiffness)
        if link.damping is not None:
            own = link.damping.constant_matrix(link.name, m_ee, k_ee, strain_rate_beta=False)
            own_damping, own_stiffness = _projection(linearized, layout, own, None)
        # L(rho) = the point's coefficients less its own damping; affine in rho A, so exact
        scale = route.mass_rate / MASS_STEP
        mass = scale * (neighbour.M - system.M)
        damping = damping + scale * (neighbour.C - (system.C - own_damping))
        stiffness = stiffness + scale * (neighbour.K - (system.K - own_stiffness))
        force = scale * (neighbour.f - system.f)
    return periodic.SystemDerivative(M=_nonzero(mass), C=_nonzero(damping), K=_nonzero(stiffness),
                                     f=_nonzero(force), log_period=0.0)


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
    section parameter of ``route``: the multipliers' part from the mass difference, the section's own
    part from the gradients on a link with ``A``, ``I``, ``c`` moved linearly and ``rho A`` held, and
    ``-r_A N / A`` for an axially rigid link's nominal stress: exact to rounding (module docstring)."""
    specs = list(linearized.observable_maps)
    maps = {}
    if route.mass_rate != 0.0:
        neighbour = _neighbour(linearized, route.link).observable_maps
        scale = route.mass_rate / MASS_STEP
        maps = {spec: _change(neighbour[spec], linearized.observable_maps[spec], scale) for spec in specs}
    r_area, r_moment = route.rates["area"], route.rates["second_moment"]
    if r_area == 0.0 and r_moment == 0.0:
        return maps
    link, nominal, c = route.link, linearized.nominal, linearized.coefficients
    # A, I and c (c = sqrt(12 I / A) / 2 unless the scene gives it: then fixed) moved linearly in the
    # offset t at the parameter's rates, rho A held: every gradient (E c, E I, E A, E) is then linear in t
    # and one difference at a large offset is exact
    r_fibre = 0.5 * (r_moment - r_area) if link.outer_fibre is None else 0.0
    offset = GEOMETRY_STEP / max(abs(r_area), abs(r_moment), abs(r_fibre))   # in the parameter's unit
    area = link.area * (1.0 + r_area * offset)
    changed = dataclasses.replace(link, area=area, second_moment=link.second_moment * (1.0 + r_moment * offset),
                                  outer_fibre=link.fibre_distance * (1.0 + r_fibre * offset),
                                  density=link.density * link.area / area, damping=None)
    moved = mechanisms.assemble(linearized.mechanism.replace(links=tuple(
        changed if item.name == link.name else item for item in linearized.mechanism.links)))
    point = _Route(nominal.model, nominal.t, nominal.s, nominal.sdot, nominal.sddot, nominal.lam, c, None)

    def axial(name, x):
        # an axially rigid link's stress N / A: N is the mass part's (rho A held here), 1 / A moves as
        # -r_A / A; the moved observable divides by its own area A (1 + r_A t); other links' do not move
        if name != link.name:
            return np.zeros(len(nominal.t))
        return -r_area * (1.0 + r_area * offset) * point.axial_force(name, x)

    change = _ChangeRoute(len(nominal.t), coordinates=(
        _Route(moved, nominal.t, nominal.s, nominal.sdot, nominal.sddot, None, c, None), point, offset), axial=axial)
    for spec in specs:
        own = moved.observable(spec).linear_map(change)
        maps[spec] = own if spec not in maps else _sum(maps[spec], own)
    return maps
