"""Discretisations of an elastic link (``ElasticLink.discretisation``)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, ClassVar, Union

from .checks import MAX_ELEMENTS, MAX_MODES, MechanismError, _check_count


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

