"""What the studies and linearize read from a registered part's declarations, not from its class
(issue 19): a discretisation defined here with public API only declares its count keys (rounded
when swept, refused as continuous bounds, unit 1) and the optional modal reduction (``modes``,
``with_modes``) that ``linearize.reduction_error`` uses; a quantity registered with
``position=True`` may be the output of a control comparison, one without may not."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import pytest

import linearize
import mechanisms
import periodic
import studies
from studies import kinds

COUPLER_COUNT = "links.coupler.discretisation.n_terms"


@mechanisms.register_discretisation
@dataclass(frozen=True)
class _Sines:
    """Pinned-pinned bending sines ``sin(i pi x / L)``, ``i = 1 .. modes or n_terms``, no axial
    shapes: with ``modes`` the basis "reduced" to its first ``modes`` terms, the built-in
    ``Ritz(n_bending=modes, n_axial=0)`` exactly."""

    n_terms: int = 3
    modes: int | None = None

    TYPE: ClassVar[str] = "test_sines"
    KEYS: ClassVar[tuple[str, ...]] = ("type", "n_terms", "modes")
    COUNT_KEYS: ClassVar[tuple[str, ...]] = ("n_terms", "modes")
    check_boundary: ClassVar[bool] = True

    @classmethod
    def from_table(cls, table):
        modes = table.integer("modes", minimum=1, maximum=20, why="test basis") if table.has("modes") else None
        return cls(table.integer("n_terms", 3, minimum=1, maximum=20, why="test basis"), modes)

    def to_table(self):
        return {"type": self.TYPE, "n_terms": self.n_terms,
                **({} if self.modes is None else {"modes": self.modes})}

    def with_modes(self, modes):
        return _Sines(self.n_terms, modes)

    def _count(self):
        return self.n_terms if self.modes is None else self.modes

    def layout(self, link, attachments=None):
        return mechanisms.ShapeLayout(tuple(f"b{i + 1}" for i in range(self._count())))

    def values(self, link, x, basis=None):
        x = np.asarray(x, dtype=float)
        bending = []
        for i in range(1, self._count() + 1):
            k = i * math.pi / link.length
            bending.append((np.sin(k * x), k * np.cos(k * x), -k * k * np.sin(k * x)))
        return mechanisms.ShapeValues.from_functions(bending, [])


def _four_bar(discretisation):
    base = mechanisms.four_bar(n_elements=1)
    links = tuple(dataclasses.replace(link, discretisation=discretisation) if link.name == "coupler" else link
                  for link in base.links)
    return base.replace(links=links)


def _coupler(mechanism):
    return next(link for link in mechanism.links if link.name == "coupler")


# ---------------------------------------------------------------------------------------------------
# count keys
# ---------------------------------------------------------------------------------------------------
def test_a_registered_count_key_is_rounded_when_swept_and_refused_as_a_bound():
    problem = studies.MechanismProblem.from_mechanism(_four_bar(_Sines(3)), parameter_paths=[COUPLER_COUNT])
    assert problem.parameters[COUPLER_COUNT] == 3
    assert problem.units[COUPLER_COUNT] == "1"
    swept = problem.mechanism({COUPLER_COUNT: 4.6})
    assert _coupler(swept).discretisation == _Sines(5)           # rounded, not refused as 4.6
    assert mechanisms.assemble(swept).n_coords == mechanisms.assemble(problem.mechanism()).n_coords + 2
    with pytest.raises(studies.StudiesError, match="is a count"):
        studies.optimize(problem, {COUPLER_COUNT: (2.0, 6.0)}, objective="peak_to_peak:coupler.deflection@0.5",
                         speeds=[100.0], n_steps=32)


# ---------------------------------------------------------------------------------------------------
# the modal reduction a discretisation declares
# ---------------------------------------------------------------------------------------------------
def test_a_registered_reduction_is_checked_against_its_own_larger_mode_set():
    """The reduction error of the 2-term "reduction" of a 6-term sine basis is the difference
    between the built-in Ritz models with 2 and 4 bending modes (the reference: modes + 2)."""
    reduced = _four_bar(_Sines(6, modes=2))
    assert linearize.reduced_links(reduced) == ("coupler",)
    assert linearize.reduced_links(_four_bar(_Sines(6))) == ()
    assert linearize.reduced_links(_four_bar(mechanisms.Ritz(2, 0))) == ()   # no modal reduction
    reference, modes = linearize.reference_mechanism(reduced, "next")
    assert modes == {"coupler": (2, 4)} and _coupler(reference).discretisation == _Sines(6, 4)
    full, modes = linearize.reference_mechanism(reduced, "full")
    assert modes == {"coupler": (2, None)} and _coupler(full).discretisation == _Sines(6)

    spec, n_steps = "coupler.deflection@0.5", 64
    check = linearize.reduction_error(reduced, n_steps=n_steps, observables=[spec])
    responses = []
    for n_bending in (2, 4):   # the built-in Ritz modes: the same shapes, another class
        lin = linearize.about(_four_bar(mechanisms.Ritz(n_bending, 0)), n_steps=n_steps, observables=[spec])
        steady = periodic.steady_state(lin.system)
        responses.append(lin.observable_maps[spec].evaluate(steady.x, steady.v, steady.a))
    difference = float(np.abs(responses[0] - responses[1]).max())
    assert difference > 0.0
    assert check.difference[spec] == pytest.approx(difference, rel=1e-6)
    assert check.relative[spec] == pytest.approx(difference / np.ptp(responses[1]), rel=1e-6)


# ---------------------------------------------------------------------------------------------------
# a registered observable as the output of a control comparison
# ---------------------------------------------------------------------------------------------------
def _point_x(model, link, fraction):
    """The built-in point x position, registered again under another name."""
    point = model.observable(f"{link}.point_error_x@{fraction!r}")
    return point.value, point.gradient


mechanisms.register_observable("test_position_x", _point_x, unit="m", position=True)
mechanisms.register_observable("test_not_position_x", _point_x, unit="m")


def test_a_quantity_declared_a_position_may_be_the_output():
    assert "test_position_x" in mechanisms.position_quantities()
    assert {"angle", "point_error", "point_error_x", "point_error_y"} <= set(mechanisms.position_quantities())
    assert not {"deflection", "strain", "test_not_position_x"} & set(mechanisms.position_quantities())
    kind = kinds()["control_comparison"]
    assert kind.check("studies.control_comparison", {"output": "coupler.test_position_x@0.5"}, 128)["output"] \
        == "coupler.test_position_x@0.5"
    with pytest.raises(studies.StudiesError, match=r"\[studies.control_comparison\] output: expected the "
                                                   r"observable spec of a position"):
        kind.check("studies.control_comparison", {"output": "coupler.test_not_position_x@0.5"}, 128)

    spec = mechanisms.four_bar(n_elements=1).to_spec()
    spec["drive"].update(type="torque", kp=20.0, kd=0.5)
    problem = studies.MechanismProblem.from_mechanism(mechanisms.build(spec, source="torque four-bar"))
    found = {}
    for output in ("coupler.test_position_x@0.5", "coupler.point_error_x@0.5"):
        result = studies.control_comparison(problem, output=output, n_periods=4, n_steps=64)
        assert result.roles[output] == "output"
        found[output] = result
    mine, builtin = found["coupler.test_position_x@0.5"], found["coupler.point_error_x@0.5"]
    for case in ("with", "without"):
        history = getattr(mine, f"{case}_control")
        np.testing.assert_allclose(history["coupler.test_position_x@0.5"],
                                   getattr(builtin, f"{case}_control")["coupler.point_error_x@0.5"],
                                   rtol=0, atol=1e-12)
        assert np.nanmax(np.abs(history["coupler.test_position_x@0.5"])) > 0.0
    assert mine.failed["with"] == "" and np.all(np.isfinite(mine.with_control["coupler.test_position_x@0.5"]))
    assert mine.steady_peak["with"]["coupler.test_position_x@0.5"] \
        == pytest.approx(builtin.steady_peak["with"]["coupler.point_error_x@0.5"], rel=1e-12)


# ---------------------------------------------------------------------------------------------------
# a pin to the ground that is not a Revolute: the Grashof check and the default output find it
# ---------------------------------------------------------------------------------------------------
@mechanisms.register_joint
@dataclass(frozen=True)
class _GroundPin:
    """Holds ``point`` of ``link`` at the ground position ``at`` (m): ``r - at = 0`` along x and y."""

    name: str
    link: str
    point: object
    at: tuple

    TYPE: ClassVar[str] = "test_ground_pin"
    KEYS: ClassVar[tuple[str, ...]] = ("type", "link", "point", "at")
    n_equations: ClassVar[int] = 2
    point_force: ClassVar[bool] = True
    force_unit: ClassVar[str] = "N"

    @classmethod
    def from_table(cls, name, table):
        return cls(name, table.string("link"), table.point("point"), table.pair("at", "m"))

    def to_table(self):
        return {"type": self.TYPE, "link": self.link, "point": self.point, "at": list(self.at)}

    @property
    def ends(self):
        return ((self.link, self.point),)

    def constraint_rows(self):
        return tuple(mechanisms.PointRow(label, (mechanisms.PointTerm(self.link, self.point, direction),),
                                         -float(self.at[axis]))
                     for axis, (label, direction) in enumerate((("x", (1.0, 0.0)), ("y", (0.0, 1.0)))))

    def force_components(self):
        return {"fx": (-1.0, 0.0), "fy": (0.0, -1.0)}   # Phi = r - at: the force on the link is -lam

    def drive_terms(self):
        return None

    def coincident_points(self):
        return ((mechanisms.GROUND, tuple(self.at)), (self.link, self.point))   # the ground side first


def _four_bar_spec(l0, l1, l2, l3, offset, *, pinned=False, **drive):
    spec = mechanisms.load("four_bar_fem4").to_spec()
    for name, length in (("crank", l1), ("coupler", l2), ("rocker", l3)):
        spec["links"][name]["length"] = length
    spec["joints"]["C"] = ({"type": "test_ground_pin", "link": "rocker", "point": "start", "at": [l0, 0.0]}
                           if pinned else dict(spec["joints"]["C"], point_a=[l0, 0.0]))
    spec["drive"].update(offset=offset, **drive)
    return spec


def test_the_grashof_check_reads_pins_from_the_joints_declarations():
    """A non-Grashof four-bar (s + l = 0.45 > p + q = 0.42 m) whose rocker pivot is the pin above
    is refused as the one with a revolute pivot, at the same crank angle."""
    messages = []
    for pinned in (False, True):
        with pytest.raises(mechanisms.MechanismError, match="crank cannot turn fully") as info:
            mechanisms.build(_four_bar_spec(0.3, 0.2, 0.22, 0.15, math.radians(60.0), pinned=pinned))
        messages.append(str(info.value))
    assert messages[0] == messages[1]
    grashof = mechanisms.build(_four_bar_spec(0.254, 0.0508, 0.254, 0.1016, 0.0, pinned=True))
    assert [joint.TYPE for joint in grashof.joints] == ["revolute", "revolute", "revolute", "test_ground_pin"]


def test_the_default_output_of_a_control_comparison_is_the_angle_of_the_pinned_rocker():
    mechanism = mechanisms.build(_four_bar_spec(0.254, 0.0508, 0.254, 0.1016, 0.0, pinned=True,
                                                type="torque", kp=20.0, kd=0.5))
    result = studies.control_comparison(studies.MechanismProblem.from_mechanism(mechanism), n_periods=4, n_steps=64)
    assert result.roles["rocker.angle"] == "output"
    assert result.roles["drive.O.rate"] == "speed"


@mechanisms.register_joint
@dataclass(frozen=True)
class _GroundPinSecond(_GroundPin):
    """The same pin naming its ground side second."""

    TYPE: ClassVar[str] = "test_ground_pin_second"

    def coincident_points(self):
        return ((self.link, self.point), (mechanisms.GROUND, tuple(self.at)))


def test_the_initial_guess_walks_a_pin_whose_ground_side_is_second():
    """The nominal motion's initial guess places links from the ground out whichever side of a pin
    the ground is on (it looked the ground up as a link: KeyError): the same motion either way."""
    motions = []
    for kind in ("test_ground_pin", "test_ground_pin_second"):
        spec = _four_bar_spec(0.254, 0.0508, 0.254, 0.1016, 0.0, pinned=True)
        spec["joints"]["C"]["type"] = kind
        motions.append(mechanisms.nominal_motion(mechanisms.build(spec), n_steps=32))
    np.testing.assert_allclose(motions[1].s, motions[0].s, atol=1e-12)
