"""The constraints of ``studies.optimize``: each constraint is an object that says what it needs of
the problem, what it measures at each speed of an evaluation, and how far the evaluation is from
meeting it (scaled values >= 0 where met); the evaluator (``_optimize_search``) asks only that.

A new constraint: a frozen dataclass with ``name``, ``bound()``, ``needs(problem)`` (the observables
it reads; it raises for a problem it cannot judge), ``at_speed(evaluator, linear, steady)`` and
``judged(values, evaluator, parameters)``, its scene keys ``TABLE_KEYS`` (the first names it in the
``constraints`` table, the others are its options) and a classmethod ``from_table(where, table)``,
decorated :func:`register_constraint` (``studies.register_constraint``, from outside the package too);
optionally ``gradient_at_speed(evaluator, linear, steady, point)`` (d at_speed / d parameters from the
point's sensitivities, ``studies._derivatives``) and ``judged_gradient(gradients, evaluator)``, without
which the local method takes forward differences.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from .._derivatives import headline_derivatives
from .._errors import StudiesError
from .._kind import HARMONIC_WHY, MAX_HARMONIC, fraction, integer, number, reject_unknown
from .._numerics import frozen_modes, peak_summary
from .._problem import SPEED

#: Frozen-time samples per period of the frequency-separation constraint.
FROZEN_SAMPLES = 32

#: The registered constraint classes, in registration order (:func:`register_constraint`).
_CONSTRAINTS: list[type] = []


def register_constraint(cls: type) -> type:
    """Register the constraint class ``cls`` (a class decorator; the module docstring says what it
    declares): its first ``TABLE_KEYS`` entry becomes a key of the ``constraints`` table. Returns
    ``cls``. A second class claiming a key already taken raises :class:`StudiesError`."""
    keys = tuple(getattr(cls, "TABLE_KEYS", ()))
    if not keys or not callable(getattr(cls, "from_table", None)):
        raise StudiesError(f"register_constraint: expected a class with TABLE_KEYS and from_table(where, table), "
                           f"got {cls!r}")
    taken = {key: other for other in _CONSTRAINTS if other is not cls for key in other.TABLE_KEYS}
    clash = [key for key in keys if key in taken]
    if clash:
        raise StudiesError(f"register_constraint: {cls.__name__} claims the key {clash[0]!r} of "
                           f"{taken[clash[0]].__name__}")
    if cls not in _CONSTRAINTS:
        _CONSTRAINTS.append(cls)
    return cls


def constraint_types() -> tuple[type, ...]:
    """The registered constraint classes."""
    return tuple(_CONSTRAINTS)


def constraint_keys() -> tuple[str, ...]:
    """Every key of the ``constraints`` table (each registered class's ``TABLE_KEYS``)."""
    return tuple(key for cls in _CONSTRAINTS for key in cls.TABLE_KEYS)


@register_constraint
@dataclass(frozen=True)
class StabilityMargin:
    """Spectral radius at most ``1 - margin`` at every speed (``margin`` in [0, 1))."""

    margin: float = 0.0
    name = "stability"
    #: its gradient reads the critical multiplier's derivative
    needs_radius = True
    TABLE_KEYS = ("stability_margin",)

    @classmethod
    def from_table(cls, where: str, table: Mapping[str, Any]) -> StabilityMargin:
        return cls(fraction(where, "constraints.stability_margin", table["stability_margin"]))

    def limit(self) -> float:
        return 1.0 - self.margin

    def bound(self) -> float:
        """The limit the result reports (the largest spectral radius allowed)."""
        return self.limit()

    def needs(self, problem: Any) -> tuple[str, ...]:
        return ()

    def at_speed(self, evaluator: Any, linear: Any, steady: Any) -> float:
        return steady.state.spectral_radius

    def gradient_at_speed(self, evaluator: Any, linear: Any, steady: Any, point: Any) -> np.ndarray:
        """d spectral radius / d parameters (P,): the critical multiplier's (``studies._derivatives``); NaN
        where the radius is another mode's (one the step does not resolve) or the multiplier is repeated."""
        state = steady.state
        if not math.isclose(abs(state.critical_multiplier), state.spectral_radius, rel_tol=1e-12):
            return np.full(len(point.names), np.nan)
        return point.radius

    def judged(self, values: np.ndarray, evaluator: Any, parameters: Mapping[str, float]) -> tuple[np.ndarray, float]:
        """(scaled (n_s,), >= 0 where met; the value reported: the largest spectral radius)."""
        return self.limit() - values, float(values.max())

    def judged_gradient(self, gradients: np.ndarray, evaluator: Any) -> np.ndarray:
        """d scaled / d parameters (n_s, P) from ``gradient_at_speed``'s rows."""
        return -gradients


@register_constraint
@dataclass(frozen=True)
class TorqueLimit:
    """Peak total drive torque (N m) at most ``limit`` at every speed, for the drives at ``joints``
    (None: every drive of the mechanism). Several limits on different sets of drives may be given;
    each is named ``"torque"`` (every drive) or ``"torque@<joint>+<joint>..."``."""

    limit: float
    joints: tuple[str, ...] | None = None
    TABLE_KEYS = ("torque_limit",)

    @classmethod
    def from_table(cls, where: str, table: Mapping[str, Any]) -> TorqueLimit:
        return cls(number(where, "constraints.torque_limit", table["torque_limit"], positive=True))

    @property
    def name(self) -> str:
        return "torque" if self.joints is None else "torque@" + "+".join(self.joints)

    def bound(self) -> float:
        return self.limit

    def needs(self, problem: Any) -> tuple[str, ...]:
        """The drive torques it limits, as observable specs."""
        return tuple(f"drive.{joint}.torque" for joint in drive_joints(problem, self))

    def at_speed(self, evaluator: Any, linear: Any, steady: Any) -> float:
        rows = [linear.observables.index(spec) for spec in evaluator.specs[self.name]]
        return max(peak_summary(steady.response[:, rows], steady.response_error[rows])["peak"])

    def gradient_at_speed(self, evaluator: Any, linear: Any, steady: Any, point: Any) -> np.ndarray:
        """d peak / d parameters (P,) of the drive torque with the largest peak (envelope rule)."""
        rows = [linear.observables.index(spec) for spec in evaluator.specs[self.name]]
        peaks = peak_summary(steady.response[:, rows], steady.response_error[rows])["peak"]
        k = rows[int(np.argmax(peaks))]
        found, _ = headline_derivatives(point.response[:, [k]], point.derivative[:, :, [k]])
        return found["peak"][:, 0]

    def judged(self, values: np.ndarray, evaluator: Any, parameters: Mapping[str, float]) -> tuple[np.ndarray, float]:
        """(scaled (n_s,); the largest peak drive torque, N m)."""
        return 1.0 - values / self.limit, float(values.max())

    def judged_gradient(self, gradients: np.ndarray, evaluator: Any) -> np.ndarray:
        """d scaled / d parameters (n_s, P)."""
        return -gradients / self.limit


@register_constraint
@dataclass(frozen=True)
class MassBudget:
    """Sum of the links' masses (``density * area * length`` for elastic links; kg) at most ``budget``."""

    budget: float
    name = "mass"
    TABLE_KEYS = ("mass_budget",)

    @classmethod
    def from_table(cls, where: str, table: Mapping[str, Any]) -> MassBudget:
        return cls(number(where, "constraints.mass_budget", table["mass_budget"], positive=True))

    def bound(self) -> float:
        return self.budget

    def needs(self, problem: Any) -> tuple[str, ...]:
        """Nothing observed; the problem must have links."""
        if not hasattr(problem, "mechanism"):
            raise StudiesError(f"constraints: a mass budget needs a mechanism problem; problem {problem.name!r} "
                               f"has no links")
        return ()

    def at_speed(self, evaluator: Any, linear: Any, steady: Any) -> float:
        return math.nan   # the mass does not depend on the speed

    def judged(self, values: np.ndarray, evaluator: Any, parameters: Mapping[str, float]) -> tuple[np.ndarray, float]:
        """(scaled (1,); the links' mass, kg)."""
        mass = links_mass(evaluator.problem, parameters)
        return np.array([1.0 - mass / self.budget]), mass


@register_constraint
@dataclass(frozen=True)
class FrequencySeparation:
    """Every frozen-time natural frequency band (over the crank angle) at least ``fraction * k *
    speed`` away from ``k * speed`` for k = 1 .. ``max_harmonic``, at every speed."""

    fraction: float
    max_harmonic: int = 4
    name = "frequency"
    TABLE_KEYS = ("frequency_separation", "max_harmonic")

    @classmethod
    def from_table(cls, where: str, table: Mapping[str, Any]) -> FrequencySeparation:
        return cls(fraction(where, "constraints.frequency_separation", table["frequency_separation"]),
                   integer(where, "constraints.max_harmonic", table.get("max_harmonic", 4), 1,
                           maximum=MAX_HARMONIC, why=HARMONIC_WHY))

    def bound(self) -> float:
        return self.fraction

    def needs(self, problem: Any) -> tuple[str, ...]:
        return ()

    def at_speed(self, evaluator: Any, linear: Any, steady: Any) -> float:
        return separation(linear.system, 2.0 * math.pi / linear.system.period, self.max_harmonic)

    def judged(self, values: np.ndarray, evaluator: Any, parameters: Mapping[str, float]) -> tuple[np.ndarray, float]:
        """(scaled (n_s,); the least distance of a frozen band from k x speed over k x speed)."""
        return values - self.fraction, float(values.min())


def constraints_from_table(where: str, table: Mapping[str, Any]) -> tuple:
    """The constraint objects of a ``constraints`` table (keys: :func:`constraint_keys`), one per
    registered class whose first key is present; an option key without its constraint's first key is
    refused."""
    keys = constraint_keys()
    if not isinstance(table, Mapping):
        raise StudiesError(f"[{where}] constraints: expected a table with keys {', '.join(keys)}, got {table!r}")
    reject_unknown(f"{where}.constraints", table, keys)
    found: list = []
    for cls in _CONSTRAINTS:
        first, *options = cls.TABLE_KEYS
        if first in table:
            found.append(cls.from_table(where, table))
        else:
            stray = [key for key in options if key in table]
            if stray:
                raise StudiesError(f"[{where}] constraints.{stray[0]}: only with {first}")
    return tuple(found)


def check_constraints(constraints: Any) -> tuple:
    if isinstance(constraints, Mapping):
        return constraints_from_table("optimize", constraints)
    constraints = tuple(constraints)
    for item in constraints:
        if type(item) not in _CONSTRAINTS:
            raise StudiesError(f"constraints: expected objects of the registered constraint classes "
                               f"({', '.join(cls.__name__ for cls in _CONSTRAINTS)}; studies.register_constraint "
                               f"adds one) or a table with keys {', '.join(constraint_keys())}, got {item!r}")
    names = [item.name for item in constraints]
    if len(set(names)) != len(names):
        raise StudiesError(f"constraints: at most one of each kind (torque limits: one per set of joints), "
                           f"got {list(constraints)!r}")
    return constraints


def drive_joints(problem: Any, constraint: TorqueLimit) -> tuple[str, ...]:
    if not hasattr(problem, "mechanism"):
        raise StudiesError(f"constraints: a torque limit needs a mechanism problem; problem {problem.name!r} "
                           f"has no drives")
    joints = tuple(drive.joint for drive in problem.mechanism().drives)
    chosen = constraint.joints if constraint.joints is not None else joints
    unknown = [joint for joint in chosen if joint not in joints]
    if unknown:
        raise StudiesError(f"constraints: torque limit on joint {unknown[0]!r}, which has no drive "
                           f"(drives at {', '.join(joints)})")
    return tuple(chosen)


def links_mass(problem: Any, values: Mapping[str, float]) -> float:
    """Sum of the links' masses (kg) of the mechanism at ``values`` (the mechanism knows each:
    ``density * area * length`` of an elastic link, the given or uniform-bar mass of a rigid one)."""
    mechanism = problem.mechanism({k: v for k, v in values.items() if k != SPEED})
    return float(sum(link.mass for link in mechanism.links))


def separation(system: Any, speed: float, max_harmonic: int) -> float:
    """The smallest distance of a frozen natural-frequency band (over the period) from ``k * speed``,
    k = 1 .. ``max_harmonic``, over ``k * speed`` (0 where a band holds ``k * speed``)."""
    _, frozen, _ = frozen_modes(system, FROZEN_SAMPLES)
    low, high = frozen.min(axis=0), frozen.max(axis=0)
    harmonics = speed * np.arange(1, max_harmonic + 1)[:, None]
    distance = np.maximum(np.maximum(low[None, :] - harmonics, harmonics - high[None, :]), 0.0)
    return float((distance / harmonics).min())


def describe(constraint: Any) -> dict[str, Any]:
    """The constraint as the result's settings record it: its class and fields."""
    return {"kind": type(constraint).__name__, **{k: getattr(constraint, k) for k in constraint.__dataclass_fields__}}
