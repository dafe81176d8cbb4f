"""The vocabulary of constraint rows a joint is made of, each one a term the numba kernels read.

A joint (``mechanisms/_parts/joints.py``) returns its rows from ``constraint_rows()``; the assembler
(``_assemble``) asks each row to ``store`` itself through a small writer that puts the row's terms
in the kernels' tables, so a new kind of joint composed of these rows needs no new kernel and no
edit of the assembler. The rows, with ``r_i`` the world position (m) of the material point
``point_i`` of link ``link_i`` (it moves with the link's elastic deformation) and
``theta_i + w_i'(x_i)`` the material angle (rad) of the section there:

* ``PointRow``: ``Phi = sum_i d_i . r_i + constant`` (m), a linear combination of points' positions.
  A pin is two of them (``r_a - r_b`` along x and y), a point on a ground line one
  (``n . r - n . origin``). A term may hold its direction in a moving link's frame and measure the
  point from that frame's origin (``PointTerm.frame``): a point on a line of a moving link, a pin
  in a slot (``n_f . (r - R_f) - n_loc . c``). Kernel term: ``ct_int``/``ct_real`` (``_kernels``, a
  point term, eq. 10-12 for the frame).
* ``AngleRow``: ``Phi = sum_i c_i (theta_i + w_i'(x_i)) + constant`` (rad), a linear relation
  between material angles (a gear pair, a fixed relative angle). Linear in ``s``: a row of
  ``h_lin`` and ``phi0``, with a constant Jacobian and no acceleration or force-Jacobian term.

Each row names its ``label``: the constraint is labelled ``"<joint>.<label>"``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Protocol

from .checks import MechanismError, PointRef, _check_number, _check_pair, _is_number


class RowWriter(Protocol):
    """What a row may put in the assembled constraint tables (``_assemble`` implements it)."""

    def point_term(self, row: int, link: str, point: PointRef, direction: tuple[float, float],
                   frame: str | None = None) -> None:
        """``Phi[row] += direction . r(link, point)``; with ``frame`` (a link name) the direction
        is fixed in that link's frame and the position taken from its origin:
        ``Phi[row] += (A(theta_f) direction) . (r - R_f)``."""

    def angle_term(self, row: int, link: str, point: PointRef, coefficient: float) -> None:
        """``Phi[row] += coefficient (theta + w'(x))`` of the link's section at ``point``."""

    def constant(self, row: int, value: float) -> None:
        """``Phi[row] += value``."""


@dataclass(frozen=True)
class PointTerm:
    """``direction . r``: the world position ``r`` (m) of material point ``point`` of link ``link``
    along ``direction`` (a pair, 1). With ``frame`` (the name of a link) the direction is fixed in
    that link's (floating) frame and ``r`` is taken from its origin: ``(A(theta_f) direction) .
    (r - R_f)``, the distance of the point from a line of a moving link (a pin in a slot)."""

    link: str
    point: PointRef
    direction: tuple[float, float]
    frame: str | None = None

    def __post_init__(self) -> None:
        _check_pair(f"point term on link {self.link!r}", "direction", self.direction, "1")
        if self.frame is not None and not isinstance(self.frame, str):
            raise MechanismError(f"point term on link {self.link!r}: frame must be a link name "
                                 f"or None, got {self.frame!r}")


@dataclass(frozen=True)
class AngleTerm:
    """``coefficient (theta + w'(x))``: the material angle (rad) of link ``link``'s section at
    ``point`` times ``coefficient`` (1)."""

    link: str
    point: PointRef
    coefficient: float

    def __post_init__(self) -> None:
        _check_number(f"angle term on link {self.link!r}", "coefficient", self.coefficient, "1")


@dataclass(frozen=True)
class _Row:
    """One constraint row: ``sum of its terms + constant = 0``; a subclass names its ``term`` type
    and ``unit`` and stores a term through the writer."""

    label: str
    terms: tuple
    constant: float = 0.0

    term: ClassVar[type]
    unit: ClassVar[str]

    def __post_init__(self) -> None:
        object.__setattr__(self, "terms", tuple(self.terms))
        kind = type(self).__name__
        if not isinstance(self.label, str) or not self.label or "." in self.label:
            raise MechanismError(f"{kind}: label must be a non-empty word without dots, got "
                                 f"{self.label!r}")
        if not self.terms or not all(isinstance(term, self.term) for term in self.terms):
            raise MechanismError(f"{kind} {self.label!r}: terms must be a non-empty tuple of "
                                 f"{self.term.__name__}, got {self.terms!r}")
        if not _is_number(self.constant):
            raise MechanismError(f"{kind} {self.label!r}: constant must be a number, got "
                                 f"{self.constant!r}")

    def store(self, writer: RowWriter, row: int) -> None:
        """Put the row in the assembled tables as constraint ``row``."""
        writer.constant(row, float(self.constant))
        for term in self.terms:
            self._store_term(writer, row, term)

    def _store_term(self, writer: RowWriter, row: int, term) -> None:
        raise NotImplementedError


@dataclass(frozen=True)
class PointRow(_Row):
    """One constraint ``sum_i d_i . r_i + constant = 0`` (m) on points' world positions
    (``terms``: ``PointTerm``)."""

    term: ClassVar[type] = PointTerm
    unit: ClassVar[str] = "m"

    def _store_term(self, writer: RowWriter, row: int, term: PointTerm) -> None:
        writer.point_term(row, term.link, term.point, (float(term.direction[0]),
                                                       float(term.direction[1])), term.frame)


@dataclass(frozen=True)
class AngleRow(_Row):
    """One constraint ``sum_i c_i (theta_i + w_i'(x_i)) + constant = 0`` (rad) on material
    angles (``terms``: ``AngleTerm``)."""

    term: ClassVar[type] = AngleTerm
    unit: ClassVar[str] = "rad"

    def _store_term(self, writer: RowWriter, row: int, term: AngleTerm) -> None:
        writer.angle_term(row, term.link, term.point, float(term.coefficient))
