"""Joint forces, torques, stresses and point errors in the studies: peaks and peak-to-peak with
their errors (closed form), the speed-family route against a direct linearisation, the HDF5
fields with units, and the linear totals against the full nonlinear model's multipliers."""

import math

import h5py
import numpy as np
import pytest

import mechanisms as mc
import studies
from studies._numerics import peak_summary  # the studies' internal peak measure: no public face

SPECS = ("coupler.deflection@0.5", "joint.B.fx", "joint.A.force", "drive.O.torque",
         "coupler.stress_top@0.5", "coupler.point_error@0.5")
UNITS = {"coupler.deflection@0.5": "m", "joint.B.fx": "N", "joint.A.force": "N",
         "drive.O.torque": "N m", "coupler.stress_top@0.5": "Pa", "coupler.point_error@0.5": "m"}


def _mechanism(rate=100.0):
    return mc.four_bar(discretisation="fem", n_elements=2, axial=False,
                       geometric_stiffening=False, crank_speed=rate)


def test_peak_and_peak_to_peak_of_a_sampled_harmonic_against_the_closed_form():
    """offset + A cos(k phi + phase) sampled coarsely: peak |offset| + A, peak-to-peak 2 A; the
    refined extremes are within the reported error (the sampling correction bounds the rest)."""
    n, k, amplitude, offset = 48, 3, 2.0, -0.7
    phi = np.linspace(0.0, 2 * math.pi, n + 1)
    samples = offset + amplitude * np.cos(k * phi + 0.3)
    error = 1e-3
    result = peak_summary(samples[:, None], np.array([error]))
    assert result["peak"][0] == pytest.approx(abs(offset) + amplitude, abs=result["peak_error"][0])
    assert result["peak_to_peak"][0] == pytest.approx(2 * amplitude,
                                                      abs=result["peak_to_peak_error"][0])
    # the refinement does better than the raw samples, whose miss is up to A (k dphi)^2 / 8
    raw_miss = 2 * amplitude - np.ptp(samples)
    assert abs(result["peak_to_peak"][0] - 2 * amplitude) < 0.1 * raw_miss
    assert result["peak_to_peak_error"][0] >= 2 * error


@pytest.mark.slow
def test_sweep_reports_force_peaks_as_a_direct_steady_state_does(tmp_path):
    """The sweep's grid points take the speed family's maps at each speed; a steady state of the
    scene built at that speed linearises directly. Their peaks and time-step errors agree (the error
    budget is left out, ``budget=False``: the sweep's mesh term is the scene point's applied
    relatively, its linearisation term takes fewer chord steps); the file keeps the fields with their
    units."""
    speeds = np.array([60.0, 100.0, 140.0])
    problem = studies.MechanismProblem.from_mechanism(_mechanism(), observables=SPECS)
    with studies.open_file(tmp_path / "run.h5") as out:
        swept = studies.sweep(problem, "speed", speeds, n_steps=64, out=out, budget=False)
    for i, rate in enumerate(speeds):
        direct = studies.steady_state(
            studies.MechanismProblem.from_mechanism(_mechanism(rate), observables=SPECS),
            n_steps=64, budget=False)
        for spec in SPECS:
            assert direct.units[spec] == UNITS[spec]
            for name in ("peak", "peak_to_peak", "peak_error", "peak_to_peak_error"):
                expected = getattr(direct, name)[spec]
                assert getattr(swept, name)[spec][i] == pytest.approx(expected, rel=1e-6), \
                    (spec, name, rate)
        if rate == 100.0:
            # the error estimates have the size of the actual error (against 16 times the steps),
            # for the forces as for the deflection (the order-2 estimate at a coarse N = 64 is
            # outside its asymptotic range: within a factor of 3)
            fine = studies.steady_state(
                studies.MechanismProblem.from_mechanism(_mechanism(rate), observables=SPECS),
                n_steps=1024)
            for spec in SPECS:
                for name in ("peak", "peak_to_peak"):
                    actual = abs(getattr(direct, name)[spec] - getattr(fine, name)[spec])
                    assert actual < 3.0 * getattr(direct, f"{name}_error")[spec], (spec, name)
    # joint forces are totals: their peak is of the order of the nominal force, not the vibration
    assert direct.peak["joint.A.force"] > 10.0
    loaded = studies.load(tmp_path / "run.h5")["sweep"]
    np.testing.assert_array_equal(loaded.peak["joint.A.force"], swept.peak["joint.A.force"])
    with h5py.File(tmp_path / "run.h5", "r") as handle:
        for name in ("peak", "peak_error", "peak_to_peak", "peak_to_peak_error"):
            for spec, unit in UNITS.items():
                assert handle["sweep"][name][spec].attrs["units"] == unit


@pytest.mark.slow
def test_linear_forces_torque_and_stress_agree_with_the_full_nonlinear_model():
    """The nonlinear check runs the full model (generalized-alpha, its own multipliers) from the
    linear periodic state: the totals of joint forces and drive torque, the stress and the point
    error follow the linear prediction to well under 1 % of their peak-to-peak."""
    problem = studies.MechanismProblem.from_mechanism(_mechanism(), observables=SPECS)
    check = studies.nonlinear_check(problem, n_steps=128, n_periods=3)
    assert check.verdict == "agrees", check.message
    for spec in SPECS:
        assert check.relative_difference[spec] < 0.01, (spec, check.relative_difference[spec])


@pytest.mark.slow
def test_torque_driven_arm_agrees_with_the_full_nonlinear_model():
    """A torque drive's total torque (feedforward plus PD change), the other drive's, a joint
    force, the tip's point error and the root stress against the full model (the run's own
    multipliers and torque law)."""
    arm = mc.load("two_link_arm")
    elbow = next(d for d in arm.drives if d.joint == "elbow")
    driven = arm.replace(drives=tuple(
        mc.TorqueDrive("elbow", elbow.rate, elbow.offset, elbow.harmonics, kp=40.0, kd=0.5)
        if d.joint == "elbow" else d for d in arm.drives))
    specs = ("drive.elbow.torque", "drive.shoulder.torque", "joint.elbow.force",
             "forearm.point_error@end", "forearm.stress_top@0.0")
    check = studies.nonlinear_check(
        studies.MechanismProblem.from_mechanism(driven, observables=specs), n_steps=128,
        n_periods=2)
    assert check.verdict == "agrees", check.message
    for spec in specs:
        assert check.relative_difference[spec] < 0.01, (spec, check.relative_difference[spec])


def test_a_turning_links_angle_deviation_does_not_gain_two_pi_per_period():
    """The crank of a prescribed drive follows its nominal angle exactly, also after several turns:
    the nonlinear run's ``crank.angle`` deviation stays at round-off (it used to gain 2 pi per
    period, the run's angle growing while the repeated nominal did not)."""
    problem = studies.MechanismProblem.from_mechanism(_mechanism(), observables=("crank.angle",))
    check = studies.nonlinear_check(problem, n_periods=3, n_steps=64)
    deviation = np.asarray(check.nonlinear["crank.angle"])
    assert deviation.size > 2 * 64 and np.abs(deviation).max() < 1e-6
