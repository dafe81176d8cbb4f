"""Ritz-Galerkin discretisations: the thesis's modes (``Ritz``) and shapes given as functions
(``UserShapes``), bending coordinates first, then axial.

* ``Ritz``: pinned-pinned bending ``sin(i pi x / L)`` (seed eq. 2.2), axial
  ``sin((2k-1) pi x / (2L))`` (eq. 2.4); for ``boundary="clamped-free"`` the clamped-free beam
  eigenfunctions ``cosh bx - cos bx - sigma (sinh bx - sin bx)``, ``cos bL cosh bL = -1``.
* ``UserShapes``: the user's callables. In a scene (and so in the studies, the result file and the
  worker pool) each is named ``"module:qualname"`` and imported back: a module-level function of
  an importable module. Naming a function in a scene file imports its module, so load scene files
  from sources you trust as you would run their code.

The shapes are not polynomials: ``_beams`` finds their Gauss rule by doubling the points until the
integrals converge.
"""

from __future__ import annotations

import importlib
import math
from dataclasses import dataclass
from typing import Any, Callable, ClassVar

import numpy as np

from .checks import MAX_MODES, MechanismError, _check_count
from .discretisations import ShapeLayout, ShapeValues, bending_and_axial_labels, register_discretisation
from .fem import MODES_LIMIT


@register_discretisation
@dataclass(frozen=True)
class Ritz:
    """Ritz-Galerkin discretisation with the thesis's modes (seed eq. 2.2 and 2.4).

    Pinned-pinned bending ``X_i(x) = sin(i pi x / L)``, ``i = 1..n_bending``; axial
    ``Y_k(x) = sin((2k - 1) pi x / (2 L))``, ``k = 1..n_axial`` (ignored when the link has no axial
    deformation). For ``clamped-free`` links the clamped-free beam modes are used instead.
    """

    n_bending: int = 2
    n_axial: int = 1

    TYPE: ClassVar[str] = "ritz"
    KEYS: ClassVar[tuple[str, ...]] = ("type", "n_bending", "n_axial")
    COUNT_KEYS: ClassVar[tuple[str, ...]] = ("n_bending", "n_axial")
    check_boundary: ClassVar[bool] = False    # the modes satisfy the boundary conditions exactly

    #: why the mode counts are bounded (``MAX_MODES``)
    LIMIT: ClassVar[str] = MODES_LIMIT

    def __post_init__(self) -> None:
        _check_count("Ritz", "n_bending", self.n_bending, 1, MAX_MODES, self.LIMIT)
        _check_count("Ritz", "n_axial", self.n_axial, 0, MAX_MODES, self.LIMIT)

    @classmethod
    def from_table(cls, table) -> "Ritz":
        return cls(table.integer("n_bending", 2, minimum=1, maximum=MAX_MODES, why=cls.LIMIT),
                   table.integer("n_axial", 1, minimum=0, maximum=MAX_MODES, why=cls.LIMIT))

    def to_table(self) -> dict[str, Any]:
        return {"type": self.TYPE, "n_bending": self.n_bending, "n_axial": self.n_axial}

    def layout(self, link, attachments=None) -> ShapeLayout:
        return ShapeLayout(bending_and_axial_labels(self.n_bending, self.n_axial if link.axial else 0))

    def refined(self) -> "Ritz":
        """Two more bending modes and, where the link has axial modes, two more axial ones (the
        optional refinement of the interface). Adding modes has no element size, so no
        ``convergence_order`` is declared: the mesh term observes the rate from three levels."""
        return Ritz(self.n_bending + 2, self.n_axial + 2 if self.n_axial else 0)

    def values(self, link, x: np.ndarray, basis=None) -> ShapeValues:
        length = link.length
        if link.boundary == "pinned-pinned":
            bending = [_sine(i * math.pi / length, x) for i in range(1, self.n_bending + 1)]
        else:
            bending = [_clamped_free_mode(x, beta_l / length, length)
                       for beta_l in clamped_free_roots(self.n_bending)]
        axial = ([_sine((2 * j - 1) * math.pi / (2 * length), x) for j in range(1, self.n_axial + 1)]
                 if link.axial else [])
        return ShapeValues.from_functions(bending, axial)


def _sine(k: float, x: np.ndarray):
    return np.sin(k * x), k * np.cos(k * x), -k * k * np.sin(k * x)


@register_discretisation
@dataclass(frozen=True)
class UserShapes:
    """Ritz-Galerkin discretisation with shape functions supplied by the user.

    Each callable takes ``(x, length)`` with ``x`` an array in metres and returns a tuple
    ``(value, first_derivative, second_derivative)`` of arrays shaped like ``x``. Bending shapes must
    satisfy the link's boundary conditions (checked at the ends when the link is assembled). In a
    scene table (``type = "user"``) each callable is the string ``"module:qualname"`` of a
    module-level function, imported when the scene is read; a lambda or a nested function cannot be
    written to a scene (``to_table`` says so).
    """

    bending: tuple[Callable, ...] = ()
    axial: tuple[Callable, ...] = ()

    TYPE: ClassVar[str] = "user"
    KEYS: ClassVar[tuple[str, ...]] = ("type", "bending", "axial")
    check_boundary: ClassVar[bool] = True

    def __post_init__(self) -> None:
        object.__setattr__(self, "bending", tuple(self.bending))
        object.__setattr__(self, "axial", tuple(self.axial))
        if not self.bending or not all(callable(f) for f in self.bending + self.axial):
            raise MechanismError("UserShapes: bending must be a non-empty tuple of callables and "
                                 "axial a tuple of callables")
        if len(self.bending) > MAX_MODES or len(self.axial) > MAX_MODES:
            raise MechanismError(f"UserShapes: at most {MAX_MODES} bending and {MAX_MODES} axial "
                                 f"shapes ({MODES_LIMIT}), got {len(self.bending)} and "
                                 f"{len(self.axial)}")

    @classmethod
    def from_table(cls, table) -> "UserShapes":
        return cls(tuple(_imported(table, "bending")), tuple(_imported(table, "axial", [])))

    def to_table(self) -> dict[str, Any]:
        return {"type": self.TYPE,
                "bending": [_importable_name(f, f"bending[{i}]") for i, f in enumerate(self.bending)],
                "axial": [_importable_name(f, f"axial[{i}]") for i, f in enumerate(self.axial)]}

    def layout(self, link, attachments=None) -> ShapeLayout:
        return ShapeLayout(bending_and_axial_labels(len(self.bending),
                                                    len(self.axial) if link.axial else 0))

    def values(self, link, x: np.ndarray, basis=None) -> ShapeValues:
        bending = [_call_user(f, x, link, "bending", i) for i, f in enumerate(self.bending)]
        axial = ([_call_user(f, x, link, "axial", i) for i, f in enumerate(self.axial)]
                 if link.axial else [])
        return ShapeValues.from_functions(bending, axial)


def _importable_name(function: Callable, key: str) -> str:
    """``"module:qualname"`` of a module-level function, checked to import back to itself."""
    module = getattr(function, "__module__", None)
    qualname = getattr(function, "__qualname__", None)
    if not module or not qualname or "<" in qualname:
        raise MechanismError(
            f"UserShapes.{key} ({function!r}) cannot be written to a scene: a scene names a shape "
            f"function by 'module:qualname' and imports it back, which a lambda, a nested "
            f"function or a closure does not survive; define it with def at the top level of an "
            f"importable module (or use Ritz or Fem)")
    name = f"{module}:{qualname}"
    try:
        found = _import(name)
    except (ImportError, AttributeError) as error:
        found = error
    if found is not function:
        raise MechanismError(f"UserShapes.{key}: {name!r} does not import back to {function!r} "
                             f"(got {found!r}); define the function at the top level of an "
                             f"importable module")
    return name


def _import(name: str) -> Any:
    module, _, qualname = name.partition(":")
    target: Any = importlib.import_module(module)
    for part in qualname.split("."):
        target = getattr(target, part)
    return target


def _imported(table, key: str, default: Any = None) -> list[Callable]:
    names = table.raw(key) if default is None else table.raw(key, default)
    where = f"{table.path}.{key}"
    if not isinstance(names, list) or not all(isinstance(n, str) and ":" in n for n in names):
        raise MechanismError(f"{where} must be a list of 'module:qualname' strings naming shape "
                             f"functions f(x, length) -> (value, d/dx, d2/dx2), got {names!r}")
    functions = []
    for name in names:
        try:
            function = _import(name)
        except (ImportError, AttributeError) as error:
            raise MechanismError(f"{where}: cannot import {name!r} ({error}); the module must be "
                                 f"importable where the scene is read") from None
        if not callable(function):
            raise MechanismError(f"{where}: {name!r} is {function!r}, not a function")
        functions.append(function)
    return functions


def clamped_free_roots(n: int) -> np.ndarray:
    """The first ``n`` roots ``beta L`` of ``cos(b) cosh(b) = -1`` (1.8751, 4.6941, ...)."""
    from scipy.optimize import brentq  # here: scipy.optimize costs about 0.5 s to import

    def f(b):
        return math.cos(b) + 1.0 / math.cosh(b)  # same roots, no overflow
    return np.array([brentq(f, (i - 1) * math.pi + 1e-3, i * math.pi, xtol=1e-15, rtol=1e-15)
                     for i in range(1, n + 1)])


def _clamped_free_mode(x: np.ndarray, beta: float, length: float):
    """Clamped-free eigenfunction ``cosh bx - cos bx - sigma (sinh bx - sin bx)`` and two
    derivatives, written with decaying exponentials so that high modes do not cancel."""
    bl = beta * length
    denominator = math.sinh(bl) + math.sin(bl)
    sigma = (math.cosh(bl) + math.cos(bl)) / denominator
    one_minus_sigma = (math.sin(bl) - math.cos(bl) - math.exp(-bl)) / denominator
    bx = beta * x
    grow = 0.5 * one_minus_sigma * np.exp(bx)      # e^{bx} (1 - sigma) / 2
    decay = 0.5 * (1.0 + sigma) * np.exp(-bx)      # e^{-bx} (1 + sigma) / 2
    value = decay + grow - np.cos(bx) + sigma * np.sin(bx)
    slope = beta * (grow - decay + np.sin(bx) + sigma * np.cos(bx))
    curvature = beta**2 * (grow + decay + np.cos(bx) - sigma * np.sin(bx))
    return value, slope, curvature


def _call_user(f, x, link, kind, index):
    try:   # any failure of user code is bad input, reported with the shape it came from
        result = f(x, link.length)
    except Exception as error:
        raise MechanismError(f"link {link.name!r}: UserShapes.{kind}[{index}] raised "
                             f"{type(error).__name__}: {error}; expected f(x, length) -> (value, d/dx, "
                             f"d2/dx2) with x an array of abscissae (m)") from error
    try:
        arrays = tuple(np.broadcast_to(np.asarray(a, dtype=float), x.shape) for a in result)
    except (TypeError, ValueError) as error:
        raise MechanismError(f"link {link.name!r}: UserShapes.{kind}[{index}] must return "
                         f"(value, d/dx, d2/dx2), arrays shaped like x") from error
    if len(arrays) != 3 or not all(np.all(np.isfinite(a)) for a in arrays):
        raise MechanismError(f"link {link.name!r}: UserShapes.{kind}[{index}] must return three "
                         f"finite arrays (value, d/dx, d2/dx2)")
    return arrays


