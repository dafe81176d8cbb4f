"""A new controller defined outside the packages with public API only: one that adds a PD law on
the driven angle and the feedback of a strain gauge, both from one table, registered with
``mechanisms.register_controller``. Its ``law()`` is a ``mechanisms.ControllerLaw``; the model must
treat it exactly as the built-in PD controller plus observable feedback with the same gains (an
equivalent model: the same torque and derivatives)."""

from __future__ import annotations

import numpy as np

import mechanisms as mc
from tests._support.extensions import GaugedPD


def test_a_registered_controller_acts_as_its_built_in_equivalent():
    base = mc.load("four_bar_controlled")
    drive = base.drives[0]
    mine = base.replace(controllers=(GaugedPD("g", drive.joint, 3.0, 0.05, 40.0),))
    built_in = base.replace(controllers=(mc.PDController("p", drive.joint, 3.0, 0.05),
                                         mc.ObservableFeedback("f", drive.joint,
                                                               "coupler.strain@0.5", 40.0)))
    assert mc.CONTROLLER_TYPES["gauged_pd"] is GaugedPD
    assert mc.loads(mine.to_toml()) == mine
    models = [mc.assemble(m) for m in (mine, built_in)]
    rng = np.random.default_rng(3)
    n = models[0].n_coords
    t = np.array([0.0, 0.01, 0.02])
    s, sdot = rng.normal(size=(3, n)) * 0.1, rng.normal(size=(3, n))
    ours, theirs = (m.drive_torque_terms(drive.joint, t, s, sdot) for m in models)
    for a, b in zip(ours, theirs):
        np.testing.assert_allclose(a, b, rtol=1e-13, atol=1e-13 * np.abs(b).max())
    assert np.abs(ours[1]).max() > 0.0        # the law has gains: the comparison is not of zeros
