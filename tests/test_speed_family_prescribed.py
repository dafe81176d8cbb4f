"""``linearize.speed_family`` beyond one constant-rate crank: harmonic drive laws and several
prescribed drives (the 3-RRR ``parallel_robot``). Every prescribed drive's angle is a function of
the phase ``2 pi t / period``, so the coefficients stay quadratic in the speed ``2 pi / period``;
checked against direct linearisation (``linearize.about``) of the mechanism rebuilt at each speed,
and, through ``studies``, a stability-chart cell and a sweep point against the same computation
done by hand on the directly linearised system. Torque drives keep the direct route."""

import math

import numpy as np
import pytest

import linearize
import mechanisms as mc
import periodic
import studies
from studies._numerics import STUDY_SCHEME, extremes  # the studies' own scheme and extremes: no public face

N_STEPS = 32  # the charts' minimum; the robot's coefficients are resolved at 32 samples
PAYLOAD = "point_masses.payload.mass"
ROBOT_SPECS = ("platform.point_error_x@centre", "proximal1.transverse@1.0", "drive.O1.torque",
               "joint.E2.fx", "proximal3.stress_top@0.5")


def assert_systems_equal(fast, direct, tol=1e-11):
    """Same period and coefficients; the three-speed quadratic fit leaves round-off amplified by
    (speed / base speed)^2 at most ~100 here."""
    assert fast.period == pytest.approx(direct.period, rel=1e-14)
    for name in ("M", "C", "K", "f"):
        a, b = getattr(fast, name), getattr(direct, name)
        np.testing.assert_allclose(a, b, rtol=0, atol=tol * np.abs(b).max(), err_msg=name)


def assert_multiplier_maps_equal(fast, direct):
    """The maps of the multipliers' change (A_x, A_v, A_a) of a family member against a direct
    linearisation's: present on both (the specs include a joint force) and equal."""
    assert len(direct.coefficients.multiplier_maps) == 3
    for name, mine, theirs in zip(("A_x", "A_v", "A_a"), fast.coefficients.multiplier_maps,
                                  direct.coefficients.multiplier_maps):
        np.testing.assert_allclose(mine, theirs, rtol=0, atol=1e-9 * np.abs(theirs).max(),
                                   err_msg=name)


def assert_maps_equal(fast, direct, specs):
    for spec in specs:
        for name, expected in direct[spec].arrays().items():
            np.testing.assert_allclose(fast[spec].arrays()[name], expected, rtol=0,
                                       atol=1e-9 * np.abs(expected).max(),
                                       err_msg=f"{spec} {name}")


def robot_at(robot, speed, payload=None):
    """The robot rebuilt with its period 2 pi / speed (and the payload mass, kg)."""
    changes = {"period": 2.0 * math.pi / speed}
    if payload is not None:
        changes[PAYLOAD] = payload
    return robot.with_parameters(changes)


@pytest.fixture(scope="module")
def robot():
    return mc.load("parallel_robot")


@pytest.fixture(scope="module")
def robot_family(robot):
    return linearize.speed_family(robot, n_steps=N_STEPS, observables=ROBOT_SPECS)


def test_robot_family_speed_is_the_fundamental_frequency(robot, robot_family):
    assert robot_family.rate == pytest.approx(2.0 * math.pi / robot.period, rel=1e-15)
    assert robot_family.base.system.period == robot.period


@pytest.mark.parametrize("speed", [20.0, 95.0, 280.0])
def test_robot_family_equals_direct_linearisation(robot, robot_family, speed):
    """Coefficients, observable maps (joint force, drive torque, stress with its nominal axial
    part), linear-range axial forces and the rebuilt mechanism at three speeds."""
    direct = linearize.about(robot_at(robot, speed), n_steps=N_STEPS, observables=ROBOT_SPECS)
    fast = robot_family.at_speed(speed)
    assert_systems_equal(fast.system, direct.system)
    assert_maps_equal(robot_family.observable_maps_at(speed), direct.observable_maps, ROBOT_SPECS)
    assert_multiplier_maps_equal(fast, direct)
    for mine, theirs in zip(fast.range_probes, direct.range_probes):
        np.testing.assert_allclose(mine.axial, theirs.axial, rtol=0,
                                   atol=1e-10 * np.abs(theirs.axial).max())
    assert fast.mechanism.period == pytest.approx(direct.mechanism.period, rel=1e-15)
    assert [d.rate for d in fast.mechanism.drives] == [d.rate for d in direct.mechanism.drives]
    np.testing.assert_allclose(fast.nominal.sddot, direct.nominal.sddot, rtol=0,
                               atol=1e-9 * np.abs(direct.nominal.sddot).max())


def harmonic_four_bar(turns=1, sign=1.0, base_speed=100.0):
    """The thesis four-bar whose crank turns ``turns`` times per period (direction ``sign``) with
    a harmonic speed fluctuation at the fundamental 2 pi / period and its second multiple: period
    2 pi / ``base_speed``, explicit when the crank turns more than once."""
    four_bar = mc.four_bar(discretisation="fem", n_elements=2, gravity=(0.0, -9.81))
    drive = mc.PrescribedDrive("O", rate=sign * turns * base_speed, offset=0.3,
                               harmonics=((1, 0.08, -0.05), (2, 0.02, 0.03)))
    period = None if turns == 1 else 2.0 * math.pi / base_speed
    return four_bar.replace(drives=(drive,), period=period)


def four_bar_at(mechanism, speed):
    """``mechanism`` rebuilt by hand with its motion's fundamental frequency ``speed`` (> 0)."""
    drive = mechanism.drives[0]
    turns = drive.rate * mechanism.period / (2.0 * math.pi)
    faster = mc.PrescribedDrive("O", rate=turns * speed, offset=drive.offset,
                                harmonics=drive.harmonics)
    period = None if mechanism.period_is_default else 2.0 * math.pi / speed
    return mechanism.replace(drives=(faster,), period=period)


@pytest.mark.parametrize("turns, sign", [(1, 1.0), (2, -1.0)])
def test_harmonic_four_bar_family_equals_direct_linearisation(turns, sign):
    """A crank with a harmonic drive law, turning once counter-clockwise (the period its rate's)
    or twice clockwise per explicit period: the family's speed is 2 pi / period signed like the
    crank, and at_speed equals the four-bar rebuilt by hand at that speed."""
    specs = ("coupler.deflection@0.5", "drive.O.torque", "joint.A.fy")
    mechanism = harmonic_four_bar(turns, sign)
    family = linearize.speed_family(mechanism, n_steps=64, observables=specs)
    assert family.rate == pytest.approx(sign * 100.0, rel=1e-15)
    for speed in (37.0, 161.0):
        direct = linearize.about(four_bar_at(mechanism, speed), n_steps=64, observables=specs)
        fast = family.at_speed(sign * speed)
        assert_systems_equal(fast.system, direct.system)
        assert_maps_equal(fast.observable_maps, direct.observable_maps, specs)
        assert_multiplier_maps_equal(fast, direct)
        assert fast.mechanism.drives[0].rate == pytest.approx(direct.mechanism.drives[0].rate,
                                                               rel=1e-15)
    with pytest.raises(ValueError, match="same sign"):
        family.at_speed(-sign * 50.0)


def test_torque_drive_is_refused_by_the_family_and_linearised_directly_by_studies():
    """A torque drive (feedforward plus PD law) has no speed family; a study problem linearises
    it afresh at each speed, as the direct route does."""
    four_bar = mc.four_bar(discretisation="fem", n_elements=1)
    torque_driven = four_bar.replace(drives=(mc.TorqueDrive("O", rate=100.0, kp=10.0, kd=1.0),))
    with pytest.raises(linearize.LinearizationError, match="PrescribedDrive"):
        linearize.speed_family(torque_driven, n_steps=16)
    problem = studies.MechanismProblem.from_mechanism(torque_driven)
    for speed in (100.0, 140.0):
        linear = problem.linearize({"speed": speed}, n_steps=32, context=False)
        direct = linearize.about(torque_driven.replace(drives=(mc.TorqueDrive(
            "O", rate=speed, kp=10.0, kd=1.0),)), n_steps=32)
        assert_systems_equal(linear.system, direct.system, tol=1e-13)


def test_studies_use_the_family_for_a_clockwise_crank():
    """The studies' speed is 2 pi / period (positive); a clockwise crank's family has a negative
    speed: a problem must hand it the signed one."""
    mechanism = harmonic_four_bar(1, -1.0)
    problem = studies.MechanismProblem.from_mechanism(mechanism)
    for speed in (60.0, 140.0):
        linear = problem.linearize({"speed": speed}, n_steps=32, context=False)
        direct = linearize.about(four_bar_at(mechanism, speed), n_steps=32)
        assert_systems_equal(linear.system, direct.system)


def test_robot_chart_cells_equal_the_directly_linearised_ones(robot):
    """Each cell of a small speed x payload chart of the robot (its speed family per payload)
    against Floquet multipliers of the robot rebuilt and linearised at that cell: the spectral
    radius and its error estimate to round-off, across the loss of stability."""
    problem = studies.MechanismProblem.from_mechanism(robot, parameter_paths=(PAYLOAD,))
    speeds, payloads = np.array([150.0, 240.0, 300.0]), np.array([0.5, 2.0])
    chart = studies.stability_chart(problem, ("speed", speeds), (PAYLOAD, payloads),
                                    n_steps=N_STEPS)
    for i, speed in enumerate(speeds):
        for j, payload in enumerate(payloads):
            system = linearize.about(robot_at(robot, speed, payload), n_steps=N_STEPS).system
            direct = periodic.floquet(system, scheme=STUDY_SCHEME, estimate_error=True)
            assert chart.spectral_radius[i, j] == pytest.approx(direct.spectral_radius, rel=1e-9)
            assert chart.spectral_radius_error[i, j] == pytest.approx(
                direct.spectral_radius_error, rel=1e-6, abs=1e-12)
            assert bool(chart.is_stable[i, j]) == direct.is_stable
    assert chart.is_stable.any() and not chart.is_stable.all()


def test_robot_sweep_points_equal_the_directly_linearised_ones(robot):
    """Peak-to-peak responses of a speed sweep of the robot (deviation, torque, joint force,
    stress) against the steady state of the directly linearised robot at each speed."""
    problem = studies.MechanismProblem.from_mechanism(robot, observables=ROBOT_SPECS)
    speeds = np.array([40.0, 120.0])
    sweep = studies.sweep(problem, "speed", speeds, n_steps=N_STEPS)
    for k, speed in enumerate(speeds):
        lin = linearize.about(robot_at(robot, speed), n_steps=N_STEPS, observables=ROBOT_SPECS)
        response = lin.observe(periodic.steady_state(lin.system, scheme=STUDY_SCHEME).x)
        for spec in ROBOT_SPECS:
            high, low, _, _ = extremes(response[spec])
            assert sweep.peak_to_peak[spec][k] == pytest.approx(high - low, rel=1e-8), spec
