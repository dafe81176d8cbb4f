"""A grid point's stability judged on its whole bar: a spectral radius the time step alone calls stable
is ``marginal`` where the mesh term brings 1 within its error bar (a wrong ``ok`` is worse than a
crash). The mesh estimate is replaced by a known one here, so the rule itself is what is checked."""

from __future__ import annotations

import numpy as np
import pytest

import studies._mesh_error as mesh_error
from studies._budget import grid_radius_mesh, stability_with_mesh


@pytest.mark.parametrize("radius, error, mesh, expected", [
    (0.99, 1e-3, 1e-3, "ok"),          # 1 - 0.99 = 0.01 beyond both terms
    (0.99, 1e-3, 0.02, "marginal"),    # the mesh term reaches 1
    (0.99, 0.02, 0.0, "ok"),           # the time step's own bar reaches 1: its verdict (marginal) stands
    (1.02, 1e-3, 0.05, "ok"),          # unstable by the time step: not this rule's
    (0.99, 1e-3, float("nan"), "ok"),  # unknown mesh term: the accuracy verdict says so
])
def test_the_rule(radius, error, mesh, expected):
    status, message = stability_with_mesh(radius, error, mesh)
    assert status == expected
    assert (expected == "marginal") == ("mesh" in message)


def test_a_grid_point_near_one_becomes_marginal(monkeypatch):
    radius = np.array([0.5, 0.997, 0.998])
    fields = {"spectral_radius": radius, "spectral_radius_error": np.full(3, 1e-4),
              "done": np.ones(3, bool), "point_status": np.array(["ok", "ok", "marginal"]),
              "point_message": np.array(["", "", "marginal: within its own bar"])}
    points = [((i,), {"speed": float(i + 1)}) for i in range(3)]

    def known(problem, values, *, n_steps, scheme, radius=None):   # 0.4 % of the radius
        found = radius if radius is not None else 0.5
        return mesh_error.RadiusMeshError(0.004 * found, found, found, "one refinement", True, 0.0)

    monkeypatch.setattr(mesh_error, "radius_mesh_error", known)
    term, _ = grid_radius_mesh(object(), fields, points, n_steps=64, scheme="trapezoidal", tolerance=0.5,
                               scene_radius=0.5)
    np.testing.assert_allclose(term, 0.004 * radius)
    assert list(fields["point_status"]) == ["ok", "marginal", "marginal"]
    assert "once the mesh term counts" in fields["point_message"][1]
    assert fields["point_message"][2] == "marginal: within its own bar"   # judged by its own verdict
