"""A new drive kind defined outside the packages with public API only: ``ServoDrive``, a torque drive
whose PD gains follow from a closed-loop bandwidth, registered with ``mechanisms.register_drive``. The
scene reader, the scene writer, the ``Mechanism``'s checks, the nominal motion, the linearisation and
``without_feedback`` must treat it exactly as the built-in ``TorqueDrive`` with the same gains (an
equivalent model: the same linearised coefficients)."""

from __future__ import annotations

import copy

import numpy as np
import pytest

import linearize
import mechanisms as mc
from tests._support.extensions import ServoDrive

BANDWIDTH, DAMPING_RATIO, CRANK_INERTIA = 40.0, 0.6, 2e-3   # rad/s, 1, kg m^2
N_STEPS = 32


@pytest.fixture(scope="module")
def pair():
    """(the controlled four-bar with a servo drive from its scene table, the same with the built-in
    torque drive of kp = J w^2, kd = 2 zeta J w)."""
    base = mc.load("four_bar_controlled")
    spec = copy.deepcopy(base.spec)
    table = dict(spec.pop("drive"))
    joint = table.pop("joint")
    table.update(type="servo", bandwidth=BANDWIDTH, damping_ratio=DAMPING_RATIO, crank_inertia=CRANK_INERTIA)
    spec["drives"] = {joint: table}
    mine = mc.Mechanism.from_spec(spec)
    kp, kd = CRANK_INERTIA * BANDWIDTH**2, 2.0 * DAMPING_RATIO * CRANK_INERTIA * BANDWIDTH
    built_in = base.replace(drives=(mc.TorqueDrive(joint, rate=table["rate"], kp=kp, kd=kd,
                                                   motor=base.drives[0].motor, flywheel=0.0,
                                                   torque_limit=table["torque_limit"]),))
    return mine, built_in


def assert_same_system(a, b):
    assert a.period == b.period
    for name in ("M", "C", "K", "f"):
        x, y = getattr(a, name), getattr(b, name)
        np.testing.assert_allclose(x, y, rtol=0, atol=1e-12 * np.abs(y).max(), err_msg=name)


def test_the_scene_reader_builds_the_registered_kind(pair):
    mine, _ = pair
    assert mc.DRIVE_TYPES["servo"] is ServoDrive
    (drive,) = mine.drives
    assert isinstance(drive, ServoDrive) and not drive.IMPOSES_MOTION
    assert mine.torque_drives == (drive,)
    assert drive.kp == pytest.approx(CRANK_INERTIA * BANDWIDTH**2, rel=1e-15) and drive.kp > 0.0


def test_it_linearises_as_its_built_in_equivalent(pair):
    mine, built_in = pair
    ours, theirs = (linearize.about(m, n_steps=N_STEPS) for m in pair)
    assert_same_system(ours.system, theirs.system)
    # the gains enter: without them the coefficients differ
    loose = linearize.about(built_in.without_feedback(), n_steps=N_STEPS).system
    assert np.abs(loose.K - theirs.system.K).max() > 1e-6 * np.abs(theirs.system.K).max()


def test_without_feedback_and_the_scene_round_trip(pair):
    mine, built_in = pair
    # from the scene table (the spec's route) and from the parts (the drive's own method)
    from_parts = built_in.replace(drives=(ServoDrive(
        "O", rate=mine.drives[0].rate, motor=mine.drives[0].motor, torque_limit=mine.drives[0].torque_limit,
        bandwidth=BANDWIDTH, damping_ratio=DAMPING_RATIO, crank_inertia=CRANK_INERTIA),))
    for mechanism in (mine, from_parts):
        quiet = mechanism.without_feedback()
        assert quiet.drives[0].kp == 0.0 and quiet.drives[0].kd == 0.0
        assert_same_system(linearize.about(quiet, n_steps=N_STEPS).system,
                           linearize.about(built_in.without_feedback(), n_steps=N_STEPS).system)
    again = mc.loads(from_parts.to_toml())
    assert again.drives == from_parts.drives
