"""Kelvin-Voigt damping of a stiffened link against the linear steady state at large amplitude.

The thesis four-bar at 100 rad/s bends its coupler by ~3 % of its length. Before the damping acted
on the projected membrane strain rate, the linear Kelvin-Voigt term beta EA int u' du' resisted the
chord shortening of the bent coupler (u' = -P[w'^2/2], no strain) as if it were a strain rate: a
large amplitude-dependent axial force that cut the nonlinear run's peak-to-peak midspan deflection
to 0.575 of the linear one (0.853 at 70 rad/s, 0.994 at 40 rad/s; converged in elements and steps).
An independent Exudyn model agreed with the linear result within 3.9 % at 100 rad/s. What remains
is a genuine nonlinear correction, which for a weakly nonlinear response grows as the square of the
amplitude: the tests pin both its size and that scaling.
"""

import numpy as np
import pytest

import linearize
import mechanisms as mc
import periodic

SPEC = "coupler.deflection@0.5"
STEPS = 1024          # per period; halving the step changes the ratio at 100 rad/s by ~3e-4
PERIODS = 16          # from the linear periodic state; 16 vs 32 periods differ by ~3e-4


def _relative_difference(speed):
    """1 - (peak-to-peak of the nonlinear run's last period) / (that of the linear steady state),
    and the linear peak over the coupler's length."""
    mechanism = mc.four_bar(discretisation="fem", n_elements=2, crank_speed=speed)
    lin = linearize.about(mechanism, n_steps=512)
    steady = periodic.steady_state(lin.system, extrapolate=True)
    linear = lin.observe(steady.x)[SPEC]
    s, sdot = lin.full_state(steady.x, steady.v)
    run = mc.simulate(mechanism, n_periods=PERIODS, steps_per_period=STEPS, s0=s[0],
                      sdot0=sdot[0], observables=[SPEC], estimate_error=False)
    nonlinear = run.observables[SPEC][-STEPS - 1:]
    return 1.0 - np.ptp(nonlinear) / np.ptp(linear), np.abs(linear).max() / mechanism.link(
        "coupler").length


@pytest.fixture(scope="module")
def differences():
    return {speed: _relative_difference(speed) for speed in (40.0, 70.0, 100.0)}


@pytest.mark.slow
def test_stiffened_coupler_keeps_the_linear_amplitude_at_100_rad_s(differences):
    """The damping locking removed 42.5 % of the amplitude; the genuine correction, estimated from
    the 40 rad/s run by its amplitude^2 scaling (see below), is ~10 %: the bound 10 % is four times
    below the locked value and is what the scaling predicts."""
    relative, amplitude = differences[100.0]
    assert amplitude > 0.02          # a large amplitude: the regime where the locking showed
    assert abs(relative) < 0.10


def test_difference_shrinks_as_the_square_of_the_amplitude(differences):
    """Lowering the speed lowers the amplitude; a weakly nonlinear correction scales as its square,
    so relative / (amplitude / L)^2 must be about constant (within a factor 2, the cubic and higher
    terms, and the phase of the resonance moving with speed) and the difference must shrink."""
    relative = {speed: r for speed, (r, _) in differences.items()}
    assert relative[40.0] < relative[70.0] < relative[100.0]
    coefficient = [r / a**2 for r, a in differences.values()]
    assert max(coefficient) < 2.0 * min(coefficient)
