"""``flexvib show SCENE`` on every shipped scene: every link, joint, drive and controller is listed,
every observable it offers is one the model accepts (and the ones it leaves out are refused), the
values ``--set`` may change are the scene's own, and ``--out`` draws the mechanism at t = 0."""

from __future__ import annotations

import re

import pytest

import mechanisms
from studies.cli import main
from studies.cli._show import offered_observables, settable_values  # the command's machinery: no public face

SCENES = mechanisms.scenes()


def _get(spec, path):
    for key in path.split("."):
        spec = spec[key]
    return spec


@pytest.mark.parametrize("scene", SCENES)
def test_show_lists_the_parts_observables_and_values(scene, capsys):
    assert main(["show", scene]) == 0
    out = capsys.readouterr().out
    mechanism = mechanisms.load(scene)
    links = out.split("\nlinks (")[1].split("\n\n")[0]
    for link in mechanism.links:
        assert re.search(rf"^  {re.escape(link.name)}\s+(rigid|elastic)\s+length {link.length:.6g} m", links, re.M)
    joints = out.split("\njoints (")[1].split("\n\n")[0]
    for joint in mechanism.joints:
        assert re.search(rf"^  {re.escape(joint.name)}\s+{joint.TYPE}: ", joints, re.M), joint.name
    for drive in mechanism.drives:
        assert f"  at {drive.joint}: " in out
    for controller in mechanism.controllers:
        assert f"  {controller.name}: {controller.to_table()['type']}: " in out
    for mass in mechanism.point_masses:
        assert f"  on {mass.link} at " in out and f"mass {mass.mass:.6g} kg" in out
    # every force component a joint declares, and each drive's torque, by the name a spec takes
    for joint in mechanism.joints:
        for component in joint.force_components():
            assert f"joint.{joint.name}.{component} (N)" in out
    for drive in mechanism.drives:
        assert f"drive.{drive.joint}.torque (N m)" in out
    # the values --set changes: the scene's own, at their paths
    spec = mechanism.to_spec()
    for path, value in settable_values(spec):
        assert f"  {path} " in out
        assert _get(spec, path) == value


@pytest.mark.parametrize("scene", ["four_bar_ritz", "parallel_robot", "six_bar"])
def test_every_offered_observable_is_accepted_and_the_others_refused(scene):
    mechanism = mechanisms.load(scene)
    model = mechanisms.assemble(mechanism)
    offered = offered_observables(mechanism)
    for link in mechanism.links:
        shown = {spec for spec, _ in offered.link_quantities[link.name]}
        for quantity in mechanisms.quantity_names():
            at_point, bare = f"{link.name}.{quantity}@F", f"{link.name}.{quantity}"
            accepted = []
            for spec in (at_point.replace("@F", "@0.25"), bare):
                try:
                    model.observable(spec)
                    accepted.append(spec)
                except ValueError:
                    pass
            # shown exactly when the model makes it (at another fraction than the probe's too)
            assert (at_point in shown or bare in shown) == bool(accepted), (link.name, quantity)
        elastic = getattr(link, "youngs_modulus", None) is not None
        assert (f"{link.name}.deflection@F" in shown) == elastic
        for point in offered.points[link.name]:
            model.observable(f"{link.name}.point_error@{point}")    # a named point is accepted
    for spec, unit in offered.joint_forces + offered.drive_torques:
        assert model.observable(spec).unit == unit


def test_an_observable_registered_from_outside_is_shown(capsys):
    from tests._support import extensions  # noqa: F401  registers curvature, slope, chord angle

    assert main(["show", "four_bar_ritz"]) == 0
    out = capsys.readouterr().out
    added = [name for name in mechanisms.quantity_names() if name in ("curvature", "slope", "chord_angle")]
    assert added
    for name in added:
        assert f"coupler.{name}" in out


def test_show_draws_the_mechanism_with_its_names(tmp_path, capsys):
    out = tmp_path / "drawings" / "robot.png"
    assert main(["show", "parallel_robot", "--out", str(out)]) == 0
    assert out.is_file() and out.stat().st_size > 10_000
    assert f"wrote {out}" in capsys.readouterr().out


def test_show_draws_names_at_their_places():
    from types import SimpleNamespace

    import matplotlib.pyplot as plt
    import numpy as np

    from studies._drawing import draw_names, mechanism_drawing  # the drawings' geometry: no public face

    mechanism = mechanisms.load("four_bar_ritz")
    nominal = mechanisms.nominal_motion(mechanism, n_steps=8)
    drawing = mechanism_drawing(SimpleNamespace(mechanism=mechanism, nominal=nominal))
    figure, ax = plt.subplots()
    artists = draw_names(ax, drawing, 0)
    texts = {t.get_text(): t for t in ax.texts}
    assert set(texts) == {link.name for link in mechanism.links} | {joint.name for joint in mechanism.joints}
    # the ground pins where the scene puts them, the crank's end at its length along the crank angle 0
    np.testing.assert_allclose(texts["O"].xy, (0.0, 0.0), atol=1e-12)
    np.testing.assert_allclose(texts["C"].xy, (0.254, 0.0), atol=1e-12)
    np.testing.assert_allclose(texts["A"].xy, (0.0508, 0.0), atol=1e-9)
    assert "joint O" in artists and "coupler" in artists
    plt.close(figure)


def test_show_refuses_what_is_not_a_mechanism(tmp_path, capsys):
    assert main(["show", "mathieu"]) == 2
    assert "not a mechanism" in capsys.readouterr().err
    assert main(["show", str(tmp_path / "nosuch.toml")]) == 2
    assert main(["show", "four_bar_ritz", "--out", str(tmp_path)]) == 2
    assert "is a folder" in capsys.readouterr().err


def test_a_plate_is_drawn_as_the_hull_of_its_points():
    import numpy as np

    from studies._drawing import plate_corners  # the drawings' geometry: no public face

    platform = mechanisms.load("parallel_robot").link("platform")   # three pins and a centre point
    corners = plate_corners(platform)
    expected = {tuple(np.round(platform.points[name], 12)) for name in ("A1", "A2", "A3")}
    assert {tuple(np.round(c, 12)) for c in corners} == expected     # the centre is inside: no corner
    x, y = corners.T
    assert 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) > 0  # counter-clockwise
