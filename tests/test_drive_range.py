"""The torque drives' saturation measures in a study point's linear range (``studies._verdicts``):
the peak demanded torque over ``torque_limit`` and the motor's peak command over ``G stall_torque``,
checked against the drive torque the steady state reports as an observable and the motor's
characteristic written out here; they reach the result file."""

from __future__ import annotations

import numpy as np
import pytest

import mechanisms
import studies


def test_steady_state_reports_the_drive_measures_and_writes_them(tmp_path):
    scene = mechanisms.load("four_bar_controlled")
    problem = studies.MechanismProblem.from_mechanism(scene, observables=["drive.O.torque",
                                                                          "coupler.deflection@0.5"])
    result = studies.steady_state(problem, n_steps=128)
    drive, motor = scene.drives[0], scene.drives[0].motor
    torque = np.asarray(result.response["drive.O.torque"])
    ratio = result.linear_range["drive.O.peak_torque_over_limit"]
    assert ratio == pytest.approx(np.abs(torque).max() / drive.torque_limit, rel=1e-6)
    # the command is the torque plus the back EMF of the crank's rate, c theta' (c = G^2 T_s / w0)
    command = result.linear_range["drive.O.peak_command_over_limit"] * motor.gear_ratio * motor.stall_torque
    c = motor.gear_ratio**2 * motor.stall_torque / motor.no_load_speed
    assert np.abs(torque).max() < command <= np.abs(torque).max() + c * 1.1 * drive.rate
    assert command == pytest.approx(3.05, abs=0.05)   # the scene's comment: 3.05 N m of 4
    assert result.status != "outside_linear_range" and ratio < 1.0
    path = tmp_path / "steady.h5"
    result.save(path, "steady")
    back = studies.load(path)["steady"]
    assert back.linear_range["drive.O.peak_torque_over_limit"] == ratio


def test_a_drive_without_limits_has_no_measure_and_a_saturating_one_is_above_one():
    scene = mechanisms.load("four_bar_controlled")
    unlimited = scene.replace(drives=(scene.drives[0].__class__(
        **{**scene.drives[0].__dict__, "motor": None, "torque_limit": float("inf")}),))
    result = studies.steady_state(studies.MechanismProblem.from_mechanism(unlimited), n_steps=128)
    assert "drive.O.peak_torque_over_limit" not in result.linear_range   # nothing to measure against
    tight = scene.with_parameter("drive.torque_limit", 1.0)
    result = studies.steady_state(studies.MechanismProblem.from_mechanism(tight), n_steps=128)
    assert result.linear_range["drive.O.peak_torque_over_limit"] > 1.0
    assert result.status == "outside_linear_range" and "peak demanded torque" in result.message
