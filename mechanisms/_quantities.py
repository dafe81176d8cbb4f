"""The quantities of a link that observable specs name, ``"<link>.<quantity>@<fraction>"``: one
registry, filled by ``_observables`` with the built-in quantities and by ``register_observable``
with a user's function of the coordinates.

A registered quantity needs nothing else: ``Model.observable(spec)`` parses its specs,
``mechanisms.simulate`` evaluates it, ``linearize`` maps it through its gradient and the studies
report it (and store it in their files) by its spec. Workers of the studies' process pools are
forked from the registering process and inherit the registry.
"""

from __future__ import annotations

import difflib
import re
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ._parts import ArgumentError

__all__ = ["position_quantities", "quantity_names", "register_observable"]


class OfCoordinates:
    """The evaluation route of a function of the coordinates ``s`` alone (``Observable`` in
    ``_protocol.py``): its linear change is ``gradient(s0) . x``; along a nonlinear run, its value
    less its value along the nominal motion."""

    of_coordinates = True        # value(s) and gradient(s) are the whole quantity
    needs_multipliers = False    # its linear map reads no multiplier maps

    def linear_map(self, route):
        return route.coordinates(self)

    def along_run(self, run, linear_map) -> np.ndarray:
        return run.coordinates(self, linear_map)


@dataclass(frozen=True)
class _Quantity:
    """How the observable of one quantity is made: ``make(model, spec, layout, name, where)``,
    ``layout`` the link's ``LinkLayout``, ``where`` the text after ``'@'`` (``""`` if none);
    ``function`` the user's function (None for a built-in quantity); ``position``: its value is a
    position of the mechanism (``position_quantities``)."""

    make: Callable
    function: Callable | None = None
    position: bool = False


_QUANTITIES: dict[str, _Quantity] = {}
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")


def add_quantity(name: str, make: Callable, *, position: bool = False) -> None:
    """Register a built-in quantity (package-internal: ``_observables``)."""
    _QUANTITIES[name] = _Quantity(make, position=position)


def quantity_names() -> tuple[str, ...]:
    """The names of every quantity of a link an observable spec may name, built-in and registered
    (``"<link>.<name>@<fraction>"``, or without ``@`` for those that take none); which links offer
    which one is the model's to say (``Model.observable`` refuses a rigid link's deflection)."""
    return tuple(_QUANTITIES)


def position_quantities() -> tuple[str, ...]:
    """The names of the quantities of a link, built-in and registered, whose value is a position of
    the mechanism (a frame angle, a point's global coordinate, the magnitude of a point's
    displacement), so that their change from the nominal motion is an error of the motion (the
    output of ``studies.control_comparison``); a deflection, strain or moment is not one."""
    return tuple(name for name, known in _QUANTITIES.items() if known.position)


def quantity(spec: str, name: str) -> Callable:
    """The ``make`` of quantity ``name``; an unknown one is refused naming the nearest."""
    if name not in _QUANTITIES:
        known = sorted(_QUANTITIES)
        close = difflib.get_close_matches(name, known, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise ArgumentError(f"observable {spec!r}: unknown quantity {name!r}{hint}; expected one of "
                            f"{known} (mechanisms.register_observable adds one)")
    return _QUANTITIES[name].make


def fraction_of(spec: str, where: str) -> float:
    """The fraction of a link's length after ``'@'`` (default 0.5), checked to be in [0, 1]."""
    try:
        fraction = float(where) if where else 0.5
    except ValueError:
        raise ArgumentError(f"observable {spec!r}: the part after '@' must be a fraction of the "
                            f"length in [0, 1]; received {where!r}") from None
    if not 0.0 <= fraction <= 1.0:
        raise ArgumentError(f"observable {spec!r}: fraction must be in [0, 1]; received {fraction}")
    return fraction


@dataclass(frozen=True)
class RegisteredObservable(OfCoordinates):
    """An observable of a quantity added by ``register_observable``: ``value(s)`` -> float and
    ``gradient(s)`` -> (n,) from the user's functions, their results checked."""

    spec: str
    unit: str
    kind: str                    # the quantity's registered name
    n_coords: int
    value_function: Callable
    gradient_function: Callable
    depends_on_elastic_only: bool = False

    def _s(self, s) -> np.ndarray:
        s = np.asarray(s, dtype=float)
        if s.shape != (self.n_coords,):
            raise ArgumentError(f"s must have shape ({self.n_coords},); received shape {s.shape}")
        return s

    def value(self, s) -> float:
        return float(self.value_function(self._s(s)))

    def gradient(self, s) -> np.ndarray:
        out = np.asarray(self.gradient_function(self._s(s)), dtype=float)
        if out.shape != (self.n_coords,):
            raise ArgumentError(f"observable {self.spec!r}: its gradient function returned shape "
                                f"{out.shape}; expected ({self.n_coords},) (d value / ds)")
        return out


def register_observable(name: str, function: Callable, *, unit: str, at_point: bool = True,
                        elastic_only: bool = False, position: bool = False, replace: bool = False) -> None:
    """Add the quantity ``name`` of a link, a function of the coordinates, to the observable specs:
    ``"<link>.<name>@<fraction>"`` (``at_point=False``: ``"<link>.<name>"``, no ``'@'``).

    ``function(model, link, fraction)`` -> ``(value, gradient)``, for an assembled model
    (``mechanisms.Model``: ``model.layouts[link]`` says where the link's coordinates are and gives
    its shape functions), the link's name and the fraction of its length in [0, 1] (default 0.5;
    None without ``at_point``): ``value(s)`` -> float in ``unit`` (SI) and ``gradient(s)`` -> (n,)
    its derivative in the coordinates ``s`` (n,). It may raise ``ValueError`` to refuse a link (a
    rigid one, say): the message reaches the user with the spec. ``elastic_only``: value and
    gradient read only elastic coordinates (``linearize`` then evaluates the gradient once along a
    rigid nominal motion; leave False if unsure). ``position``: the value is a position of the
    mechanism (an angle or a point's coordinate, ``position_quantities``), so it may be the output
    of a control comparison. ``replace``: replace a quantity registered
    before (built-in ones cannot be replaced).

    Then ``Model.observable(spec)`` makes it, ``mechanisms.simulate`` reports it, ``linearize`` maps
    it through its gradient, and the studies (their HDF5 files and resumed runs) report it by its
    spec. Call it at import time of the code that uses it, before the studies start their workers.
    """
    if not isinstance(name, str) or not _NAME.match(name):
        raise ArgumentError(f"register_observable: name must be an identifier such as 'curvature'; "
                            f"received {name!r}")
    if not callable(function):
        raise ArgumentError(f"register_observable: function must be callable (model, link, fraction) "
                            f"-> (value, gradient); received {type(function).__name__}")
    if not isinstance(unit, str) or not unit:
        raise ArgumentError(f"register_observable: unit must be a non-empty string such as '1/m'; "
                            f"received {unit!r}")
    known = _QUANTITIES.get(name)
    if known is not None and known.function is None:
        raise ArgumentError(f"register_observable: {name!r} is a built-in quantity; choose another "
                            f"name")
    if known is not None and known.function is not function and not replace:
        raise ArgumentError(f"register_observable: quantity {name!r} is registered already (with "
                            f"{known.function!r}); pass replace=True to replace it")

    def make(model, spec, layout, kind, where):
        if at_point:
            fraction = fraction_of(spec, where)
        elif where:
            raise ArgumentError(f"observable {spec!r}: {kind!r} takes no '@fraction'")
        else:
            fraction = None
        try:
            made = function(model, layout.link.name, fraction)
        except ArgumentError:
            raise
        except ValueError as error:
            raise ArgumentError(f"observable {spec!r}: {error}") from None
        if not (isinstance(made, (tuple, list)) and len(made) == 2 and all(map(callable, made))):
            raise ArgumentError(f"observable {spec!r}: the function registered for {kind!r} must "
                                f"return (value, gradient), two callables of s; received {made!r}")
        value, gradient = made
        return RegisteredObservable(spec, unit, kind, model.n_coords, value, gradient,
                                    bool(elastic_only))

    _QUANTITIES[name] = _Quantity(make, function, bool(position))
