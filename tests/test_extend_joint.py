"""A new kind of joint defined outside the packages with public API only: a gear pair.

The gear holds a fixed ratio between the material angles of two links,
``theta_b = offset - ratio * theta_a``: one ``mechanisms.AngleRow`` (a linear row, no new kernel),
registered with ``mechanisms.register_joint`` (defined in ``tests/_support/extensions.py``). It is
checked against what does not know of it:

* the rigid kinematics and inverse dynamics in closed form (a wheel pinned at its centroid and
  geared to the crank of the thesis four-bar turns at ``-ratio`` times the crank; the gear's torque
  on it is ``I alpha`` of the wheel; the crank needs ``ratio^2 I alpha_crank`` more torque than the
  four-bar alone);
* an equivalent model: the geared wheel adds the inertia ``ratio^2 I`` to the crank, so under a
  torque drive with PD feedback (the crank free to vibrate) the steady state of the geared
  four-bar equals that of the four-bar with a flywheel ``ratio^2 I`` on its crank;

and it goes through a study's steady state, its result file and the scene text.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

import mechanisms
import studies
from tests._support.extensions import Gear

RATIO, OFFSET = 2.0, 0.3        # a whole ratio: the wheel returns after one period
WHEEL_INERTIA = 4e-5        # kg m^2 about its centroid, the pivot
HARMONIC = 0.05             # rad: the crank's angle oscillates about its mean rate


def _four_bar(drive) -> mechanisms.Mechanism:
    base = mechanisms.load("four_bar_ritz")
    return base.replace(drives=(drive,))


def _geared(drive) -> mechanisms.Mechanism:
    base = _four_bar(drive)
    wheel = mechanisms.RigidLink("wheel", 0.03, mass=0.05, inertia=WHEEL_INERTIA, centroid=(0.0, 0.0))
    joints = base.joints + (mechanisms.Revolute("W", "ground", (0.05, -0.08), "wheel", "start"),
                            Gear("G", "crank", "start", "wheel", "start", RATIO, OFFSET))
    return base.replace(links=base.links + (wheel,), joints=joints)


def _prescribed():
    return mechanisms.PrescribedDrive("O", rate=100.0, harmonics=((1, HARMONIC, 0.0),))


def test_gear_is_registered_and_its_scene_table_round_trips():
    assert mechanisms.JOINT_TYPES["gear"] is Gear
    mech = _geared(_prescribed())
    again = mechanisms.loads(mech.to_toml())
    assert again == mech and again.joint("G") == mech.joint("G")
    with pytest.raises(mechanisms.MechanismError, match="ratio"):
        mechanisms.build({**mech.to_spec(), "joints": {**mech.to_spec()["joints"],
                                                        "G": {"type": "gear", "link_a": "crank",
                                                              "point_a": "start",
                                                              "link_b": "wheel",
                                                              "point_b": "start"}}})
    with pytest.raises(mechanisms.MechanismError, match="already"):
        mechanisms.register_joint(type("Other", (Gear,), {}))


def test_geared_wheel_follows_the_crank_and_carries_the_closed_form_torque():
    mech = _geared(_prescribed())
    motion = mechanisms.nominal_motion(mech, n_steps=128)
    model = motion.model
    crank, wheel = model.link_coordinates("crank"), model.link_coordinates("wheel")
    theta_c, theta_w = motion.s[:, crank.start + 2], motion.s[:, wheel.start + 2]
    np.testing.assert_allclose(theta_w, OFFSET - RATIO * theta_c, rtol=0, atol=1e-12)
    # the drive's closed-form angle: 100 t + 0.05 cos(w t)
    _, _, alpha_c = mechanisms.drive_law(mech.drives[0], mech.period, motion.t)
    alpha_w = -RATIO * alpha_c
    torque = model.observable("joint.G.torque")
    assert torque.unit == "N m"
    gear_torque = np.array([torque.value_from(lam) for lam in motion.lam])
    scale = WHEEL_INERTIA * np.abs(alpha_w).max()
    np.testing.assert_allclose(gear_torque, WHEEL_INERTIA * alpha_w, rtol=0, atol=1e-9 * scale)
    # the crank needs ratio^2 I alpha_crank on top of the four-bar's own torque
    alone = mechanisms.nominal_motion(_four_bar(_prescribed()), n_steps=128)
    extra = motion.drive_torque[:, 0] - alone.drive_torque[:, 0]
    np.testing.assert_allclose(extra, RATIO**2 * WHEEL_INERTIA * alpha_c, rtol=0,
                               atol=1e-9 * np.abs(alone.drive_torque).max())
    rows = model.joint_rows("G")
    assert rows.kind == "gear" and not rows.point_force and len(rows.rows) == 1
    with pytest.raises(mechanisms.ArgumentError, match=r"'fx'.*expected one of \['torque'\]"):
        model.observable("joint.G.fx")


def test_geared_steady_state_equals_a_flywheel_of_the_reflected_inertia(tmp_path, assert_same):
    torque = mechanisms.TorqueDrive("O", rate=100.0, kp=2.0, kd=0.02)
    geared = _geared(torque)
    flywheel = _four_bar(dataclasses.replace(torque, flywheel=RATIO**2 * WHEEL_INERTIA))
    specs = ("coupler.deflection@0.5", "drive.O.torque", "crank.angle")
    results = [studies.steady_state(studies.MechanismProblem.from_mechanism(m, observables=specs),
                                    n_steps=128) for m in (geared, flywheel)]
    for spec in specs:
        a, b = results[0].response[spec], results[1].response[spec]
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-8 * np.abs(b).max())
    assert results[0].peak_to_peak["coupler.deflection@0.5"] > 1e-6  # it vibrates
    # the result file of the geared steady state reads back, and its scene rebuilds the gear
    path = tmp_path / "geared.h5"
    results[0].save(path, "steady")
    loaded = studies.load(path)["steady"]
    assert_same(results[0], loaded)
    assert mechanisms.loads(loaded.scene).joint("G") == geared.joint("G")


def test_gear_torque_observable_through_the_linearisation_is_the_closed_form():
    mech = _geared(_prescribed())
    result = studies.steady_state(studies.MechanismProblem.from_mechanism(
        mech, observables=("joint.G.torque", "coupler.deflection@0.5")), n_steps=128)
    t = result.t
    _, _, alpha_c = mechanisms.drive_law(mech.drives[0], mech.period, t)
    expected = -RATIO * WHEEL_INERTIA * alpha_c   # the crank is prescribed: the wheel is rigid
    np.testing.assert_allclose(result.response["joint.G.torque"], expected, rtol=0,
                               atol=1e-9 * np.abs(expected).max())
    assert result.units["joint.G.torque"] == "N m"
    assert math.isfinite(result.peak["joint.G.torque"])
