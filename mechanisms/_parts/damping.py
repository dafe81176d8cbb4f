"""Damping of the elastic coordinates of a link (``ElasticLink.damping``).

Each kind is a frozen class that carries what the rest of ``mechanisms`` needs of it, and nothing
else asks which kind a link has: ``TYPE`` and ``KEYS`` (its ``damping`` table in a scene),
``from_table(table, link)`` and ``to_table()``, ``strain_rate_beta`` (the Kelvin-Voigt coefficient
``beta`` (s) a link with geometric stiffening applies to its projected strain rates, ``_kernels``
eq. 7-9; 0 for none), ``constant_on_stiffened`` (a constant matrix that on a stiffened link also
damps the chord shortening's axial motion: the assembler warns) and ``constant_matrix(link_name,
m_ee, k_ee, *, strain_rate_beta)``, the constant damping matrix ``C0`` (N s/m) of the link's elastic
coordinates, and ``matrix_derivative(key, link, m_ee, k_ee)``, the derivative of the linearised
damping matrix of the link's elastic coordinates with respect to the scalar scene key ``key`` of its
``damping`` table (None where the kind has no closed form for that key: the sensitivities then take
differences of linearisations), and ``modulus_derivative(link, m_ee, k_ee)``, its derivative with
respect to the link's Young's modulus ``E`` (``K_ee`` is proportional to ``E``, ``M_ee`` does not
depend on it), and optionally ``section_derivative(link, m_ee, k_ee, d_mass, d_stiffness,
d_log_frequency)``, its derivative with respect to a section parameter that changes ``M_ee`` by
``d_mass``, ``K_ee`` by ``d_stiffness`` and the link's first bending frequency by ``d_log_frequency``
(relative), per unit of the parameter, as the scene rebuilt at the new value would give it (None, or
no such method, where the kind is not affine in them: the sensitivities then difference). ``DAMPING_TYPES``
lists them by ``TYPE``; a scene's ``type = "none"`` is no damping.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar, Union

import numpy as np
from scipy.linalg import eigh

from .checks import MechanismError, _check_number


@dataclass(frozen=True)
class Rayleigh:
    """Rayleigh damping, units 1/s and s: ``alpha M_ee`` on a link's elastic coordinates plus
    Kelvin-Voigt damping ``beta``, a damping stress ``beta E`` times the strain rate of bending and
    of axial (membrane) strain. Without geometric stiffening that is ``beta K_ee``; with it, it acts
    on the rate of the projected membrane strain, so a bent link shortening its chord is not damped
    as if it were stretched (equal to ``beta K_ee`` at zero deflection, hence in the linearisation).
    In a scene, ``ratio`` instead of ``alpha`` and ``beta``: ``beta = 2 ratio / omega_1``, the
    stiffness-proportional damping with that ratio at the link's first bending frequency (``ratio``
    then records it: ``beta`` follows the frequency, hence ``E``, when the scene is rebuilt)."""

    alpha: float = 0.0
    beta: float = 0.0
    # the scene's ratio that beta was made from (None: beta given); not part of the kind's identity,
    # which is alpha and beta
    ratio: float | None = field(default=None, compare=False, repr=False)

    TYPE: ClassVar[str] = "rayleigh"
    KEYS: ClassVar[tuple[str, ...]] = ("type", "alpha", "beta", "ratio")
    constant_on_stiffened: ClassVar[bool] = False

    def __post_init__(self) -> None:
        _check_number("Rayleigh", "alpha", self.alpha, "1/s", nonnegative=True)
        _check_number("Rayleigh", "beta", self.beta, "s", nonnegative=True)

    @classmethod
    def from_table(cls, table, link) -> "Rayleigh":
        if table.has("ratio"):
            if table.has("beta") or table.has("alpha"):
                raise MechanismError(f"{table.path}: give either ratio (stiffness-proportional "
                                     f"damping with that ratio at the first bending frequency) or "
                                     f"alpha and beta, not both")
            # C = beta K gives the ratio beta omega / 2 at omega: beta = 2 zeta / omega_1.
            ratio = table.number("ratio", "1", nonnegative=True)
            return cls(0.0, 2.0 * ratio / link.first_bending_frequency(), ratio=ratio)
        return cls(table.number("alpha", "1/s", 0.0, nonnegative=True),
                   table.number("beta", "s", 0.0, nonnegative=True))

    def to_table(self) -> dict[str, Any]:
        # made from a ratio: written as one, so that a rebuilt link (another E, density, section) gets
        # its beta from its own first frequency, as modulus_derivative assumes
        if self.ratio is not None:
            return {"type": self.TYPE, "ratio": self.ratio}
        return {"type": self.TYPE, "alpha": self.alpha, "beta": self.beta}

    @property
    def strain_rate_beta(self) -> float:
        return float(self.beta)

    def constant_matrix(self, link_name: str, m_ee: np.ndarray, k_ee: np.ndarray, *,
               strain_rate_beta: bool) -> np.ndarray:
        """``alpha M + beta K``; with ``strain_rate_beta`` the strain points carry ``beta``."""
        if strain_rate_beta:
            return self.alpha * m_ee
        return self.alpha * m_ee + self.beta * k_ee

    def matrix_derivative(self, key: str, link, m_ee: np.ndarray, k_ee: np.ndarray) -> np.ndarray | None:
        """d(linearised damping of the elastic coordinates)/d ``key``: ``M_ee`` for ``alpha``, ``K_ee``
        for ``beta`` (the strain-rate form linearises to ``beta K_ee`` too), ``2 K_ee / omega_1`` for
        ``ratio`` (``beta = 2 ratio / omega_1``, ``link.first_bending_frequency()``); None for others."""
        if key == "alpha":
            return m_ee
        if key == "beta":
            return k_ee
        if key == "ratio":
            return (2.0 / link.first_bending_frequency()) * k_ee
        return None

    def modulus_derivative(self, link, m_ee: np.ndarray, k_ee: np.ndarray) -> np.ndarray:
        """d(linearised damping)/dE with ``K_ee`` proportional to ``E``: ``beta K_ee / E`` for a
        given ``beta``; with a ``ratio``, ``beta = 2 ratio / omega_1`` falls as ``E^-1/2`` (``omega_1``
        grows as ``sqrt(E)``), so ``beta K_ee`` grows as ``sqrt(E)``: ``beta K_ee / (2 E)``."""
        share = 0.5 if self.ratio is not None else 1.0
        return (share * self.beta / link.youngs_modulus) * k_ee

    def section_derivative(self, link, m_ee: np.ndarray, k_ee: np.ndarray, d_mass: np.ndarray,
                           d_stiffness: np.ndarray, d_log_frequency: float) -> np.ndarray:
        """d(``alpha M_ee + beta K_ee``) for changes ``d_mass``, ``d_stiffness`` of ``M_ee``, ``K_ee`` (kg,
        N/m per unit of the parameter): ``alpha dM + beta dK``, and with a ``ratio`` also ``beta``'s own
        change, ``beta = 2 ratio / omega_1`` moving by ``-beta d ln omega_1`` (``d_log_frequency``)."""
        change = self.alpha * d_mass + self.beta * d_stiffness
        if self.ratio is not None:
            change = change - (self.beta * d_log_frequency) * k_ee
        return change


@dataclass(frozen=True)
class ModalDamping:
    """Damping ratios of the link's own modes (free-floating frame held fixed), lowest first; the
    modes past the last ratio given are undamped."""

    ratios: tuple[float, ...] = ()

    TYPE: ClassVar[str] = "modal"
    KEYS: ClassVar[tuple[str, ...]] = ("type", "ratios")
    constant_on_stiffened: ClassVar[bool] = True
    strain_rate_beta: ClassVar[float] = 0.0

    def __post_init__(self) -> None:
        for i, ratio in enumerate(self.ratios):
            _check_number("ModalDamping", f"ratios[{i}]", ratio, "1", nonnegative=True)

    @classmethod
    def from_table(cls, table, link) -> "ModalDamping":
        ratios = table.raw("ratios")
        if not isinstance(ratios, list):
            raise MechanismError(f"{table.path}.ratios must be a list of damping ratios, got "
                                 f"{ratios!r}")
        return cls(tuple(ratios))

    def to_table(self) -> dict[str, Any]:
        return {"type": self.TYPE, "ratios": list(self.ratios)}

    def matrix_derivative(self, key: str, link, m_ee: np.ndarray, k_ee: np.ndarray) -> None:
        """No closed form for a scalar key (its entries are lists): the sensitivities difference."""
        return None

    def modulus_derivative(self, link, m_ee: np.ndarray, k_ee: np.ndarray) -> np.ndarray:
        """d(damping)/dE: the modes do not change with ``E`` (``K_ee`` scales with it) and each
        ``omega`` grows as ``sqrt(E)``, so the matrix does too: ``C0 / (2 E)``."""
        return self.constant_matrix(link.name, m_ee, k_ee, strain_rate_beta=False) / (2.0 * link.youngs_modulus)

    def section_derivative(self, link, m_ee: np.ndarray, k_ee: np.ndarray, d_mass: np.ndarray,
                           d_stiffness: np.ndarray, d_log_frequency: float) -> None:
        """No closed form: ``M Phi diag(2 zeta omega) Phi^T M`` is not affine in ``M_ee`` and ``K_ee`` (its
        modes move when they change unlike each other): the sensitivities difference linearisations."""
        return None

    def constant_matrix(self, link_name: str, m_ee: np.ndarray, k_ee: np.ndarray, *,
               strain_rate_beta: bool) -> np.ndarray:
        """``M Phi diag(2 zeta omega) Phi^T M`` over the modes given ratios (mass-normalised)."""
        # The number of modes is the discretisation's: checked here, not when the ratios are made.
        n_e = m_ee.shape[0]
        ratios = np.asarray(self.ratios, dtype=float)
        if len(ratios) > n_e:
            raise MechanismError(f"link {link_name!r}: damping.ratios must be at most {n_e} "
                                 f"numbers (one per elastic coordinate); received {self.ratios!r}")
        omega2, modes = eigh(k_ee, m_ee)  # mass-normalised: modes^T M modes = I
        omega = np.sqrt(np.maximum(omega2[:len(ratios)], 0.0))
        mphi = m_ee @ modes[:, :len(ratios)]
        return mphi @ np.diag(2.0 * ratios * omega) @ mphi.T


@dataclass(frozen=True)
class DampingMatrix:
    """An explicit damping matrix on the link's elastic coordinates, N s/m (n_elastic, n_elastic)."""

    matrix: tuple[tuple[float, ...], ...] = ()

    TYPE: ClassVar[str] = "matrix"
    KEYS: ClassVar[tuple[str, ...]] = ("type", "matrix")
    constant_on_stiffened: ClassVar[bool] = True
    strain_rate_beta: ClassVar[float] = 0.0

    def __post_init__(self) -> None:
        n = len(self.matrix)
        for i, row in enumerate(self.matrix):
            if len(row) != n:
                raise MechanismError(f"DampingMatrix: matrix must be square, row {i} has "
                                     f"{len(row)} entries instead of {n}")
            for j, value in enumerate(row):
                _check_number("DampingMatrix", f"matrix[{i}][{j}]", value, "N s/m")

    @classmethod
    def from_table(cls, table, link) -> "DampingMatrix":
        matrix = table.raw("matrix")
        if not isinstance(matrix, list) or not all(isinstance(row, list) for row in matrix):
            raise MechanismError(f"{table.path}.matrix must be a list of rows (N s/m), got "
                                 f"{matrix!r}")
        return cls(tuple(tuple(row) for row in matrix))

    def to_table(self) -> dict[str, Any]:
        return {"type": self.TYPE, "matrix": [list(row) for row in self.matrix]}

    def matrix_derivative(self, key: str, link, m_ee: np.ndarray, k_ee: np.ndarray) -> None:
        """No closed form for a scalar key (its entries are lists): the sensitivities difference."""
        return None

    def modulus_derivative(self, link, m_ee: np.ndarray, k_ee: np.ndarray) -> np.ndarray:
        """An explicit matrix does not depend on ``E``: zero."""
        return np.zeros_like(k_ee)

    def section_derivative(self, link, m_ee: np.ndarray, k_ee: np.ndarray, d_mass: np.ndarray,
                           d_stiffness: np.ndarray, d_log_frequency: float) -> np.ndarray:
        """An explicit matrix does not depend on the section: zero."""
        return np.zeros_like(k_ee)

    def constant_matrix(self, link_name: str, m_ee: np.ndarray, k_ee: np.ndarray, *,
                        strain_rate_beta: bool) -> np.ndarray:
        # its size is the discretisation's, checked here
        n_e = m_ee.shape[0]
        matrix = np.asarray(self.matrix, dtype=float)
        if matrix.shape != (n_e, n_e):
            raise MechanismError(f"link {link_name!r}: damping.matrix must be a ({n_e}, {n_e}) "
                                 f"matrix (one row per elastic coordinate); received shape "
                                 f"{matrix.shape}")
        return matrix


Damping = Union[Rayleigh, ModalDamping, DampingMatrix, None]
#: The kinds of damping a scene's ``damping`` table names by ``type`` (the first is the default).
DAMPING_TYPES: dict[str, type] = {cls.TYPE: cls for cls in (Rayleigh, ModalDamping, DampingMatrix)}
