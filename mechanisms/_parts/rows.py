"""The vocabulary of constraint rows a joint is made of, each one a term the numba kernels read.

A joint (``mechanisms/_parts/joints.py``) returns its rows from ``constraint_rows()``; the assembler
(``_assemble``) asks each row to ``store`` itself through a small writer that puts the row's terms
in the kernels' tables, so a new kind of joint composed of these rows needs no new kernel and no
edit of the assembler. The rows, with ``r_i`` the world position (m) of the material point
``point_i`` of link ``link_i`` (it moves with the link's elastic deformation) and
``theta_i + w_i'(x_i)`` the material angle (rad) of the section there:

* ``PointRow``: ``Phi = sum_i d_i . r_i + constant`` (m), a linear combination of points' positions.
  A pin is two of them (``r_a - r_b`` along x and y), a point on a ground line one
  (``n . r - n . origin``). Kernel term: ``ct_int``/``ct_real`` (``_kernels``, a point term).
* ``AngleRow``: ``Phi = sum_i c_i (theta_i + w_i'(x_i)) + constant`` (rad), a linear relation
  between material angles (a gear pair, a fixed relative angle). Linear in ``s``: a row of
  ``h_lin`` and ``phi0``, with a constant Jacobian and no acceleration or force-Jacobian term.

Each row names its ``label``: the constraint is labelled ``"<joint>.<label>"``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

from .checks import MechanismError, PointRef, _check_number, _check_pair, _is_number


class RowWriter(Protocol):
    """What a row may put in the assembled constraint tables (``_assemble`` implements it)."""

    def point_term(self, row: int, link: str, point: PointRef, direction: tuple[float, float]
                   ) -> None:
        """``Phi[row] += direction . r(link, point)``."""

    def angle_term(self, row: int, link: str, point: PointRef, coefficient: float) -> None:
        """``Phi[row] += coefficient (theta + w'(x))`` of the link's section at ``point``."""

    def constant(self, row: int, value: float) -> None:
        """``Phi[row] += value``."""


@dataclass(frozen=True)
class PointTerm:
    """``direction . r``: the world position ``r`` (m) of material point ``point`` of link ``link``
    along ``direction`` (a pair, 1)."""

    link: str
    point: PointRef
    direction: tuple[float, float]

    def __post_init__(self) -> None:
        _check_pair(f"point term on link {self.link!r}", "direction", self.direction, "1")


@dataclass(frozen=True)
class AngleTerm:
    """``coefficient (theta + w'(x))``: the material angle (rad) of link ``link``'s section at
    ``point`` times ``coefficient`` (1)."""

    link: str
    point: PointRef
    coefficient: float

    def __post_init__(self) -> None:
        _check_number(f"angle term on link {self.link!r}", "coefficient", self.coefficient, "1")


def _check_row(kind: str, label: object, terms: tuple, term_type: type, constant: object) -> None:
    if not isinstance(label, str) or not label or "." in label:
        raise MechanismError(f"{kind}: label must be a non-empty word without dots, got {label!r}")
    if not terms or not all(isinstance(term, term_type) for term in terms):
        raise MechanismError(f"{kind} {label!r}: terms must be a non-empty tuple of "
                             f"{term_type.__name__}, got {terms!r}")
    if not _is_number(constant):
        raise MechanismError(f"{kind} {label!r}: constant must be a number, got {constant!r}")


@dataclass(frozen=True)
class PointRow:
    """One constraint ``sum_i d_i . r_i + constant = 0`` (m) on points' world positions."""

    label: str
    terms: tuple[PointTerm, ...]
    constant: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "terms", tuple(self.terms))
        _check_row("PointRow", self.label, self.terms, PointTerm, self.constant)

    unit = "m"

    def store(self, writer: RowWriter, row: int) -> None:
        writer.constant(row, float(self.constant))
        for term in self.terms:
            writer.point_term(row, term.link, term.point, tuple(float(d) for d in term.direction))


@dataclass(frozen=True)
class AngleRow:
    """One constraint ``sum_i c_i (theta_i + w_i'(x_i)) + constant = 0`` (rad) on material
    angles."""

    label: str
    terms: tuple[AngleTerm, ...]
    constant: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "terms", tuple(self.terms))
        _check_row("AngleRow", self.label, self.terms, AngleTerm, self.constant)

    unit = "rad"

    def store(self, writer: RowWriter, row: int) -> None:
        writer.constant(row, float(self.constant))
        for term in self.terms:
            writer.angle_term(row, term.link, term.point, float(term.coefficient))
