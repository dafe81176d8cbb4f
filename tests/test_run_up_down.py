"""Run-down after a stop and the run-up's verdicts along the ramp (``studies.run_up``), each against an
independent reference: a coasting stiff arm (the motor off) against scipy's DOP853 of the rigid
pendulum; braking by a PD torque drive whose command is ramped to 0 against DOP853 of the rigid crank
under the same torque law; the per-revolution linear-range measures of a slow ramp against the closed
form of the arm's single-degree-of-freedom oscillator and against the steady states' own check."""

from __future__ import annotations

import math
import pathlib
import tomllib

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import mechanisms
import studies
from studies.cli import main

ARM = pathlib.Path(__file__).parent / "data" / "arm_sdof.toml"
TIP = "arm.transverse@1"
ARM_SCENE = tomllib.loads(ARM.read_text())
GRAVITY = -ARM_SCENE["gravity"][1]
#: The stiff arm: ten times the thickness (first mode 285 rad/s), nearly a rigid pendulum.
STIFF_THICKNESS = 0.02


def _stiff_arm_scene(**drive):
    scene = tomllib.loads(ARM.read_text())
    scene["links"]["arm"]["thickness"] = STIFF_THICKNESS
    scene["drive"].update(drive)
    return scene


def _stiff_arm(**drive):
    mechanism = mechanisms.build(_stiff_arm_scene(**drive), source="stiff arm")
    return studies.MechanismProblem.from_mechanism(mechanism, observables=[TIP])


def _rigid_arm():
    """(I about the root kg m^2, gravity moment arm m g L / 2 N m) of the stiff arm as a rigid
    pendulum (no rotary inertia of the section: rotary_inertia = false)."""
    link = ARM_SCENE["links"]["arm"]
    mass = link["density"] * link["width"] * STIFF_THICKNESS * link["length"]
    return mass * link["length"] ** 2 / 3.0, mass * GRAVITY * link["length"] / 2.0


def test_coast_follows_the_rigid_pendulum():
    """The motor off at 20 rad/s: the arm coasts under gravity, its speed the rigid pendulum's
    ``I theta'' = -m g L/2 cos theta`` (the arm's elastic sag changes it by about 3e-4)."""
    problem = _stiff_arm()
    result = studies.run_up(problem, start=20.0, stop=0.0, duration=1.2, start_state="linear", curve_points=0,
                            run_down="coast")
    assert result.status == "ok", result.message
    assert "coasting: the drives released at t = 0" in result.message and result.settings["run_down"] == "coast"
    inertia, moment = _rigid_arm()
    reference = solve_ivp(lambda t, y: [y[1], -moment * math.cos(y[0]) / inertia], (0.0, result.t[-1]),
                          [0.0, 20.0], method="DOP853", rtol=1e-11, atol=1e-12, dense_output=True)
    speed = reference.sol(result.t)[1]
    assert np.ptp(speed) > 1.0                      # gravity changes the speed along a turn
    # the rates of the first steps carry the scheme's start transient (the released drive's reaction
    # drops at once; rho_inf = 0.8 damps it within a period of the mode, 16 steps), 1.5 % at its largest
    np.testing.assert_allclose(result.drive_speed[:16], speed[:16], rtol=0.02)
    np.testing.assert_allclose(result.drive_speed[16:], speed[16:], rtol=0.0, atol=1e-4 * 20.0)
    np.testing.assert_allclose(result.drive_torque, 0.0, atol=0.0)     # the motor is off
    # each whole revolution's mean speed: 2 pi over the reference's time of a turn
    turns = [0.0]
    for n in range(1, result.speed.size + 1):
        turns.append(solve_ivp(lambda t, y: [y[1], -moment * math.cos(y[0]) / inertia], (0.0, 2.0),
                               [0.0, 20.0], method="DOP853", rtol=1e-11, atol=1e-12,
                               events=lambda t, y, n=n: y[0] - 2 * math.pi * n).t_events[0][0])
    np.testing.assert_allclose(result.speed, 2 * math.pi / np.diff(turns), rtol=1e-3)
    # what follows the last whole revolution is said and measured, not dropped
    assert result.tail_start == pytest.approx(turns[-1], rel=1e-3)
    assert "no whole revolution" in result.message and result.tail_peak_to_peak[TIP] > 0.0


def test_braking_by_the_motor_follows_the_rigid_crank():
    """A PD torque drive whose speed command goes 20 -> 0 rad/s in 1.5 s brakes the arm to a
    standstill: its speed and its torque (the deceleration's I alpha, gravity, the feedforward of
    gravity at the command's angle) are those of the rigid crank under the same law."""
    kp, kd = 2000.0, 40.0
    problem = _stiff_arm(type="torque", kp=kp, kd=kd)
    duration = 1.5
    result = studies.run_up(problem, start=20.0, stop=0.0, duration=duration, start_state="linear",
                            curve_points=0)
    assert result.status == "ok", result.message
    inertia, moment = _rigid_arm()
    ramp = mechanisms.SpeedRamp(20.0, 0.0, duration)

    def torque(t, y):
        angle, rate, _ = ramp.law(t)
        # the feedforward: the nominal torque at 20 rad/s (gravity's only) where the nominal has the
        # command's angle
        return moment * math.cos(angle) + kp * (angle - y[0]) + kd * (rate - y[1])

    reference = solve_ivp(lambda t, y: [y[1], (torque(t, y) - moment * math.cos(y[0])) / inertia],
                          (0.0, duration), [0.0, 20.0], method="DOP853", rtol=1e-11, atol=1e-12,
                          dense_output=True, max_step=1e-3)
    states = reference.sol(result.t)
    expected = np.array([torque(t, y) for t, y in zip(result.t, states.T)])
    assert np.abs(expected).max() > 5.0
    # after the scheme's start transient (the rates of the first period of the PD's mode, 16 steps:
    # the ramp's deceleration starts at once), which kd carries into the torque
    later = result.t > 16 * result.dt
    np.testing.assert_allclose(result.drive_speed[later], states[1][later], rtol=0.0, atol=1e-3 * 20.0)
    np.testing.assert_allclose(result.drive_torque[later], expected[later], rtol=0.0,
                               atol=5e-3 * np.abs(expected).max())
    # the deceleration: the mean speeds fall as the command's, and the crank ends at rest
    assert np.all(np.diff(result.speed) < 0) and abs(result.drive_speed[-1]) < 0.05
    alpha = -20.0 / duration
    assert np.median(result.drive_torque - moment * np.cos(states[0])) == pytest.approx(inertia * alpha, rel=0.05)


def test_refused_where_the_drive_cannot_run_down():
    feedforward_only = _stiff_arm(type="torque")
    with pytest.raises(studies.StudiesError, match="run_down / stop: the torque drive at 'O' has no feedback"):
        studies.run_up(feedforward_only, start=20.0, stop=0.0, duration=1.0, start_state="rest", curve_points=0)
    with pytest.raises(studies.StudiesError, match="run_down = 'coast' releases the drives .* expected stop = 0"):
        studies.run_up(feedforward_only, start=20.0, stop=10.0, duration=1.0, run_down="coast")
    with pytest.raises(studies.StudiesError, match="run_down: expected one of"):
        studies.run_up(feedforward_only, start=20.0, stop=0.0, duration=1.0, run_down="brake")


def test_scene_key_run_down(tmp_path):
    scene = tmp_path / "arm.toml"
    base = ARM.read_text() + "\n[studies]\nobservables = [\"arm.transverse@1\"]\n\n[studies.run_up]\n"
    scene.write_text(base + "start = 12.0\nstop = 6.0\nduration = 1.0\nrun_down = \"coast\"\n")
    assert main(["run", str(scene), "--out", str(tmp_path / "o.h5"), "--quiet"]) == 2
    table = {"start": 12.0, "stop": 0.0, "duration": 1.0, "run_down": "coast"}
    assert studies.kinds()["run_up"].check("studies.run_up", table, 128)["run_down"] == "coast"


def test_time_step_is_bounded_down_to_standstill():
    """A run-down to 0 takes its step from the elastic periods at both ends of the ramp, not from the
    revolutions of its slowest one: here the stiff arm's first mode (285 rad/s) at 16 steps."""
    result = studies.run_up(_stiff_arm(), start=20.0, stop=0.0, duration=0.5, start_state="linear",
                            curve_points=0, estimate_error=False)
    frequency = float(result.dt_reason.split("(")[1].split(" rad/s")[0])
    assert frequency == pytest.approx(285.0, rel=0.02)
    assert result.dt <= 2 * math.pi / frequency / 16 * (1 + 1e-12)
    assert "at 0.4 rad/s" in result.dt_reason or "at 20 rad/s" in result.dt_reason


# --- verdicts along the ramp --------------------------------------------------------------------------
def _arm_tip_amplitude(speed):
    """|tip Q| (m) of the flexible arm's steady state at a constant speed: tests/test_run_up.py's
    closed form of its single-degree-of-freedom oscillator."""
    from tests.test_run_up import _arm_oscillator, _steady_amplitude

    m, c, k, _, s0, tip = _arm_oscillator()
    return abs(tip * _steady_amplitude(speed, m, c, k, s0))


@pytest.fixture(scope="module")
def slow_arm_ramp():
    arm = studies.MechanismProblem.from_mechanism(mechanisms.load(str(ARM)), observables=[TIP])
    # a slow smooth ramp (its angular acceleration at most 0.1 rad/s^2) far below the resonance at
    # 20.2 rad/s: the response follows the steady states within the lag of a mode damped at 1 %
    result = studies.run_up(arm, start=14.0, stop=14.5, duration=8.0, start_state="linear", curve_points=3,
                            profile="smooth")
    return arm, result


def test_linear_range_along_a_slow_ramp_is_the_steady_states(slow_arm_ramp):
    """Per revolution the peak deflection over the section height is the steady state's at the
    revolution's speed (closed form), and the steady states' own check (solve_steady's measures) gives
    the same numbers and the same model-form verdict."""
    arm, result = slow_arm_ramp
    height = ARM_SCENE["links"]["arm"]["thickness"]
    measured = result.range_measures["arm.peak_deflection_over_height"][:-1]
    closed_form = np.array([_arm_tip_amplitude(w) for w in result.speed]) / height
    np.testing.assert_allclose(measured, closed_form, rtol=0.01)
    assert np.all(result.revolution_status[:-1] == "outside_linear_range")
    assert "along the ramp: outside the linear range in" in result.message
    assert "model form: link 'arm' has no geometric stiffening" in result.message.split("along the ramp")[1]
    from studies._numerics import solve_steady

    for k in (0, result.speed.size - 1):
        steady = solve_steady(arm.linearize({"speed": float(result.speed[k])}, n_steps=128))
        for name in ("peak_deflection_over_height", "peak_slope", "peak_compression_over_euler"):
            assert result.range_measures[f"arm.{name}"][k] == pytest.approx(
                steady.linear_range[f"arm.{name}"], rel=0.01, abs=1e-12), name
        assert steady.status == "outside_linear_range"


def test_is_stable_of_a_ramp_through_stable_states(slow_arm_ramp):
    _, result = slow_arm_ramp
    assert result.is_stable and np.all(result.curve_is_stable == 1.0)
    assert result.status != "unstable"


def test_instability_band_along_the_ramp_is_unstable():
    """The verdict from the frozen states: a band of unstable ones (a curve point whose linear
    Floquet radius exceeds 1) makes the run unstable and is_stable false, the band named."""
    from studies._kinds._run_up_checks import stability

    is_stable, verdicts, _ = stability(np.array([10.0, 11.0, 12.0, 13.0]), np.array([1.0, 0.0, 0.0, 1.0]), [])
    assert not is_stable
    assert verdicts[0][0] == "unstable" and "11-12 rad/s (2 of 4 curve points)" in verdicts[0][1]
    is_stable, verdicts, words = stability(np.zeros(0), np.zeros(0), [])
    assert is_stable and not verdicts and "not checked (curve_points = 0" in words


# --- the reduced model --------------------------------------------------------------------------------
def test_reduced_model_run_up_against_the_full_one():
    """modes = "auto": the run on the reduced coupler (its reduction check at the ramp's ends and
    resonances) gives the full model's per-revolution peak to peak within the two runs' time-step
    estimates and the stated reduction error."""
    problem = studies.MechanismProblem.from_scene("four_bar_fem4")
    options = dict(start=60.0, stop=64.0, duration=1.0, curve_points=0, mode_steps=24)
    full = studies.run_up(problem, modes="full", **options)
    reduced = studies.run_up(problem, **options)   # the default, modes = "auto"
    assert full.status == reduced.status == "ok", (full.message, reduced.message)
    assert reduced.reduced_modes == {"coupler": 4} and not full.reduced_modes
    assert "on the reduced model (coupler 4 modes" in reduced.message and "full element models" in full.message
    for spec in full.units:
        stated = reduced.reduction_error[spec]
        assert 0.0 < stated < 0.01 * reduced.largest[spec]
        difference = np.abs(full.peak_to_peak[spec] - reduced.peak_to_peak[spec])
        allowed = 3.0 * (full.peak_to_peak_error[spec] + reduced.peak_to_peak_error[spec]) + stated
        assert np.all(difference <= allowed), (difference, allowed)
    with pytest.raises(studies.StudiesError, match="modes: expected 'auto'"):
        studies.run_up(problem, modes="some", **options)


@pytest.mark.slow
def test_run_down_through_resonance_to_a_standstill_against_the_oscillator():
    """The flexible arm run down 28 -> 0 rad/s in 5 s through its resonance (20.2 rad/s) to a stop:
    each whole revolution's peak to peak is the DOP853 oscillator's within 3x its error estimate, the
    largest after the resonance in the sweep's direction (below it), and what follows the last whole
    revolution (a third of a turn to the stop) the oscillator's there."""
    from tests.test_run_up import _arm_oscillator, _only_the_model_form_verdict

    arm = studies.MechanismProblem.from_mechanism(mechanisms.load(str(ARM)), observables=[TIP])
    start, duration = 28.0, 5.0
    result = studies.run_up(arm, start=start, stop=0.0, duration=duration, start_state="linear", n_steps=128,
                            curve_points=0)
    verdicts = _only_the_model_form_verdict(result, start)
    assert "along the ramp: outside the linear range" in verdicts   # the model form, revolution by revolution
    m, c, k, s, s0, tip = _arm_oscillator()
    rate = -start / duration

    def rhs(t, y):
        angle, speed = start * t + 0.5 * rate * t * t, start + rate * t
        return [y[1], (-c * y[1] - (k - m * speed**2) * y[0] - s * rate - GRAVITY * s0 * math.cos(angle)) / m]

    from tests.test_run_up import _steady_amplitude

    q = _steady_amplitude(start, m, c, k, s0)
    solution = solve_ivp(rhs, (0.0, duration), [q.real, (1j * start * q).real], method="DOP853", rtol=1e-11,
                         atol=1e-14, dense_output=True)
    ends = [(-start + math.sqrt(start**2 + 2.0 * rate * 2 * math.pi * j)) / rate
            for j in range(result.speed.size + 1)]
    reference = np.array([np.ptp(tip * solution.sol(np.linspace(a, b, 4001))[0]) for a, b in zip(ends, ends[1:])])
    np.testing.assert_allclose(result.speed, 2 * math.pi / np.diff(ends), rtol=1e-6)
    ptp, error = result.peak_to_peak[TIP], result.peak_to_peak_error[TIP]
    assert np.all(np.abs(ptp - reference) <= 3.0 * error + 1e-3 * reference.max()), np.c_[result.speed, ptp,
                                                                                          reference, error]
    assert result.speed_at_largest[TIP] < 20.19 - 0.3
    tail = np.ptp(tip * solution.sol(np.linspace(ends[-1], duration, 4001))[0])
    assert result.tail_start == pytest.approx(ends[-1], rel=1e-6)
    assert result.tail_peak_to_peak[TIP] == pytest.approx(tail, abs=3.0 * result.tail_peak_to_peak_error[TIP]
                                                          + 1e-3 * reference.max())
    assert "no whole revolution" in result.message and "final speed" in result.message
