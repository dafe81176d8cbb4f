"""The constraints of ``studies.optimize``: each constraint is an object that says what it needs of
the problem, what it measures at each speed of an evaluation, and how far the evaluation is from
meeting it (scaled values >= 0 where met); the evaluator (``_optimize_search``) asks only that.

A new constraint: a frozen dataclass with ``name``, ``bound()``, ``needs(problem)`` (the observables
it reads; it raises for a problem it cannot judge), ``at_speed(evaluator, linear, steady)`` and
``judged(values, evaluator, parameters)``, and its entry in ``CONSTRAINT_TYPES`` (and a key of the
scene table in ``constraints_from_table``); optionally ``gradient_at_speed(evaluator, linear, steady,
point)`` (d at_speed / d parameters from the point's sensitivities, ``studies._derivatives``) and
``judged_gradient(gradients, evaluator)``, without which the local method takes forward differences.
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
#: Keys of the ``constraints`` table.
CONSTRAINT_KEYS = ("stability_margin", "torque_limit", "mass_budget", "frequency_separation", "max_harmonic")


@dataclass(frozen=True)
class StabilityMargin:
    """Spectral radius at most ``1 - margin`` at every speed (``margin`` in [0, 1))."""

    margin: float = 0.0
    name = "stability"
    #: its gradient reads the critical multiplier's derivative
    needs_radius = True

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


@dataclass(frozen=True)
class TorqueLimit:
    """Peak total drive torque (N m) at most ``limit`` at every speed, for the drives at ``joints``
    (None: every drive of the mechanism). Several limits on different sets of drives may be given;
    each is named ``"torque"`` (every drive) or ``"torque@<joint>+<joint>..."``."""

    limit: float
    joints: tuple[str, ...] | None = None

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


@dataclass(frozen=True)
class MassBudget:
    """Sum of the links' masses (``density * area * length`` for elastic links; kg) at most ``budget``."""

    budget: float
    name = "mass"

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


@dataclass(frozen=True)
class FrequencySeparation:
    """Every frozen-time natural frequency band (over the crank angle) at least ``fraction * k *
    speed`` away from ``k * speed`` for k = 1 .. ``max_harmonic``, at every speed."""

    fraction: float
    max_harmonic: int = 4
    name = "frequency"

    def bound(self) -> float:
        return self.fraction

    def needs(self, problem: Any) -> tuple[str, ...]:
        return ()

    def at_speed(self, evaluator: Any, linear: Any, steady: Any) -> float:
        return separation(linear.system, 2.0 * math.pi / linear.system.period, self.max_harmonic)

    def judged(self, values: np.ndarray, evaluator: Any, parameters: Mapping[str, float]) -> tuple[np.ndarray, float]:
        """(scaled (n_s,); the least distance of a frozen band from k x speed over k x speed)."""
        return values - self.fraction, float(values.min())


CONSTRAINT_TYPES = (StabilityMargin, TorqueLimit, MassBudget, FrequencySeparation)


def constraints_from_table(where: str, table: Mapping[str, Any]) -> tuple:
    """The constraint objects of a ``constraints`` table (keys ``CONSTRAINT_KEYS``)."""
    if not isinstance(table, Mapping):
        raise StudiesError(f"[{where}] constraints: expected a table with keys {', '.join(CONSTRAINT_KEYS)}, "
                           f"got {table!r}")
    reject_unknown(f"{where}.constraints", table, CONSTRAINT_KEYS)
    found: list = []
    if "stability_margin" in table:
        found.append(StabilityMargin(fraction(where, "constraints.stability_margin", table["stability_margin"])))
    if "torque_limit" in table:
        found.append(TorqueLimit(number(where, "constraints.torque_limit", table["torque_limit"], positive=True)))
    if "mass_budget" in table:
        found.append(MassBudget(number(where, "constraints.mass_budget", table["mass_budget"], positive=True)))
    if "max_harmonic" in table and "frequency_separation" not in table:
        raise StudiesError(f"[{where}] constraints.max_harmonic: only with frequency_separation")
    if "frequency_separation" in table:
        found.append(FrequencySeparation(
            fraction(where, "constraints.frequency_separation", table["frequency_separation"]),
            integer(where, "constraints.max_harmonic", table.get("max_harmonic", 4), 1,
                    maximum=MAX_HARMONIC, why=HARMONIC_WHY)))
    return tuple(found)


def check_constraints(constraints: Any) -> tuple:
    if isinstance(constraints, Mapping):
        return constraints_from_table("optimize", constraints)
    constraints = tuple(constraints)
    for item in constraints:
        if not isinstance(item, CONSTRAINT_TYPES):
            raise StudiesError(f"constraints: expected studies.StabilityMargin, TorqueLimit, MassBudget or "
                               f"FrequencySeparation objects (or a table with keys "
                               f"{', '.join(CONSTRAINT_KEYS)}), got {item!r}")
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
