"""Joints: what holds the links together."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, Union

from .checks import GROUND, MechanismError, PointRef, _check_name, _check_number, _check_pair


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

