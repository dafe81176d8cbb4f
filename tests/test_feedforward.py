"""The torque drive's feedforward switched on and off (``[drive] feedforward = true|false``).

The reference is a rigid crank turning in gravity, whose equation is written down here by hand:

    J theta'' = -m g (L/2) cos(theta) + tau,       J = I_c + m (L/2)^2 about the pivot,

so the feedforward (the inverse-dynamics torque of theta = w t) is ``m g (L/2) cos(w t)``. Without
feedforward and feedback the crank swings as this pendulum equation says (scipy integrates it);
with the feedforward alone it keeps the nominal motion; and the linearisation without feedforward
has the closed-form coefficients of the deviation ``x = theta - w t``:

    J x'' + kd x' + (kp - m g (L/2) sin(w t)) x = -m g (L/2) cos(w t).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import linearize
import mechanisms as mc

MASS, LENGTH, GRAVITY, RATE = 0.3, 0.1, 9.81, 10.0    # kg, m, m/s^2, rad/s
CENTROID_INERTIA = MASS * LENGTH**2 / 12.0             # kg m^2, uniform bar
PIVOT_INERTIA = CENTROID_INERTIA + MASS * (LENGTH / 2) ** 2
GRAVITY_MOMENT = MASS * GRAVITY * LENGTH / 2           # N m, peak of the feedforward


def _crank(*, feedforward: bool, kp: float = 0.0, kd: float = 0.0) -> mc.Mechanism:
    return mc.loads("\n".join([
        'name = "crank_in_gravity"', f"gravity = [0.0, {-GRAVITY}]", "[links.crank]",
        'type = "rigid"', f"length = {LENGTH}", f"mass = {MASS}", f"inertia = {CENTROID_INERTIA}",
        "[joints.O]", 'link_a = "ground"', "point_a = [0.0, 0.0]", 'link_b = "crank"',
        'point_b = "start"', "[drive]", 'type = "torque"', 'joint = "O"', f"rate = {RATE}",
        f"kp = {kp}", f"kd = {kd}", f"feedforward = {str(feedforward).lower()}"]) + "\n")


def _crank_angle_run(mechanism, n_periods=2.0, steps_per_period=400):
    run = mc.simulate(mechanism, n_periods=n_periods, steps_per_period=steps_per_period,
                      estimate_error=False)
    assert run.success, run.message
    return run.t, run.s @ mc.assemble(mechanism).drive_gradient("O")


def test_feedforward_key_is_read_written_back_and_checked():
    off = _crank(feedforward=False)
    assert off.drives[0].feedforward is False and _crank(feedforward=True).drives[0].feedforward
    assert mc.loads(off.to_toml()) == off
    assert off.with_parameter("drive.feedforward", True).drives[0].feedforward is True
    # without_feedback keeps the drive's feedforward as it is (on or off)
    assert off.without_feedback().drives[0].feedforward is False
    with pytest.raises(mc.MechanismError, match="feedforward must be true or false"):
        off.with_parameter("drive.feedforward", 1)
    assert set(mc.feedforward_torques(off, mc.nominal_motion(off, n_steps=16))) == set()


def test_without_feedforward_the_crank_swings_as_the_pendulum_equation_says():
    t, angle = _crank_angle_run(_crank(feedforward=False))

    def pendulum(_, y):
        return [y[1], -GRAVITY_MOMENT * math.cos(y[0]) / PIVOT_INERTIA]

    reference = solve_ivp(pendulum, (0.0, t[-1]), [0.0, RATE], t_eval=t, rtol=1e-11, atol=1e-12)
    deviation_from_nominal = np.abs(angle - RATE * t).max()
    assert deviation_from_nominal > 0.05          # it does not follow its nominal motion
    assert np.abs(angle - reference.y[0]).max() < 1e-3 * deviation_from_nominal


def test_with_the_feedforward_alone_the_crank_follows_its_nominal_motion():
    t, angle = _crank_angle_run(_crank(feedforward=True))
    _, swinging = _crank_angle_run(_crank(feedforward=False))
    assert np.abs(angle - RATE * t).max() < 1e-4 * np.abs(swinging - RATE * t).max()


@pytest.mark.parametrize("feedforward", [True, False])
def test_linearisation_without_feedforward_is_forced_by_the_missing_torque(feedforward):
    kp, kd = 5.0, 0.05
    lin = linearize.about(_crank(feedforward=feedforward, kp=kp, kd=kd), n_steps=64,
                          observables=["drive.O.torque"])
    t, system = lin.nominal.t, lin.system
    assert system.M[:, 0, 0] == pytest.approx(np.full(t.size, PIVOT_INERTIA), rel=1e-9)
    assert system.C[:, 0, 0] == pytest.approx(np.full(t.size, kd), rel=1e-9)
    stiffness = kp - GRAVITY_MOMENT * np.sin(RATE * t)
    assert system.K[:, 0, 0] == pytest.approx(stiffness, abs=1e-9 * kp)
    forcing = -GRAVITY_MOMENT * np.cos(RATE * t) if not feedforward else 0.0 * t
    assert system.f[:, 0] == pytest.approx(forcing, abs=1e-9 * GRAVITY_MOMENT)
    # the drive torque observable's nominal is the torque the law applies on the nominal motion
    nominal_torque = lin.observable_maps["drive.O.torque"].nominal
    expected = GRAVITY_MOMENT * np.cos(RATE * t) if feedforward else 0.0 * t
    assert nominal_torque == pytest.approx(expected, abs=1e-9 * GRAVITY_MOMENT)
