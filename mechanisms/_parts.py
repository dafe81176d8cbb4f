"""The parts a planar mechanism is made of: links, joints, point masses, drives.

Conventions shared by every module of ``mechanisms`` (and relied on by ``linearize``):

* SI units and radians everywhere.
* Every link carries a *floating frame* whose origin is the link's first pin ("start") and whose
  x-axis points to its second pin ("end"). For a rigid link that frame is fixed in the body. For an
  elastic link with ``boundary="pinned-pinned"`` the frame is the chord frame: the transverse
  deflection ``w`` is zero at both pins and the axial displacement ``u`` is zero at the start, so the
  end pin sits at local ``(length + u(length), 0)``. With ``boundary="clamped-free"`` (robot arms) the
  frame is tangent at the start: ``w(0) = w'(0) = u(0) = 0`` and the tip is free.
* Generalized coordinates are redundant: for each link, in the order the links are given,
  ``(x, y, theta)`` of its frame origin and angle, followed by its elastic coordinates.
* A point on a link is named by a string: ``"start"``, ``"end"``, a key of ``RigidLink.points``, or
  a float in ``[0, length]`` (a position along the undeformed x-axis of the link). A point on the ground
  is a pair of floats ``(x, y)`` in metres.

Every part checks its own numbers when it is made, and a ``Mechanism`` checks how the parts fit
together (names, mobility, Grashof for four-bars), raising ``MechanismError`` (a ``ValueError``) that
names the offending part and key. Checks that need the assembled equations (assembly at ``t = 0``, a
crank that cannot turn, toggle positions) run at the start of ``mechanisms.nominal_motion``.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import re
from dataclasses import dataclass, field
from typing import Any, Callable, ClassVar, Mapping, Union

import numpy as np

GROUND = "ground"

PointRef = Union[str, float]


class MechanismError(ValueError):
    """A mechanism or scene that is invalid: bad numbers, unknown names, a linkage that cannot be
    assembled or whose crank cannot turn, a singular constraint Jacobian."""


class ArgumentError(ValueError):
    """A bad argument to a function or method of ``mechanisms`` (a shape, a non-finite value, an
    unknown joint, link or observable name, an option that needs another): the message names the
    argument, what was expected and what was received. Numerical failures on good input raise
    ``ConvergenceError`` (a ``RuntimeError``) instead."""


_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_\-]*$")


def _check_name(kind: str, name: object) -> None:
    # Names become parts of dotted parameter paths ("links.coupler.thickness"), of observable
    # specs ("coupler.deflection@0.5") and of constraint labels ("B.x", "drive:O"), so dots, '@'
    # and ':' are not allowed.
    if not isinstance(name, str) or not _NAME.match(name):
        raise MechanismError(f"{kind} name must be a word of letters, digits, '_' or '-' starting "
                             f"with a letter (no dots), got {name!r}")
    if name == GROUND:
        raise MechanismError(f"{kind} name {GROUND!r} is reserved for the fixed frame")


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _check_number(owner: str, key: str, value: object, unit: str, *, positive: bool = False,
                  nonnegative: bool = False) -> None:
    if not _is_number(value) or not math.isfinite(value):
        raise MechanismError(f"{owner}: {key} must be a finite number ({unit}), got {value!r}")
    if positive and not value > 0:
        raise MechanismError(f"{owner}: {key} must be positive ({unit}), got {value!r}")
    if nonnegative and not value >= 0:
        raise MechanismError(f"{owner}: {key} must be zero or positive ({unit}), got {value!r}")


# Upper bounds of the size-like values of a scene (docs/scenes.md, "Limits"). Each keeps what one
# link or drive costs bounded, and far above what any model needs; what a whole study costs (its
# steps, points and all coordinates together) is estimated and limited by the studies' resource guard.
#: Hermite elements per link: each adds 3 coordinates, and a linearisation holds (n_steps + 1) n^2
#: doubles per matrix (128 elements alone: 0.3 GB per matrix at 256 steps).
MAX_ELEMENTS = 128
#: Ritz modes per link, bending or axial: beyond 64 half-waves the Euler-Bernoulli beam itself no
#: longer describes a slender link (the wavelength nears the section height of any practical link).
MAX_MODES = 64
#: Whole turns of a drive per period: the studies resolve one period with n_steps steps, and the
#: loader's Grashof scan samples 4096 crank angles per turn.
MAX_TURNS = 100
#: Order k of a drive harmonic, and how many a drive may have: the motion is sampled n_steps times
#: per period, and the studies' n_steps is at most 65536.
MAX_HARMONIC_ORDER = 1000
MAX_HARMONICS = 100


def _check_count(owner: str, key: str, value: object, minimum: int, maximum: int | None = None,
                 why: str = "") -> None:
    if (not isinstance(value, int) or isinstance(value, bool) or value < minimum
            or (maximum is not None and value > maximum)):
        bound = f"an integer >= {minimum}" if maximum is None else \
            f"an integer from {minimum} to {maximum} ({why})"
        raise MechanismError(f"{owner}: {key} must be {bound}, got {value!r}")


def _check_pair(owner: str, key: str, value: object, unit: str) -> None:
    if (not isinstance(value, (tuple, list)) or len(value) != 2
            or not all(_is_number(v) and math.isfinite(v) for v in value)):
        raise MechanismError(f"{owner}: {key} must be a pair of finite numbers ({unit}), "
                             f"got {value!r}")


# ---------------------------------------------------------------------------------------------------
# Discretisation of an elastic link
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Ritz:
    """Ritz-Galerkin discretisation with the thesis's modes (seed eq. 2.2 and 2.4).

    Pinned-pinned bending ``X_i(x) = sin(i pi x / L)``, ``i = 1..n_bending``; axial
    ``Y_k(x) = sin((2k - 1) pi x / (2 L))``, ``k = 1..n_axial`` (ignored when the link has no axial
    deformation). For ``clamped-free`` links the clamped-free beam modes are used instead.
    """

    n_bending: int = 2
    n_axial: int = 1

    # the scene file (see Revolute for the pattern; the shapes themselves are in _beams.beam_shapes)
    TYPE: ClassVar[str] = "ritz"
    KEYS: ClassVar[tuple[str, ...]] = ("type", "n_bending", "n_axial")

    #: why the mode counts are bounded (``MAX_MODES``)
    LIMIT: ClassVar[str] = "more modes than an Euler-Bernoulli beam describes"

    def __post_init__(self) -> None:
        _check_count("Ritz", "n_bending", self.n_bending, 1, MAX_MODES, self.LIMIT)
        _check_count("Ritz", "n_axial", self.n_axial, 0, MAX_MODES, self.LIMIT)

    @classmethod
    def from_table(cls, table) -> "Ritz":
        return cls(table.integer("n_bending", 2, minimum=1, maximum=MAX_MODES, why=cls.LIMIT),
                   table.integer("n_axial", 1, minimum=0, maximum=MAX_MODES, why=cls.LIMIT))

    def to_table(self) -> dict[str, Any]:
        return {"type": self.TYPE, "n_bending": self.n_bending, "n_axial": self.n_axial}


@dataclass(frozen=True)
class UserShapes:
    """Ritz-Galerkin discretisation with shape functions supplied by the user.

    Each callable takes ``(x, length)`` with ``x`` an array in metres and returns a tuple
    ``(value, first_derivative, second_derivative)`` of arrays shaped like ``x``. Bending shapes must
    satisfy the link's boundary conditions (the loader checks them at the ends).
    """

    bending: tuple[Callable, ...] = ()
    axial: tuple[Callable, ...] = ()

    def __post_init__(self) -> None:
        if not self.bending or not all(callable(f) for f in self.bending + self.axial):
            raise MechanismError("UserShapes: bending must be a non-empty tuple of callables and "
                                 "axial a tuple of callables")


@dataclass(frozen=True)
class Fem:
    """Hermite beam finite elements (seed eq. 2.5-2.8): ``n_elements`` equal elements, three DOF per
    node (axial, transverse, rotation), the link's boundary conditions removed.

    ``modes`` (optional): reduce the element model to its ``modes`` lowest modes under the link's
    boundary conditions plus the static correction modes its joints, drives and point masses and the
    floating frame's distributed inertia load need (``mechanisms._reduce``); the cost then grows with
    the modes, not the elements. ``None`` (the default): the full element model.
    """

    n_elements: int = 1
    modes: int | None = None

    TYPE: ClassVar[str] = "fem"
    KEYS: ClassVar[tuple[str, ...]] = ("type", "n_elements", "modes")

    #: why the element count is bounded (``MAX_ELEMENTS``)
    LIMIT: ClassVar[str] = "each element adds 3 coordinates, and the matrices grow as their square"

    def __post_init__(self) -> None:
        _check_count("Fem", "n_elements", self.n_elements, 1, MAX_ELEMENTS, self.LIMIT)
        if self.modes is not None:
            _check_count("Fem", "modes", self.modes, 1, MAX_MODES, Ritz.LIMIT)

    @classmethod
    def from_table(cls, table) -> "Fem":
        modes = (table.integer("modes", minimum=1, maximum=MAX_MODES, why=Ritz.LIMIT)
                 if table.has("modes") else None)
        return cls(table.integer("n_elements", 1, minimum=1, maximum=MAX_ELEMENTS, why=cls.LIMIT),
                   modes)

    def to_table(self) -> dict[str, Any]:
        table = {"type": self.TYPE, "n_elements": self.n_elements}
        if self.modes is not None:
            table["modes"] = self.modes
        return table


Discretisation = Union[Ritz, UserShapes, Fem]
#: The discretisations a scene file can name, by ``type`` (the first is the default). A class listed
#: here declares ``TYPE``, ``KEYS``, ``from_table(table)`` and ``to_table()``; its shape functions
#: are built in ``_beams.beam_shapes``. (``UserShapes`` holds callables: Python only.)
DISCRETISATION_TYPES: dict[str, type] = {cls.TYPE: cls for cls in (Fem, Ritz)}


# ---------------------------------------------------------------------------------------------------
# Damping of the elastic coordinates
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Rayleigh:
    """Rayleigh damping, units 1/s and s: ``alpha M_ee`` on a link's elastic coordinates plus
    Kelvin-Voigt damping ``beta``, a damping stress ``beta E`` times the strain rate of bending and
    of axial (membrane) strain. Without geometric stiffening that is ``beta K_ee``; with it, it acts
    on the rate of the projected membrane strain, so a bent link shortening its chord is not damped
    as if it were stretched (equal to ``beta K_ee`` at zero deflection, hence in the linearisation)."""

    alpha: float = 0.0
    beta: float = 0.0

    def __post_init__(self) -> None:
        _check_number("Rayleigh", "alpha", self.alpha, "1/s", nonnegative=True)
        _check_number("Rayleigh", "beta", self.beta, "s", nonnegative=True)


@dataclass(frozen=True)
class ModalDamping:
    """Damping ratios of the link's own modes (free-floating frame held fixed), lowest first; the
    modes past the last ratio given are undamped."""

    ratios: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        for i, ratio in enumerate(self.ratios):
            _check_number("ModalDamping", f"ratios[{i}]", ratio, "1", nonnegative=True)


@dataclass(frozen=True)
class DampingMatrix:
    """An explicit damping matrix on the link's elastic coordinates, N s/m (n_elastic, n_elastic)."""

    matrix: tuple[tuple[float, ...], ...] = ()

    def __post_init__(self) -> None:
        n = len(self.matrix)
        for i, row in enumerate(self.matrix):
            if len(row) != n:
                raise MechanismError(f"DampingMatrix: matrix must be square, row {i} has "
                                     f"{len(row)} entries instead of {n}")
            for j, value in enumerate(row):
                _check_number("DampingMatrix", f"matrix[{i}][{j}]", value, "N s/m")


Damping = Union[Rayleigh, ModalDamping, DampingMatrix, None]


# ---------------------------------------------------------------------------------------------------
# Links
# ---------------------------------------------------------------------------------------------------
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
        if not isinstance(self.discretisation, (Ritz, UserShapes, Fem)):
            raise MechanismError(f"{owner}: discretisation must be Ritz, UserShapes or Fem, got "
                                 f"{self.discretisation!r}")
        if self.boundary not in _BOUNDARIES:
            raise MechanismError(f"{owner}: boundary must be one of {_BOUNDARIES}, got "
                                 f"{self.boundary!r}")
        for key in ("axial", "geometric_stiffening", "rotary_inertia"):
            if not isinstance(getattr(self, key), bool):
                raise MechanismError(f"{owner}: {key} must be true or false, got "
                                     f"{getattr(self, key)!r}")
        if not isinstance(self.damping, (Rayleigh, ModalDamping, DampingMatrix, type(None))):
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


# ---------------------------------------------------------------------------------------------------
# Joints
# ---------------------------------------------------------------------------------------------------
# A joint class declares what the rest of ``mechanisms`` needs of it: ``TYPE`` (its scene-file
# ``type``), ``KEYS`` (its scene-table keys), ``from_table(name, table)`` and ``to_table()`` (the scene
# file both ways; ``table`` reads keys with their units and checks, see ``_load._Table``),
# ``n_equations`` and ``ends`` (the link points it joins, ground left out). Its constraint rows are
# written in ``_assemble``; register the class in ``JOINT_TYPES`` below.
@dataclass(frozen=True)
class Revolute:
    """A pin between ``(link_a, point_a)`` and ``(link_b, point_b)``; ``link_a`` may be ``"ground"``,
    then ``point_a`` is ``(x, y)`` in metres. Two constraint equations (x and y)."""

    name: str
    link_a: str
    point_a: PointRef | tuple[float, float]
    link_b: str
    point_b: PointRef

    TYPE: ClassVar[str] = "revolute"
    KEYS: ClassVar[tuple[str, ...]] = ("type", "link_a", "point_a", "link_b", "point_b")
    n_equations: ClassVar[int] = 2

    @classmethod
    def from_table(cls, name: str, table) -> "Revolute":
        link_a = table.string("link_a")
        point_a = table.pair("point_a", "m") if link_a == GROUND else table.point("point_a")
        return cls(name, link_a, point_a, table.string("link_b"), table.point("point_b"))

    def to_table(self) -> dict[str, Any]:
        return {"type": self.TYPE, "link_a": self.link_a,
                "point_a": list(self.point_a) if self.link_a == GROUND else self.point_a,
                "link_b": self.link_b, "point_b": self.point_b}

    @property
    def ends(self) -> tuple[tuple[str, PointRef], ...]:
        """``(link, point)`` of each side on a link (the ground side left out)."""
        ground = self.link_a == GROUND
        return ((self.link_b, self.point_b),) if ground else ((self.link_a, self.point_a),
                                                              (self.link_b, self.point_b))

    def __post_init__(self) -> None:
        _check_name("joint", self.name)
        if self.link_b == GROUND:
            raise MechanismError(f"joint {self.name!r}: put the ground on side a (link_a = "
                                 f"{GROUND!r}, point_a = (x, y)), not on side b")
        if self.link_a == self.link_b:
            raise MechanismError(f"joint {self.name!r} joins link {self.link_a!r} to itself")
        if self.link_a == GROUND:
            _check_pair(f"joint {self.name!r}", "point_a (a ground point)", self.point_a, "m")


@dataclass(frozen=True)
class Slider:
    """A prismatic slider: a point of a link moves on a ground line through ``origin`` (m) at angle
    ``angle`` (rad) to the x-axis. One constraint equation (normal distance zero)."""

    name: str
    link: str
    point: PointRef
    origin: tuple[float, float] = (0.0, 0.0)
    angle: float = 0.0

    TYPE: ClassVar[str] = "slider"
    KEYS: ClassVar[tuple[str, ...]] = ("type", "link", "point", "origin", "angle")
    n_equations: ClassVar[int] = 1

    def __post_init__(self) -> None:
        _check_name("joint", self.name)
        _check_pair(f"joint {self.name!r}", "origin", self.origin, "m")
        _check_number(f"joint {self.name!r}", "angle", self.angle, "rad")

    @classmethod
    def from_table(cls, name: str, table) -> "Slider":
        return cls(name, table.string("link"), table.point("point"), table.pair("origin", "m", (0.0, 0.0)),
                   table.number("angle", "rad", 0.0))

    def to_table(self) -> dict[str, Any]:
        return {"type": self.TYPE, "link": self.link, "point": self.point, "origin": list(self.origin),
                "angle": self.angle}

    @property
    def ends(self) -> tuple[tuple[str, PointRef], ...]:
        return ((self.link, self.point),)


Joint = Union[Revolute, Slider]
#: The joint classes by their scene-file ``type`` (the first is the default type).
JOINT_TYPES: dict[str, type] = {cls.TYPE: cls for cls in (Revolute, Slider)}


# ---------------------------------------------------------------------------------------------------
# Drives
# ---------------------------------------------------------------------------------------------------
def _check_drive(drive: "PrescribedDrive | TorqueDrive") -> None:
    owner = f"drive at joint {drive.joint!r}"
    _check_number(owner, "rate", drive.rate, "rad/s")
    _check_number(owner, "offset", drive.offset, "rad")
    if len(drive.harmonics) > MAX_HARMONICS:
        raise MechanismError(f"{owner}: harmonics has {len(drive.harmonics)} entries; at most "
                             f"{MAX_HARMONICS} (the motion is sampled n_steps times per period)")
    for i, harmonic in enumerate(drive.harmonics):
        if len(harmonic) != 3:
            raise MechanismError(f"{owner}: harmonics[{i}] must be (k, cos_k, sin_k), got "
                                 f"{harmonic!r}")
        _check_count(owner, f"harmonics[{i}] order k", harmonic[0], 1, MAX_HARMONIC_ORDER,
                     "the motion is sampled n_steps times per period, at most 65536")
        _check_number(owner, f"harmonics[{i}] cos_k", harmonic[1], "rad")
        _check_number(owner, f"harmonics[{i}] sin_k", harmonic[2], "rad")


def _drive_angle(drive: "PrescribedDrive | TorqueDrive", t: float,
                 period: float | None) -> tuple[float, float, float]:
    """The drive's nominal relative angle (rad), its rate (rad/s) and acceleration (rad/s^2) at
    time ``t`` (s); ``period`` (s) sets the harmonics' fundamental."""
    from ._assemble import drive_law  # the one drive law, shared with the assembled model

    return drive_law(drive, period, t)


@dataclass(frozen=True)
class PrescribedDrive:
    """Prescribes the relative rotation at revolute joint ``joint``: the angle of ``link_b``'s material
    tangent minus that of ``link_a`` (ground: absolute angle) follows

        angle(t) = offset + rate t + sum_k (cos_k cos(k w t) + sin_k sin(k w t)),  w = 2 pi / period

    with ``harmonics`` a tuple of ``(k, cos_k, sin_k)``. One constraint equation (rheonomic).
    ``inertia`` (kg m^2) turns with ``link_b`` about the joint: the rotor and flywheel a torque
    drive carries into its nominal motion (``TorqueDrive.inertia``); not a scene key."""

    joint: str
    rate: float = 0.0
    offset: float = 0.0
    harmonics: tuple[tuple[int, float, float], ...] = ()
    inertia: float = 0.0

    def __post_init__(self) -> None:
        _check_drive(self)
        _check_number(f"drive at joint {self.joint!r}", "inertia", self.inertia, "kg m^2",
                      nonnegative=True)

    angle = _drive_angle


@dataclass(frozen=True)
class DCMotor:
    """A DC motor with a linear speed-torque characteristic behind a gear of ratio ``gear_ratio``
    (motor speed / crank speed). At full supply voltage the motor gives ``stall_torque`` (N m) at
    rest and none at ``no_load_speed`` (rad/s, motor shaft); at the command ``v`` in [-1, 1] (the
    voltage over the supply voltage) its torque is ``stall_torque (v - omega_m / no_load_speed)``.
    At the crank (angle rate ``theta'``, ``omega_m = G theta'``):

        tau = G stall_torque v - c theta',     c = G^2 stall_torque / no_load_speed (back EMF),

    and the rotor adds ``G^2 rotor_inertia`` (kg m^2) on the crank. From armature constants
    (``from_armature``): ``stall_torque = k_t V / R``, ``no_load_speed = V / k_t`` (SI: the
    back-EMF constant equals the torque constant ``k_t``)."""

    stall_torque: float
    no_load_speed: float
    rotor_inertia: float = 0.0
    gear_ratio: float = 1.0

    def __post_init__(self) -> None:
        _check_number("motor", "stall_torque", self.stall_torque, "N m", positive=True)
        _check_number("motor", "no_load_speed", self.no_load_speed, "rad/s", positive=True)
        _check_number("motor", "rotor_inertia", self.rotor_inertia, "kg m^2", nonnegative=True)
        _check_number("motor", "gear_ratio", self.gear_ratio, "1", positive=True)

    @classmethod
    def from_armature(cls, *, resistance: float, torque_constant: float, supply_voltage: float,
                      rotor_inertia: float = 0.0, gear_ratio: float = 1.0) -> "DCMotor":
        """The motor of armature resistance (ohm), torque constant (N m/A = V s/rad) and supply
        voltage (V)."""
        _check_number("motor", "resistance", resistance, "ohm", positive=True)
        _check_number("motor", "torque_constant", torque_constant, "N m/A", positive=True)
        _check_number("motor", "supply_voltage", supply_voltage, "V", positive=True)
        return cls(torque_constant * supply_voltage / resistance, supply_voltage / torque_constant,
                   rotor_inertia, gear_ratio)

    @property
    def back_emf_damping(self) -> float:
        """``c = G^2 stall_torque / no_load_speed`` (N m s/rad at the crank)."""
        return self.gear_ratio ** 2 * self.stall_torque / self.no_load_speed

    @property
    def peak_command(self) -> float:
        """The largest command at the crank, ``G stall_torque`` (N m): full supply voltage."""
        return self.gear_ratio * self.stall_torque

    @property
    def reflected_inertia(self) -> float:
        """The rotor's inertia seen at the crank, ``G^2 rotor_inertia`` (kg m^2)."""
        return self.gear_ratio ** 2 * self.rotor_inertia


@dataclass(frozen=True)
class TorqueDrive:
    """A torque on ``link_b`` of revolute joint ``joint`` (reaction on ``link_a``). The nominal motion
    follows ``PrescribedDrive(joint, rate, offset, harmonics)``; the applied torque is the nominal
    inverse-dynamics torque (the feedforward; ``feedforward=False`` switches it off) plus a PD
    correction on the deviation from it:

        tau = tau_nominal(t) + kp (angle_nominal - angle) + kd (rate_nominal - rate)

    plus what the mechanism's controllers acting at this joint add. Without the feedforward the
    nominal motion is only the reference of the feedback (and the motion the linearisation is
    about): the machine follows it only as closely as the feedback forces it to. ``motor`` (a ``DCMotor`` or
    ``None``: an ideal torque source) adds its back-EMF damping ``c (rate_nominal - rate)`` (its
    feedforward voltage covers the back EMF of the nominal speed) and its rotor inertia;
    ``flywheel`` (kg m^2) is an inertia on ``link_b`` about the joint. The torque saturates at
    ``+-torque_limit`` (N m) and, with a motor, where the command reaches the supply voltage
    (``|tau + c rate| <= G stall_torque``), in nonlinear runs; the linearisation uses the
    unsaturated law and its linear range reports the peak demanded torque against the limits.
    """

    joint: str
    rate: float = 0.0
    offset: float = 0.0
    harmonics: tuple[tuple[int, float, float], ...] = ()
    kp: float = 0.0
    kd: float = 0.0
    motor: DCMotor | None = None
    flywheel: float = 0.0
    torque_limit: float = math.inf
    feedforward: bool = True

    def __post_init__(self) -> None:
        _check_drive(self)
        owner = f"drive at joint {self.joint!r}"
        if not isinstance(self.feedforward, bool):
            raise MechanismError(f"{owner}: feedforward must be true or false, got "
                                 f"{self.feedforward!r}")
        _check_number(owner, "kp", self.kp, "N m/rad", nonnegative=True)
        _check_number(owner, "kd", self.kd, "N m s/rad", nonnegative=True)
        _check_number(owner, "flywheel", self.flywheel, "kg m^2", nonnegative=True)
        if not (self.torque_limit == math.inf or (_is_number(self.torque_limit)
                                                 and self.torque_limit > 0)):
            raise MechanismError(f"{owner}: torque_limit must be a positive number (N m), got "
                                 f"{self.torque_limit!r}")
        if self.motor is not None and not isinstance(self.motor, DCMotor):
            raise MechanismError(f"{owner}: motor must be a DCMotor or None, got {self.motor!r}")

    @property
    def inertia(self) -> float:
        """Inertia (kg m^2) turning with ``link_b`` about the joint: the motor's rotor through its
        gear and the flywheel."""
        return self.flywheel + (self.motor.reflected_inertia if self.motor is not None else 0.0)

    angle = _drive_angle


Drive = Union[PrescribedDrive, TorqueDrive]


# ---------------------------------------------------------------------------------------------------
# Controllers: what they add to the torque of the TorqueDrive at their joint
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PDController:
    """PD on the driven angle of the torque drive at ``joint`` (the thesis's case): adds
    ``kp (angle_nominal - angle) + kd (rate_nominal - rate)`` (N m) to its torque."""

    TYPE: ClassVar[str] = "pd"
    KEYS: ClassVar[tuple[str, ...]] = ("type", "joint", "kp", "kd", "lag")

    name: str
    joint: str
    kp: float = 0.0
    kd: float = 0.0
    lag: float = 0.0

    def __post_init__(self) -> None:
        _check_name("controller", self.name)
        owner = f"controller {self.name!r}"
        _check_number(owner, "kp", self.kp, "N m/rad", nonnegative=True)
        _check_number(owner, "kd", self.kd, "N m s/rad", nonnegative=True)
        _check_lag(owner, self.lag)

    @classmethod
    def from_table(cls, name: str, table) -> "PDController":
        return cls(name, table.string("joint"), table.number("kp", "N m/rad", 0.0, nonnegative=True),
                   table.number("kd", "N m s/rad", 0.0, nonnegative=True), _lag_of(table))

    def to_table(self) -> dict[str, Any]:
        return {"type": self.TYPE, "joint": self.joint, "kp": self.kp, "kd": self.kd,
                **_lag_entry(self.lag)}


@dataclass(frozen=True)
class ObservableFeedback:
    """Feedback of a measured elastic quantity to the torque drive at ``joint``: adds
    ``-(gain o + rate_gain o')`` (N m) to its torque, ``o`` the observable ``observable`` (e.g.
    ``"coupler.strain@0.5"``, the strain a gauge at midspan reads; its unit sets those of the
    gains) and ``o'`` its time derivative. The observable must be a linear function of the elastic
    coordinates alone (deflection, slope, curvature, strain of a link), so that it is zero on the
    rigid nominal motion and the feedback vanishes there."""

    TYPE: ClassVar[str] = "feedback"
    KEYS: ClassVar[tuple[str, ...]] = ("type", "joint", "observable", "gain", "rate_gain", "lag")

    name: str
    joint: str
    observable: str
    gain: float = 0.0
    rate_gain: float = 0.0
    lag: float = 0.0

    def __post_init__(self) -> None:
        _check_name("controller", self.name)
        owner = f"controller {self.name!r}"
        if not isinstance(self.observable, str) or not self.observable:
            raise MechanismError(f"{owner}: observable must be an observable spec such as "
                                 f"'coupler.strain@0.5', got {self.observable!r}")
        _check_number(owner, "gain", self.gain, "N m per unit of the observable")
        _check_number(owner, "rate_gain", self.rate_gain, "N m s per unit of the observable")
        _check_lag(owner, self.lag)

    @classmethod
    def from_table(cls, name: str, table) -> "ObservableFeedback":
        return cls(name, table.string("joint"), table.string("observable"),
                   table.number("gain", "N m per unit of the observable", 0.0),
                   table.number("rate_gain", "N m s per unit of the observable", 0.0), _lag_of(table))

    def to_table(self) -> dict[str, Any]:
        return {"type": self.TYPE, "joint": self.joint, "observable": self.observable,
                "gain": self.gain, "rate_gain": self.rate_gain, **_lag_entry(self.lag)}


# A controller's ``lag`` (s): the time constant of a first-order lag ``lag y' + y = u`` between its
# law ``u`` and the torque ``y`` it adds (0: none).  For these linear laws a sensor lag (the measured
# signal filtered, its rate taken from the filtered signal) is the same transfer function, so one
# key serves both.
def _check_lag(owner: str, lag: object) -> None:
    _check_number(owner, "lag", lag, "s", nonnegative=True)


def _lag_of(table) -> float:
    return table.number("lag", "s", 0.0, nonnegative=True)


def _lag_entry(lag: float) -> dict[str, float]:
    """The ``lag`` key of a controller's table: written only when there is a lag (older tables stay
    as they were)."""
    return {"lag": lag} if lag else {}


Controller = Union[PDController, ObservableFeedback]
#: The controller classes by their scene-file ``type``.
CONTROLLER_TYPES: dict[str, type] = {cls.TYPE: cls for cls in (PDController, ObservableFeedback)}


# ---------------------------------------------------------------------------------------------------
# The mechanism
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Mechanism:
    """An immutable planar mechanism, validated when it is made.

    ``initial_angles`` maps link names to a guess of their frame angle at ``t = 0`` (rad), used to pick
    the assembly branch. ``period`` (s) defaults to ``2 pi / |rate|`` of the first drive; every drive's
    ``rate * period`` must be a whole number of turns so that the nominal motion is periodic.

    ``spec`` is the scene description (the TOML tables as a dict) the mechanism was built from, kept
    so that ``with_parameter("links.coupler.thickness", 2e-3)`` rebuilds it with every derived
    quantity (area, I, Rayleigh beta from a damping ratio) recomputed; ``None`` for mechanisms made
    from parts. ``studies`` is the scene's raw ``[studies]`` table, kept for the ``studies`` package
    and not interpreted here.
    """

    name: str
    links: tuple[Link, ...]
    joints: tuple[Joint, ...]
    drives: tuple[Drive, ...]
    point_masses: tuple[PointMass, ...] = ()
    gravity: tuple[float, float] = (0.0, 0.0)
    initial_angles: Mapping[str, float] = field(default_factory=dict)
    period: float | None = None
    controllers: tuple[Controller, ...] = ()
    spec: Mapping[str, Any] | None = field(default=None, compare=False, repr=False)
    studies: Mapping[str, Any] = field(default_factory=dict, compare=False, repr=False)
    period_is_default: bool = field(default=False, init=False, compare=False, repr=False)

    def __post_init__(self) -> None:
        for key in ("links", "joints", "drives", "point_masses", "controllers"):
            object.__setattr__(self, key, tuple(getattr(self, key)))
        object.__setattr__(self, "gravity", tuple(self.gravity))
        _validate(self)

    # --- lookup ---------------------------------------------------------------------------------------
    def link(self, name: str) -> Link:
        """The link called ``name``."""
        for link in self.links:
            if link.name == name:
                return link
        raise KeyError(f"no link {name!r}; links are {[l.name for l in self.links]}")

    def joint(self, name: str) -> Joint:
        """The joint called ``name``."""
        for joint in self.joints:
            if joint.name == name:
                return joint
        raise KeyError(f"no joint {name!r}; joints are {[j.name for j in self.joints]}")

    # --- variants for sweeps --------------------------------------------------------------------------
    def replace(self, **changes: Any) -> "Mechanism":
        """A new validated mechanism with dataclass fields replaced (``links=..., period=...``).

        The result carries no ``spec`` (it would no longer describe it); to change one scene
        parameter and keep derived quantities consistent use ``with_parameter``.
        """
        unknown = set(changes) - {f.name for f in dataclasses.fields(self) if f.init}
        if unknown:
            raise TypeError(f"Mechanism.replace() got unknown fields {sorted(unknown)}")
        if "period" not in changes and self.period_is_default:
            changes["period"] = None  # recompute from the (possibly new) drives
        changes.setdefault("spec", None)
        return dataclasses.replace(self, **changes)

    def with_parameter(self, path: str, value: Any) -> "Mechanism":
        """A new validated mechanism with one scene parameter changed, named by its dotted path in
        the scene file, e.g. ``"drive.rate"``, ``"links.coupler.thickness"``,
        ``"links.coupler.damping.ratio"``, ``"gravity"``. Derived quantities are recomputed."""
        return self.with_parameters({path: value})

    def with_parameters(self, changes: Mapping[str, Any]) -> "Mechanism":
        """Like ``with_parameter`` for several ``{path: value}`` at once."""
        from ._load import build, set_path, to_spec

        spec = to_spec(self)
        for path, value in changes.items():
            spec = set_path(spec, path, value)
        return build(spec, source=f"{self.name} with {dict(changes)}")

    def without_feedback(self) -> "Mechanism":
        """The same machine with every feedback removed: the torque drives' ``kp``, ``kd`` set to 0
        and the controllers dropped; the feedforward torque and the motors (characteristic, rotor
        inertia, gear), flywheels and torque limits kept."""
        if self.spec is not None:
            from ._load import build, without_feedback_spec

            return build(without_feedback_spec(self.spec),
                         source=f"{self.name} without feedback")
        drives = tuple(dataclasses.replace(d, kp=0.0, kd=0.0) if isinstance(d, TorqueDrive) else d
                       for d in self.drives)
        return self.replace(drives=drives, controllers=())

    def to_spec(self) -> dict[str, Any]:
        """The scene description as nested dicts (what ``mechanisms.build`` takes)."""
        from ._load import to_spec

        return to_spec(self)

    def to_toml(self) -> str:
        """The scene as TOML text that ``mechanisms.load`` reads back to an equal mechanism."""
        from ._load import dumps

        return dumps(self.to_spec())


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


def _by_name(parts: tuple, types: tuple[type, ...], kind: str) -> dict[str, Any]:
    """Parts keyed by their names, checking their types and that no name repeats."""
    named: dict[str, Any] = {}
    for part in parts:
        if not isinstance(part, types):
            raise MechanismError(f"{kind}s must be {' or '.join(t.__name__ for t in types)}, got "
                                 f"{part!r}")
        if part.name in named:
            raise MechanismError(f"duplicate {kind} name {part.name!r}")
        named[part.name] = part
    return named


def _validate(mech: Mechanism) -> None:
    """Checks how the parts fit together; each failure names the part and the fix."""
    if not isinstance(mech.name, str) or not mech.name:
        raise MechanismError(f"mechanism name must be a non-empty string, got {mech.name!r}")
    if not mech.links:
        raise MechanismError(f"mechanism {mech.name!r} has no links")
    links: dict[str, Link] = _by_name(mech.links, (RigidLink, ElasticLink), "link")

    def known_link(owner: str, name: str) -> Link:
        if name not in links:
            close = difflib.get_close_matches(str(name), list(links) + [GROUND], n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise MechanismError(f"{owner} names unknown link {name!r} (links: {list(links)}, or "
                                 f"{GROUND!r}){hint}")
        return links[name]

    joints: dict[str, Joint] = _by_name(mech.joints, tuple(JOINT_TYPES.values()), "joint")
    neighbours: dict[str, set[str]] = {name: set() for name in links}
    grounded: set[str] = set()
    for joint in mech.joints:
        owner = f"joint {joint.name!r}"
        ends = joint.ends
        for link_name, point in ends:
            _pin_position(known_link(owner, link_name), point, owner)
        if len(ends) == 1:  # the other side is the ground
            grounded.add(ends[0][0])
        for (first, _), (second, _) in zip(ends, ends[1:]):
            neighbours[first].add(second)
            neighbours[second].add(first)

    driven: set[str] = set()
    for drive in mech.drives:
        if not isinstance(drive, (PrescribedDrive, TorqueDrive)):
            raise MechanismError(f"drives must be PrescribedDrive or TorqueDrive, got {drive!r}")
        joint = joints.get(drive.joint)
        if not isinstance(joint, Revolute):
            raise MechanismError(f"drive names joint {drive.joint!r}, which is not a revolute joint "
                                 f"of the mechanism (revolute joints: "
                                 f"{[j.name for j in mech.joints if isinstance(j, Revolute)]})")
        if drive.joint in driven:
            raise MechanismError(f"joint {drive.joint!r} is driven twice")
        driven.add(drive.joint)
    if not mech.drives:
        raise MechanismError(f"mechanism {mech.name!r} has no drive; add a PrescribedDrive or "
                             f"TorqueDrive at the crank joint")

    torque_joints = [d.joint for d in mech.drives if isinstance(d, TorqueDrive)]
    _by_name(mech.controllers, tuple(CONTROLLER_TYPES.values()), "controller")
    for controller in mech.controllers:
        if controller.joint not in torque_joints:
            raise MechanismError(f"controller {controller.name!r} names joint {controller.joint!r}, "
                                 f"which has no torque drive (torque drives act at "
                                 f"{torque_joints}); a controller adds to a torque drive's torque")

    for pm in mech.point_masses:
        owner = f"point mass on {pm.link!r}"
        _pin_position(known_link(owner, pm.link), pm.point, owner)
    _check_pair(f"mechanism {mech.name!r}", "gravity", mech.gravity, "m/s^2")
    for name, angle in mech.initial_angles.items():
        known_link("initial_angles", name)
        _check_number("initial_angles", name, angle, "rad")

    # Every link must hang together with the ground, else it floats freely.
    reached, frontier = set(grounded), list(grounded)
    while frontier:
        for other in neighbours[frontier.pop()] - reached:
            reached.add(other)
            frontier.append(other)
    floating = [name for name in links if name not in reached]
    if floating:
        raise MechanismError(f"links {floating} are not connected to the ground by joints")

    # Mobility (Gruebler): the rigid coordinates (3 per link) must be fixed by the joints and drives,
    # so that the nominal motion is determined and the rigid subsystem is square.
    n_rigid = 3 * len(mech.links)
    n_equations = sum(j.n_equations for j in mech.joints) + len(mech.drives)
    if n_equations != n_rigid:
        mobility = n_rigid - n_equations + len(mech.drives)
        raise MechanismError(
            f"linkage {mech.name!r} cannot be assembled as a driven mechanism: {len(mech.links)} "
            f"links have {n_rigid} rigid coordinates but the joints and drives give {n_equations} "
            f"constraint equations (mobility {mobility} with {len(mech.drives)} drive(s)); "
            f"{'add' if n_equations < n_rigid else 'remove'} joints or drives so that they match")

    # Period: default from the first drive; all drives must repeat over it.
    period, is_default = mech.period, mech.period is None
    if is_default:
        rate = mech.drives[0].rate
        if rate == 0.0:
            raise MechanismError(f"mechanism {mech.name!r}: the first drive has rate 0, so give the "
                                 f"period of its motion explicitly (period = ... s)")
        period = 2.0 * math.pi / abs(rate)
    _check_number(f"mechanism {mech.name!r}", "period", period, "s", positive=True)
    for drive in mech.drives:
        turns = drive.rate * period / (2.0 * math.pi)
        if not abs(turns) <= MAX_TURNS:  # also inf from an overflowing product
            raise MechanismError(f"drive at joint {drive.joint!r}: rate {drive.rate} rad/s with period "
                                 f"{period:.6g} s turns {abs(turns):.3g} times per period; at most "
                                 f"{MAX_TURNS} (one period is resolved by the studies' n_steps and "
                                 f"scanned at 4096 crank angles per turn): give a shorter period")
        if abs(turns - round(turns)) > 1e-9 * max(1.0, abs(turns)):
            raise MechanismError(f"drive at joint {drive.joint!r}: rate {drive.rate} rad/s turns "
                                 f"{turns:.6g} times per period {period:.6g} s; the nominal motion "
                                 f"is periodic only for a whole number of turns")
    object.__setattr__(mech, "period", float(period))
    object.__setattr__(mech, "period_is_default", is_default)

    _check_four_bar(mech, links, joints)


def _check_four_bar(mech: Mechanism, links: dict[str, Link], joints: dict[str, Joint]) -> None:
    """Grashof for a driven four-bar: the crank must pass every angle it is driven through.

    With crank pin O, coupler pin A, rocker pivot C and lengths l_coupler, l_rocker, the loop closes
    exactly when |A - C| lies in [|l_coupler - l_rocker|, l_coupler + l_rocker]. Scanning the crank
    angle over one period finds the first angle where it does not (a non-Grashof linkage, or a
    Grashof one whose crank is not the shortest link); touching the bound is a toggle, where the
    constraint Jacobian is singular (a change-point linkage, s + l = p + q).
    """
    revolutes = [j for j in mech.joints if isinstance(j, Revolute)]
    if len(mech.links) != 3 or len(revolutes) != 4 or len(mech.drives) != 1:
        return
    ground_joints = [j for j in revolutes if j.link_a == GROUND]
    drive_joint = joints[mech.drives[0].joint]
    if len(ground_joints) != 2 or drive_joint.link_a != GROUND:
        return
    crank = links[drive_joint.link_b]
    rocker_joint = next(j for j in ground_joints if j is not drive_joint)
    rocker = links[rocker_joint.link_b]
    if rocker is crank:
        return
    coupler = next(link for link in mech.links if link is not crank and link is not rocker)
    inner = [j for j in revolutes if j.link_a != GROUND]

    def pin(link: Link, joint: Revolute) -> tuple[float, float]:
        point = joint.point_a if joint.link_a == link.name else joint.point_b
        return _pin_position(link, point, f"joint {joint.name!r}")

    def side(link_a: Link, link_b: Link) -> Revolute | None:
        return next((j for j in inner if {j.link_a, j.link_b} == {link_a.name, link_b.name}), None)

    crank_coupler, coupler_rocker = side(crank, coupler), side(coupler, rocker)
    if crank_coupler is None or coupler_rocker is None:
        return
    o, c = drive_joint.point_a, rocker_joint.point_a
    crank_vec = [b - a for a, b in zip(pin(crank, drive_joint), pin(crank, crank_coupler))]
    l_coupler = math.dist(pin(coupler, crank_coupler), pin(coupler, coupler_rocker))
    l_rocker = math.dist(pin(rocker, rocker_joint), pin(rocker, coupler_rocker))
    l_crank, l_ground = math.hypot(*crank_vec), math.dist(o, c)
    low, high = abs(l_coupler - l_rocker), l_coupler + l_rocker
    scale = max(l_crank, l_ground, l_coupler, l_rocker)
    drive, period = mech.drives[0], mech.period

    def margin(t: float) -> float:
        theta = drive.angle(t, period)[0]
        ax = o[0] + math.cos(theta) * crank_vec[0] - math.sin(theta) * crank_vec[1]
        ay = o[1] + math.sin(theta) * crank_vec[0] + math.cos(theta) * crank_vec[1]
        d = math.hypot(ax - c[0], ay - c[1])
        return min(d - low, high - d) / scale

    # 4096 samples resolve the crank angle to 0.1 deg per turn; bisection then pins the crossing.
    # The scan is vectorised (it runs whenever a four-bar is made, e.g. at every point of a sweep).
    n_samples = 4096 * max(1, round(abs(drive.rate) * period / (2.0 * math.pi)))
    times = np.linspace(0.0, period, n_samples + 1)
    theta = _drive_angle(drive, times, period)[0]
    d = np.hypot(o[0] + np.cos(theta) * crank_vec[0] - np.sin(theta) * crank_vec[1] - c[0],
                 o[1] + np.sin(theta) * crank_vec[0] + np.cos(theta) * crank_vec[1] - c[1])
    margins = np.minimum(d - low, high - d) / scale
    lengths = sorted([l_crank, l_ground, l_coupler, l_rocker])
    grashof = (f"lengths crank {l_crank:.6g}, coupler {l_coupler:.6g}, rocker {l_rocker:.6g}, "
               f"ground {l_ground:.6g} m: s + l = {lengths[0] + lengths[3]:.6g} m, p + q = "
               f"{lengths[1] + lengths[2]:.6g} m")
    if margins[0] <= 0.0:
        raise MechanismError(f"four-bar {mech.name!r} cannot be assembled at crank angle "
                             f"{math.degrees(drive.angle(0.0, period)[0]):.2f} deg (t = 0): the "
                             f"coupler and rocker cannot reach ({grashof})")
    ratio = (math.sqrt(5.0) - 1.0) / 2.0

    def refined_minimum(k: int) -> tuple[float, float]:
        # Golden-section search of the margin's minimum between the samples around k.
        t_low, t_high = times[max(k - 1, 0)], times[min(k + 1, n_samples)]
        for _ in range(80):
            t_1, t_2 = t_high - ratio * (t_high - t_low), t_low + ratio * (t_high - t_low)
            t_low, t_high = (t_low, t_2) if margin(t_1) < margin(t_2) else (t_1, t_high)
        return margin(t_high), t_high

    opened = np.flatnonzero(margins < 0.0)
    if opened.size:
        k_open = int(opened[0])
        # The loop opens: bisect for the first angle where it no longer closes.
        kind = "the coupler and rocker cannot reach beyond it"
        t_low, t_high = times[k_open - 1], times[k_open]
        for _ in range(60):
            t_mid = 0.5 * (t_low + t_high)
            t_low, t_high = (t_mid, t_high) if margin(t_mid) > 0.0 else (t_low, t_mid)
    else:
        # A toggle touches margin 0 without crossing, between samples: refine every local minimum
        # of the samples. 1e-9 of the largest length is far below any physical clearance and far
        # above rounding (1e-16).
        inner_margins = margins[1:-1]
        candidates = np.flatnonzero((inner_margins <= margins[:-2]) & (inner_margins <= margins[2:])
                                    & (inner_margins < 1e-3)) + 1
        minima = [refined_minimum(int(k)) for k in candidates]
        toggles = [t for value, t in minima if value <= 1e-9]
        if not toggles:
            return
        kind = ("toggle: the constraint Jacobian of joints "
                f"{crank_coupler.name!r}, {coupler_rocker.name!r} is singular there")
        t_high = toggles[0]
    angle = drive.angle(t_high, period)[0]
    raise MechanismError(
        f"four-bar {mech.name!r}: the crank cannot turn fully; it fails at crank angle "
        f"{math.degrees(angle):.2f} deg (t = {t_high:.6g} s), {kind}. Grashof needs s + l <= p + q "
        f"with the crank the shortest link (or the ground shortest), strictly for no toggle; "
        f"{grashof}")
