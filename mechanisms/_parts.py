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
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Mapping, Sequence, Union

GROUND = "ground"

PointRef = Union[str, float]


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


@dataclass(frozen=True)
class UserShapes:
    """Ritz-Galerkin discretisation with shape functions supplied by the user.

    Each callable takes ``(x, length)`` with ``x`` an array in metres and returns a tuple
    ``(value, first_derivative, second_derivative)`` of arrays shaped like ``x``. Bending shapes must
    satisfy the link's boundary conditions (the loader checks them at the ends).
    """

    bending: tuple[Callable, ...] = ()
    axial: tuple[Callable, ...] = ()


@dataclass(frozen=True)
class Fem:
    """Hermite beam finite elements (seed eq. 2.5-2.8): ``n_elements`` equal elements, three DOF per
    node (axial, transverse, rotation), the link's boundary conditions removed."""

    n_elements: int = 1


Discretisation = Union[Ritz, UserShapes, Fem]


# ---------------------------------------------------------------------------------------------------
# Damping of the elastic coordinates
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Rayleigh:
    """``C = alpha M_ee + beta K_ee`` on a link's elastic coordinates; ``beta`` is Kelvin-Voigt
    (stiffness-proportional) damping acting on bending and axial strain; units 1/s and s."""

    alpha: float = 0.0
    beta: float = 0.0


@dataclass(frozen=True)
class ModalDamping:
    """Damping ratios of the link's own modes (free-floating frame held fixed), lowest first; the
    modes past the last ratio given are undamped."""

    ratios: tuple[float, ...] = ()


@dataclass(frozen=True)
class DampingMatrix:
    """An explicit damping matrix on the link's elastic coordinates, N s/m (n_elastic, n_elastic)."""

    matrix: tuple[tuple[float, ...], ...] = ()


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

    @classmethod
    def uniform(cls, name: str, length: float, *, width: float, thickness: float, density: float,
                **kwargs) -> "RigidLink":
        """A uniform bar of rectangular section ``width x thickness`` (m) and ``density`` (kg/m^3)."""
        mass = density * width * thickness * length
        return cls(name=name, length=length, mass=mass, inertia=mass * length**2 / 12.0, **kwargs)


@dataclass(frozen=True)
class ElasticLink:
    """A slender Euler-Bernoulli beam in a floating frame (see the module docstring).

    ``area`` in m^2, ``second_moment`` (I of the section about the bending axis) in m^4, ``density``
    in kg/m^3, ``youngs_modulus`` in Pa.
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
    geometric_stiffening: bool = True  # strain u' + w'^2 / 2; False keeps the seed's eq. 2.13 exactly
    rotary_inertia: bool = False
    damping: Damping = None

    @classmethod
    def rectangular(cls, name: str, length: float, *, width: float, thickness: float,
                    density: float, youngs_modulus: float, **kwargs) -> "ElasticLink":
        """Rectangular section ``width x thickness`` bending about the thin direction:
        ``A = b h``, ``I = b h^3 / 12``."""
        return cls(name=name, length=length, density=density, youngs_modulus=youngs_modulus,
                   area=width * thickness, second_moment=width * thickness**3 / 12.0, **kwargs)

    @property
    def mass(self) -> float:
        return self.density * self.area * self.length

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


# ---------------------------------------------------------------------------------------------------
# Joints
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Revolute:
    """A pin between ``(link_a, point_a)`` and ``(link_b, point_b)``; ``link_a`` may be ``"ground"``,
    then ``point_a`` is ``(x, y)`` in metres. Two constraint equations (x and y)."""

    name: str
    link_a: str
    point_a: PointRef | tuple[float, float]
    link_b: str
    point_b: PointRef


@dataclass(frozen=True)
class Slider:
    """A prismatic slider: a point of a link moves on a ground line through ``origin`` (m) at angle
    ``angle`` (rad) to the x-axis. One constraint equation (normal distance zero)."""

    name: str
    link: str
    point: PointRef
    origin: tuple[float, float] = (0.0, 0.0)
    angle: float = 0.0


Joint = Union[Revolute, Slider]


# ---------------------------------------------------------------------------------------------------
# Drives
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PrescribedDrive:
    """Prescribes the relative rotation at revolute joint ``joint``: the angle of ``link_b``'s material
    tangent minus that of ``link_a`` (ground: absolute angle) follows

        angle(t) = offset + rate t + sum_k (cos_k cos(k w t) + sin_k sin(k w t)),  w = 2 pi / period

    with ``harmonics`` a tuple of ``(k, cos_k, sin_k)``. One constraint equation (rheonomic)."""

    joint: str
    rate: float = 0.0
    offset: float = 0.0
    harmonics: tuple[tuple[int, float, float], ...] = ()


@dataclass(frozen=True)
class TorqueDrive:
    """A torque on ``link_b`` of revolute joint ``joint`` (reaction on ``link_a``). The nominal motion
    follows ``PrescribedDrive(joint, rate, offset, harmonics)``; the applied torque is the nominal
    inverse-dynamics torque plus a PD correction on the deviation from it:

        tau = tau_nominal(t) + kp (angle_nominal - angle) + kd (rate_nominal - rate).
    """

    joint: str
    rate: float = 0.0
    offset: float = 0.0
    harmonics: tuple[tuple[int, float, float], ...] = ()
    kp: float = 0.0
    kd: float = 0.0


Drive = Union[PrescribedDrive, TorqueDrive]


@dataclass(frozen=True)
class Mechanism:
    """An immutable planar mechanism.

    ``initial_angles`` maps link names to a guess of their frame angle at ``t = 0`` (rad), used to pick
    the assembly branch. ``period`` (s) defaults to ``2 pi / |rate|`` of the first drive.
    """

    name: str
    links: tuple[Link, ...]
    joints: tuple[Joint, ...]
    drives: tuple[Drive, ...]
    point_masses: tuple[PointMass, ...] = ()
    gravity: tuple[float, float] = (0.0, 0.0)
    initial_angles: Mapping[str, float] = field(default_factory=dict)
    period: float | None = None
