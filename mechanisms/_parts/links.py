"""Links (rigid and elastic) and point masses."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping, Union

from .checks import MechanismError, PointRef, _check_name, _check_number, _check_pair, _is_number
from .damping import DAMPING_TYPES, Damping
from .discretisations import DISCRETISATION_TYPES, Discretisation
from .fem import Fem


@dataclass(frozen=True)
class RigidLink:
    """A rigid link. ``centroid`` is in the link frame (default: midpoint of the pins); ``inertia`` is
    about the centroid (kg m^2); ``points`` names further attachment points in the link frame."""

    name: str
    length: float
    mass: float
    inertia: float
    centroid: tuple[float, float] | None = None
    points: Mapping[str, tuple[float, float]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        _check_name("link", self.name)
        owner = f"link {self.name!r}"
        _check_number(owner, "length", self.length, "m", positive=True)
        _check_number(owner, "mass", self.mass, "kg", positive=True)
        _check_number(owner, "inertia", self.inertia, "kg m^2", nonnegative=True)
        if self.centroid is not None:
            _check_pair(owner, "centroid", self.centroid, "m")
        for key, point in self.points.items():
            _check_name(f"{owner}: point", key)
            if key in ("start", "end"):
                raise MechanismError(f"{owner}: point name {key!r} is reserved for the pins")
            _check_pair(owner, f"points.{key}", point, "m")

    def point_position(self, point: PointRef) -> tuple[float, float]:
        """Position (m) of ``point`` (``"start"``, ``"end"``, a key of ``points`` or a distance
        along the link) in the link frame."""
        return _pin_position(self, point, f"link {self.name!r}")

    @classmethod
    def uniform(cls, name: str, length: float, *, width: float, thickness: float, density: float,
                **kwargs) -> "RigidLink":
        """A uniform bar of rectangular section ``width x thickness`` (m) and ``density`` (kg/m^3)."""
        owner = f"link {name!r}"
        for key, value, unit in (("width", width, "m"), ("thickness", thickness, "m"),
                                 ("density", density, "kg/m^3")):
            _check_number(owner, key, value, unit, positive=True)
        mass = density * width * thickness * length
        return cls(name=name, length=length, mass=mass, inertia=mass * length**2 / 12.0, **kwargs)


_BOUNDARIES = ("pinned-pinned", "clamped-free")


@dataclass(frozen=True)
class ElasticLink:
    """A slender Euler-Bernoulli beam in a floating frame (see the module docstring).

    ``area`` in m^2, ``second_moment`` (I of the section about the bending axis) in m^4, ``density``
    in kg/m^3, ``youngs_modulus`` in Pa; ``yield_strength`` (Pa, optional): the material's yield
    stress, against which ``linearize`` compares the peak bending stress (``None``: not compared);
    ``outer_fibre`` (m, optional): distance of the extreme fibre from the neutral axis for the stress
    observables (``None``: ``section_height / 2``, exact for a rectangular section).
    """

    name: str
    length: float
    density: float
    youngs_modulus: float
    area: float
    second_moment: float
    discretisation: Discretisation = Fem(1)
    boundary: str = "pinned-pinned"  # or "clamped-free"
    axial: bool = True
    geometric_stiffening: bool = True  # strain u' + P[w'^2/2] (projected, see _beams); False: seed eq. 2.13
    rotary_inertia: bool = False
    damping: Damping = None
    yield_strength: float | None = None
    outer_fibre: float | None = None

    def __post_init__(self) -> None:
        _check_name("link", self.name)
        owner = f"link {self.name!r}"
        if self.outer_fibre is not None:
            _check_number(owner, "outer_fibre", self.outer_fibre, "m", positive=True)
        for key, unit in (("length", "m"), ("density", "kg/m^3"), ("youngs_modulus", "Pa"),
                          ("area", "m^2"), ("second_moment", "m^4")):
            _check_number(owner, key, getattr(self, key), unit, positive=True)
        if self.yield_strength is not None:
            _check_number(owner, "yield_strength", self.yield_strength, "Pa", positive=True)
        if type(self.discretisation) not in DISCRETISATION_TYPES.values():
            names = ", ".join(cls.__name__ for cls in DISCRETISATION_TYPES.values())
            raise MechanismError(f"{owner}: discretisation must be a registered discretisation "
                                 f"({names}; mechanisms.register_discretisation adds one), got "
                                 f"{self.discretisation!r}")
        if self.boundary not in _BOUNDARIES:
            raise MechanismError(f"{owner}: boundary must be one of {_BOUNDARIES}, got "
                                 f"{self.boundary!r}")
        for key in ("axial", "geometric_stiffening", "rotary_inertia"):
            if not isinstance(getattr(self, key), bool):
                raise MechanismError(f"{owner}: {key} must be true or false, got "
                                     f"{getattr(self, key)!r}")
        if self.damping is not None and type(self.damping) not in DAMPING_TYPES.values():
            raise MechanismError(f"{owner}: damping must be Rayleigh, ModalDamping, DampingMatrix "
                                 f"or None, got {self.damping!r}")

    @classmethod
    def rectangular(cls, name: str, length: float, *, width: float, thickness: float,
                    density: float, youngs_modulus: float, **kwargs) -> "ElasticLink":
        """Rectangular section ``width x thickness`` bending about the thin direction:
        ``A = b h``, ``I = b h^3 / 12``."""
        owner = f"link {name!r}"
        _check_number(owner, "width", width, "m", positive=True)
        _check_number(owner, "thickness", thickness, "m", positive=True)
        return cls(name=name, length=length, density=density, youngs_modulus=youngs_modulus,
                   area=width * thickness, second_moment=width * thickness**3 / 12.0, **kwargs)

    @property
    def mass(self) -> float:
        return self.density * self.area * self.length

    def section_rates(self, key: str) -> dict[str, float] | None:
        """How the scene key ``key`` of this link's section moves its density, area and second moment:
        ``{"density": d ln rho / dp, "area": d ln A / dp, "second_moment": d ln I / dp}`` (1 / the key's
        unit) for ``density``, ``area``, ``second_moment`` and a rectangle's ``width`` ``b`` and
        ``thickness`` ``h`` (``A = b h``, ``I = b h^3 / 12``: ``h`` the ``section_height``, ``b = A / h``);
        None for any other key.  The sensitivities' exact section derivatives
        (``linearize.analytic_derivative``) combine them by the chain rule."""
        height = self.section_height
        rates = {"density": (1.0 / self.density, 0.0, 0.0), "area": (0.0, 1.0 / self.area, 0.0),
                 "second_moment": (0.0, 0.0, 1.0 / self.second_moment),
                 "width": (0.0, height / self.area, height / self.area),
                 "thickness": (0.0, 1.0 / height, 3.0 / height)}.get(key)
        return None if rates is None else dict(zip(("density", "area", "second_moment"), rates))

    def point_position(self, point: PointRef) -> tuple[float, float]:
        """Position (m) of ``point`` (``"start"``, ``"end"`` or a distance along the link) in the
        undeformed link frame: ``(x, 0)``, ``x`` the point's abscissa."""
        return _pin_position(self, point, f"link {self.name!r}")

    @property
    def section_height(self) -> float:
        """Depth ``h`` (m) of the section in the bending plane, ``sqrt(12 I / A)``: exactly the
        ``thickness`` of a rectangular section (``A = b h``, ``I = b h^3 / 12``), and for any other
        section the depth of the rectangle with the same ``A`` and ``I``. The outer fibre is at
        ``h / 2`` from the neutral axis."""
        return math.sqrt(12.0 * self.second_moment / self.area)

    @property
    def fibre_distance(self) -> float:
        """Distance ``c`` (m) of the extreme fibres from the neutral axis: ``outer_fibre`` when
        given, else ``section_height / 2``."""
        return self.outer_fibre if self.outer_fibre is not None else 0.5 * self.section_height

    @property
    def euler_load(self) -> float:
        """Euler buckling load (N) of the link alone, ``pi^2 E I / (K L)^2``, with the effective
        length factor ``K = 1`` for a pinned-pinned link (its frame is its chord: both ends pinned)
        and ``K = 2`` for a clamped-free one (a cantilever)."""
        k = 1.0 if self.boundary == "pinned-pinned" else 2.0
        return math.pi**2 * self.youngs_modulus * self.second_moment / (k * self.length) ** 2

    def first_bending_frequency(self) -> float:
        """First pinned-pinned (or clamped-free) bending frequency of the link alone, rad/s."""
        root = math.pi if self.boundary == "pinned-pinned" else 1.8751040687119611
        return (root / self.length) ** 2 * math.sqrt(
            self.youngs_modulus * self.second_moment / (self.density * self.area))


Link = Union[RigidLink, ElasticLink]


@dataclass(frozen=True)
class PointMass:
    """A concentrated mass (kg) with optional rotary inertia (kg m^2) at a point of a link."""

    link: str
    point: PointRef
    mass: float
    inertia: float = 0.0

    def __post_init__(self) -> None:
        owner = f"point mass on {self.link!r} at {self.point!r}"
        _check_number(owner, "mass", self.mass, "kg", positive=True)
        _check_number(owner, "inertia", self.inertia, "kg m^2", nonnegative=True)


def _pin_position(link: Link, point: object, owner: str) -> tuple[float, float]:
    """Position of a point of a link in its undeformed link frame, m; raises ``MechanismError``
    naming ``owner`` for an unknown point. The one point lookup of the package (the links'
    ``point_position``, the assembler, the initial guess of the nominal motion)."""
    if point == "start":
        return (0.0, 0.0)
    if point == "end":
        return (float(link.length), 0.0)
    if isinstance(point, str):
        if isinstance(link, RigidLink) and point in link.points:
            x, y = link.points[point]
            return (float(x), float(y))
        known = ["start", "end"] + (list(link.points) if isinstance(link, RigidLink) else [])
        raise MechanismError(f"{owner}: link {link.name!r} has no point {point!r}; its points are "
                             f"{known} or a distance along the link in metres")
    if _is_number(point) and math.isfinite(point) and 0.0 <= point <= link.length:
        return (float(point), 0.0)
    raise MechanismError(f"{owner}: point on link {link.name!r} must be 'start', 'end', a named "
                         f"point or a distance in [0, {link.length}] m, got {point!r}")
