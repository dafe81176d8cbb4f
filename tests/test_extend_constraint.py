"""A new optimisation constraint defined outside the packages with public API only
(``studies.register_constraint``): a floor on the lowest natural frequency. Registered, it is taken as an
object and from a ``constraints`` table, and the constrained optimum of an oscillator forced at 1 and 2
rad/s (which, unconstrained, runs down to its lowest natural frequency) sits on the floor, the closed
form of an active constraint."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

import studies


@studies.register_constraint
@dataclass(frozen=True)
class FrequencyFloor:
    """The lowest frozen natural frequency (at t = 0) at least ``floor`` rad/s at every speed."""

    floor: float
    name = "frequency_floor"
    TABLE_KEYS = ("frequency_floor",)

    @classmethod
    def from_table(cls, where, table):
        value = table["frequency_floor"]
        if not isinstance(value, (int, float)) or value <= 0:
            raise studies.StudiesError(f"[{where}] constraints.frequency_floor: expected a positive number "
                                       f"(rad/s), got {value!r}")
        return cls(float(value))

    def bound(self):
        return self.floor

    def needs(self, problem):
        return ()

    def at_speed(self, evaluator, linear, steady):
        system = linear.system
        values = np.linalg.eigvals(np.linalg.solve(system.M[0], system.K[0])).real
        return float(np.sqrt(values.min()))

    def judged(self, values, evaluator, parameters):
        return values / self.floor - 1.0, float(values.min())


def _oscillator():
    return studies.mathieu_problem(epsilon=0.0, damping_ratio=0.02, speed=1.0)


@pytest.mark.parametrize("given", ["object", "table"])
def test_the_registered_constraint_is_active_at_its_floor(given):
    constraint = FrequencyFloor(0.5) if given == "object" else {"frequency_floor": 0.5}
    found = studies.optimize(_oscillator(), {"natural_frequency": (0.3, 2.2)}, objective="rms:x",
                             speeds=[1.0, 2.0], n_steps=64, start={"natural_frequency": 0.6},
                             constraints=[constraint] if given == "object" else constraint, check=False)
    assert found.x[0] == pytest.approx(0.5, rel=1e-6), found.message
    assert found.constraint_values["frequency_floor"] == pytest.approx(0.5, rel=1e-6)
    assert found.constraint_limits == {"frequency_floor": 0.5}
    # without it the same search runs down to the bound: the constraint is what holds it
    free = studies.optimize(_oscillator(), {"natural_frequency": (0.3, 2.2)}, objective="rms:x",
                            speeds=[1.0, 2.0], n_steps=64, start={"natural_frequency": 0.6}, check=False)
    assert free.x[0] == pytest.approx(0.3, abs=1e-9)


def test_registration_is_checked_and_the_new_key_is_named_in_errors():
    assert studies.register_constraint(FrequencyFloor) is FrequencyFloor   # idempotent

    @dataclass(frozen=True)
    class Clash:
        TABLE_KEYS = ("mass_budget",)

        @classmethod
        def from_table(cls, where, table):
            return cls()

    with pytest.raises(studies.StudiesError, match="claims the key 'mass_budget' of MassBudget"):
        studies.register_constraint(Clash)
    with pytest.raises(studies.StudiesError, match="expected a class with TABLE_KEYS"):
        studies.register_constraint(int)
    with pytest.raises(studies.StudiesError, match="frequency_floor"):
        studies.optimize(_oscillator(), {"natural_frequency": (0.3, 2.2)}, objective="rms:x",
                         constraints={"frequency_flor": 0.5})
    with pytest.raises(studies.StudiesError, match="FrequencyFloor"):
        studies.optimize(_oscillator(), {"natural_frequency": (0.3, 2.2)}, objective="rms:x",
                         constraints=[object()])
    with pytest.raises(studies.StudiesError, match="constraints.max_harmonic: only with frequency_separation"):
        studies.optimize(_oscillator(), {"natural_frequency": (0.3, 2.2)}, objective="rms:x",
                         constraints={"max_harmonic": 2})
