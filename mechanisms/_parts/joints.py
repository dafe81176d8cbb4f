"""Joints: what holds the links together, each a frozen class that carries its behaviour.

A joint class declares everything the rest of ``mechanisms`` (and ``linearize``) needs of it, and
nothing else names the kinds of joint:

* ``TYPE`` (its scene-file ``type``), ``KEYS`` (its scene-table keys), ``from_table(name, table)``
  and ``to_table()`` (the scene file both ways; ``table`` reads keys with their units and checks,
  ``mechanisms/_parts/table.py``);
* ``name``, ``n_equations`` and ``ends`` (the ``(link, point)`` it joins, the ground left out; a
  joint with one end holds that link to the ground);
* ``constraint_rows()``: its ``n_equations`` rows, made of the row vocabulary (``PointRow``,
  ``AngleRow``: ``mechanisms/_parts/rows.py``), which the kernels read;
* ``force_components()``: ``{component: weights}``, what the observable ``"joint.<name>.<component>"``
  means as a weighted sum of the multipliers of its rows (in the order of its rows), in
  ``force_unit`` (N, or N m for a torque); with both ``fx`` and ``fy``, ``force`` is their
  magnitude;
* ``point_force`` (class attribute): the joint loads each link at its ``ends`` by a point force
  ``-Phi_J,R^T lam_J`` and no moment (what the geometric stiffness of ``linearize`` assumes);
* ``drive_terms()``: the relative angle a drive at the joint turns, as ``AngleTerm`` (the driven
  side first), or ``None`` when no drive can act at it;
* ``coincident_points()``: the two ``(link, point)`` a pin holds together (a ground side as
  ``(GROUND, (x, y))``, on either side), which the nominal motion's initial guess walks, or ``()``.

``register_joint(cls)`` enters a class in ``JOINT_TYPES`` (the scene loader, the ``Mechanism``
checks, the assembler and the observables find it there).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar, Union

from .checks import GROUND, MechanismError, PointRef, _check_name, _check_number, _check_pair, register_class
from .rows import AngleTerm, PointRow, PointTerm

#: The joint classes by their scene-file ``type`` (the first is the default type), filled by
#: ``register_joint``.
JOINT_TYPES: dict[str, type] = {}

_JOINT_INTERFACE = ("TYPE", "KEYS", "from_table", "to_table", "n_equations", "ends",
                    "constraint_rows", "force_components", "point_force", "drive_terms",
                    "coincident_points")


def register_joint(cls: type) -> type:
    """Enter the joint class ``cls`` in ``JOINT_TYPES`` under its ``TYPE`` and return it (usable as
    a class decorator). ``cls`` must declare the interface of the module docstring; a ``TYPE``
    already taken by another class is refused (``MechanismError``)."""
    return register_class(JOINT_TYPES, cls, _JOINT_INTERFACE, "joint", "mechanisms.Revolute")


@register_joint
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
    point_force: ClassVar[bool] = True
    force_unit: ClassVar[str] = "N"

    def constraint_rows(self) -> tuple[PointRow, PointRow]:
        """``Phi = r_a - r_b`` along x and y (rows ``"x"``, ``"y"``); a ground side is its fixed
        point, a constant."""
        rows = []
        for axis, label in enumerate(("x", "y")):
            direction = (1.0 - axis, float(axis))
            terms = [PointTerm(self.link_b, self.point_b, (-direction[0], -direction[1]))]
            constant = 0.0
            if self.link_a == GROUND:
                constant = float(self.point_a[axis])
            else:
                terms.insert(0, PointTerm(self.link_a, self.point_a, direction))
            rows.append(PointRow(label, tuple(terms), constant))
        return tuple(rows)

    def force_components(self) -> dict[str, tuple[float, ...]]:
        """The force (N, global axes) on ``link_b`` from ``link_a``: ``Phi = r_a - r_b``, so it is
        ``-(dPhi/dR_b)^T lam = +lam``."""
        return {"fx": (1.0, 0.0), "fy": (0.0, 1.0)}

    def drive_terms(self) -> tuple[AngleTerm, ...]:
        """The material angle of ``link_b`` at the pin minus that of ``link_a`` (0: the ground)."""
        driven = AngleTerm(self.link_b, self.point_b, 1.0)
        if self.link_a == GROUND:
            return (driven,)
        return (driven, AngleTerm(self.link_a, self.point_a, -1.0))

    def coincident_points(self) -> tuple[tuple[str, Any], tuple[str, Any]]:
        return ((self.link_a, self.point_a), (self.link_b, self.point_b))

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


@register_joint
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
    point_force: ClassVar[bool] = True
    force_unit: ClassVar[str] = "N"

    @property
    def normal(self) -> tuple[float, float]:
        """The unit normal ``n = (-sin angle, cos angle)`` of the line."""
        return (-math.sin(self.angle), math.cos(self.angle))

    def constraint_rows(self) -> tuple[PointRow]:
        """``Phi = n . (r - origin)`` (row ``"n"``)."""
        nx, ny = self.normal
        return (PointRow("n", (PointTerm(self.link, self.point, (nx, ny)),),
                         -(nx * float(self.origin[0]) + ny * float(self.origin[1]))),)

    def force_components(self) -> dict[str, tuple[float, ...]]:
        """The force (N, global axes) on the link from the ground: ``-n lam``."""
        nx, ny = self.normal
        return {"fx": (-nx,), "fy": (-ny,)}

    def drive_terms(self) -> None:
        return None

    def coincident_points(self) -> tuple:
        return ()

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



@register_joint
@dataclass(frozen=True)
class Slot:
    """A pin in a slot: the point ``point_a`` of ``link_a`` moves on the line of ``link_b`` through
    its material point ``point_b`` at angle ``angle`` (rad) to ``link_b``'s frame (the line turns
    with the frame; for an elastic ``link_b`` its chord or root-tangent frame). One constraint
    equation, the distance from the line: ``Phi = n_b . (r_a - r_b)``, ``n_b = A(theta_b) n``,
    ``n = (-sin angle, cos angle)`` (row ``"n"``). Its force ``normal`` (N) is the force on
    ``link_a`` along ``n_b`` (no friction). Not a point force on ``link_b`` (the contact moves along
    it), so a stiffened ``link_b`` refuses it in the geometric stiffness."""

    name: str
    link_a: str
    point_a: PointRef
    link_b: str
    point_b: PointRef = "start"
    angle: float = 0.0

    TYPE: ClassVar[str] = "slot"
    KEYS: ClassVar[tuple[str, ...]] = ("type", "link_a", "point_a", "link_b", "point_b", "angle")
    n_equations: ClassVar[int] = 1
    point_force: ClassVar[bool] = False
    force_unit: ClassVar[str] = "N"

    def __post_init__(self) -> None:
        _check_name("joint", self.name)
        if GROUND in (self.link_a, self.link_b):
            raise MechanismError(f"joint {self.name!r}: a slot joins two links (a slot in the "
                                 f"ground is a slider)")
        if self.link_a == self.link_b:
            raise MechanismError(f"joint {self.name!r} joins link {self.link_a!r} to itself")
        _check_number(f"joint {self.name!r}", "angle", self.angle, "rad")

    @classmethod
    def from_table(cls, name: str, table) -> "Slot":
        return cls(name, table.string("link_a"), table.point("point_a"), table.string("link_b"),
                   table.point("point_b") if table.has("point_b") else "start",
                   table.number("angle", "rad", 0.0))

    def to_table(self) -> dict[str, Any]:
        return {"type": self.TYPE, "link_a": self.link_a, "point_a": self.point_a,
                "link_b": self.link_b, "point_b": self.point_b, "angle": self.angle}

    @property
    def ends(self) -> tuple[tuple[str, PointRef], ...]:
        return ((self.link_a, self.point_a), (self.link_b, self.point_b))

    def constraint_rows(self) -> tuple[PointRow]:
        normal = (-math.sin(self.angle), math.cos(self.angle))
        opposite = (-normal[0], -normal[1])
        return (PointRow("n", (PointTerm(self.link_a, self.point_a, normal, frame=self.link_b),
                               PointTerm(self.link_b, self.point_b, opposite, frame=self.link_b))),)

    def force_components(self) -> dict[str, tuple[float, ...]]:
        """``Phi_{R_a} = n_b^T``: the force on ``link_a`` is ``-n_b lam``, along ``n_b`` ``-lam``."""
        return {"normal": (-1.0,)}

    def drive_terms(self) -> None:
        return None

    def coincident_points(self) -> tuple:
        return ()


Joint = Union[Revolute, Slider, Slot]
