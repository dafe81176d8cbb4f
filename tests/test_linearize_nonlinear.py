"""Linear against nonlinear: the periodic steady state of the linearised thesis four-bar (Newmark
shooting) against the full nonlinear equations (generalized-alpha), run for six periods from the
linear periodic state so that what remains of the start-up transient has died out (1-2 % damping at
~300 rad/s loses ~70 % per period at this speed)."""

import numpy as np
import pytest

import linearize
import mechanisms as mc
import periodic

SPEC = "coupler.deflection@0.5"


def _linear_and_nonlinear(stiffness_factor, steps_per_period=1024):
    mechanism = mc.four_bar(discretisation="fem", n_elements=2, crank_speed=40.0,
                            youngs_modulus=2.0e11 * stiffness_factor)
    lin = linearize.about(mechanism, n_steps=512)
    steady = periodic.steady_state(lin.system, extrapolate=True)
    linear = lin.observe(steady.x)[SPEC]
    s, sdot = lin.full_state(steady.x, steady.v)
    run = mc.simulate(mechanism, n_periods=6, steps_per_period=steps_per_period, s0=s[0],
                      sdot0=sdot[0], observables=[SPEC], estimate_error=False)
    nonlinear = run.observables[SPEC][-steps_per_period - 1::steps_per_period // 512]
    return linear, nonlinear, mechanism.link("coupler").length


@pytest.fixture(scope="module")
def pairs():
    return {factor: _linear_and_nonlinear(factor) for factor in (1.0, 4.0)}


def test_linear_steady_state_matches_nonlinear_run_below_a_thousandth_of_the_length(pairs):
    linear, nonlinear, length = pairs[4.0]
    peak = np.abs(linear).max()
    assert peak < 1e-3 * length
    assert abs(np.abs(nonlinear).max() - peak) < 0.02 * peak
    # The whole period, not only the peak.
    assert np.abs(nonlinear - linear).max() < 0.02 * peak


def test_difference_shrinks_at_least_in_proportion_to_the_amplitude(pairs):
    """Scaling the coupler's modulus by 4 scales the response by ~1/4; the linear model's error is of
    higher order in the amplitude, so the relative difference must shrink at least fourfold. The
    difference must also stand well above the nonlinear integrator's own error (measured by halving
    the step), or the comparison would say nothing."""
    relative = {}
    for factor, (linear, nonlinear, _) in pairs.items():
        relative[factor] = np.abs(nonlinear - linear).max() / np.abs(linear).max()
    amplitude_ratio = np.abs(pairs[1.0][0]).max() / np.abs(pairs[4.0][0]).max()
    assert amplitude_ratio > 3.0
    assert relative[1.0] / relative[4.0] >= amplitude_ratio
    _, finer, _ = _linear_and_nonlinear(4.0, steps_per_period=2048)
    integrator_error = np.abs(finer - pairs[4.0][1]).max() / np.abs(pairs[4.0][0]).max()
    assert integrator_error < 0.2 * relative[4.0]
