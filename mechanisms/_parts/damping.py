"""Damping of the elastic coordinates of a link."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Union

from .checks import MechanismError, _check_number


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

