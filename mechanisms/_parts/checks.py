"""The shared checks of the parts: names, numbers, counts, pairs, and the size limits of a scene.

Every part checks its own numbers when it is made (``MechanismError``, a ``ValueError`` naming the
part and key); these are the helpers they share.
"""

from __future__ import annotations

import math
import re
from typing import Union

GROUND = "ground"

PointRef = Union[str, float]


class MechanismError(ValueError):
    """A mechanism or scene that is invalid: bad numbers, unknown names, a linkage that cannot be
    assembled or whose crank cannot turn, a singular constraint Jacobian."""


class ArgumentError(ValueError):
    """A bad argument to a function or method of ``mechanisms`` (a shape, a non-finite value, an
    unknown joint, link or observable name, an option that needs another): the message names the
    argument, what was expected and what was received. Numerical failures on good input raise
    ``ConvergenceError`` (a ``RuntimeError``) instead."""


_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_\-]*$")


def _check_name(kind: str, name: object) -> None:
    # Names become parts of dotted parameter paths ("links.coupler.thickness"), of observable
    # specs ("coupler.deflection@0.5") and of constraint labels ("B.x", "drive:O"), so dots, '@'
    # and ':' are not allowed.
    if not isinstance(name, str) or not _NAME.match(name):
        raise MechanismError(f"{kind} name must be a word of letters, digits, '_' or '-' starting "
                             f"with a letter (no dots), got {name!r}")
    if name == GROUND:
        raise MechanismError(f"{kind} name {GROUND!r} is reserved for the fixed frame")


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _check_number(owner: str, key: str, value: object, unit: str, *, positive: bool = False,
                  nonnegative: bool = False) -> None:
    if not _is_number(value) or not math.isfinite(value):
        raise MechanismError(f"{owner}: {key} must be a finite number ({unit}), got {value!r}")
    if positive and not value > 0:
        raise MechanismError(f"{owner}: {key} must be positive ({unit}), got {value!r}")
    if nonnegative and not value >= 0:
        raise MechanismError(f"{owner}: {key} must be zero or positive ({unit}), got {value!r}")


# Upper bounds of the size-like values of a scene (docs/scenes.md, "Limits"). Each keeps what one
# link or drive costs bounded, and far above what any model needs; what a whole study costs (its
# steps, points and all coordinates together) is estimated and limited by the studies' resource guard.
#: Hermite elements per link: each adds 3 coordinates, and a linearisation holds (n_steps + 1) n^2
#: doubles per matrix (128 elements alone: 0.3 GB per matrix at 256 steps).
MAX_ELEMENTS = 128
#: Ritz modes per link, bending or axial: beyond 64 half-waves the Euler-Bernoulli beam itself no
#: longer describes a slender link (the wavelength nears the section height of any practical link).
MAX_MODES = 64
#: Whole turns of a drive per period: the studies resolve one period with n_steps steps, and the
#: loader's Grashof scan samples 4096 crank angles per turn.
MAX_TURNS = 100
#: Physical sense, judged relative to the mechanism itself: no link shorter than this fraction of its
#: longest (a 1e-12 m crank on a 0.3 m four-bar), no period shorter than this fraction of its elastic
#: links' shortest first natural period (a drive a million times faster than the links' lowest
#: vibration is outside what the model of slowly moving elastic links describes).
MIN_LENGTH_FRACTION = 1e-6
MIN_PERIOD_FRACTION = 1e-6
#: Characters of free text in a scene (its name and description): documentation, kept in the spec
#: and written to every result file.
MAX_TEXT = 10_000
#: Order k of a drive harmonic, and how many a drive may have: the motion is sampled n_steps times
#: per period, and the studies' n_steps is at most 65536.
MAX_HARMONIC_ORDER = 1000
MAX_HARMONICS = 100


def _check_count(owner: str, key: str, value: object, minimum: int, maximum: int | None = None,
                 why: str = "") -> None:
    if (not isinstance(value, int) or isinstance(value, bool) or value < minimum
            or (maximum is not None and value > maximum)):
        bound = f"an integer >= {minimum}" if maximum is None else \
            f"an integer from {minimum} to {maximum} ({why})"
        raise MechanismError(f"{owner}: {key} must be {bound}, got {value!r}")


def _check_pair(owner: str, key: str, value: object, unit: str) -> None:
    if (not isinstance(value, (tuple, list)) or len(value) != 2
            or not all(_is_number(v) and math.isfinite(v) for v in value)):
        raise MechanismError(f"{owner}: {key} must be a pair of finite numbers ({unit}), "
                             f"got {value!r}")


def register_class(registry: dict[str, type], cls: type, interface: tuple[str, ...], kind: str,
                   example: str) -> type:
    """Enter ``cls`` in ``registry`` under its ``TYPE`` (the registries of joints and
    discretisations): it must declare every name of ``interface`` and a ``TYPE`` no other class
    has taken; returns ``cls``. Raises ``MechanismError`` naming what is missing."""
    missing = [name for name in interface if not hasattr(cls, name)]
    if missing:
        raise MechanismError(f"register_{kind}: {cls!r} lacks {missing}; a {kind} class declares "
                             f"{list(interface)} (see {example})")
    if not isinstance(cls.TYPE, str) or not cls.TYPE or "type" not in cls.KEYS:
        raise MechanismError(f"register_{kind}: {cls.__name__}.TYPE must be a non-empty string and "
                             f"KEYS must include 'type'; got TYPE={cls.TYPE!r}, KEYS={cls.KEYS!r}")
    taken = registry.get(cls.TYPE)
    if taken is not None and taken is not cls:
        raise MechanismError(f"register_{kind}: {kind} type {cls.TYPE!r} is already {taken!r}; give "
                             f"{cls.__name__} another TYPE")
    registry[cls.TYPE] = cls
    return cls
