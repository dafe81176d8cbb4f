"""Scenes: the shipped TOML files, the Python builders, the loader and every bad-input error."""

import math
import re

import numpy as np
import pytest

import mechanisms
from mechanisms import ElasticLink, Mechanism, MechanismError, PrescribedDrive, Revolute, RigidLink, Slider

BUILDERS = {
    "four_bar_fem4": lambda: mechanisms.four_bar(),
    "four_bar_fem1": lambda: mechanisms.four_bar(n_elements=1),
    "four_bar_ritz": lambda: mechanisms.four_bar(discretisation="ritz"),
    "four_bar_thesis": lambda: mechanisms.four_bar(discretisation="ritz",
                                                   geometric_stiffening=False,
                                                   name="four_bar_thesis"),
    "six_bar": lambda: mechanisms.six_bar(),
    "slider_crank": lambda: mechanisms.slider_crank(),
    "two_link_arm": lambda: mechanisms.two_link_arm(),
    "parallel_robot": lambda: mechanisms.parallel_robot(),
    "four_bar_controlled": lambda: mechanisms.four_bar(discretisation="ritz").replace(
        name="four_bar_controlled",
        drives=(mechanisms.TorqueDrive("O", rate=100.0, torque_limit=5.0,
                                       motor=mechanisms.DCMotor(1.0, 1000.0, 1e-5, 4.0)),),
        controllers=(mechanisms.PDController("crank_pd", "O", kp=20.0, kd=0.2),
                     mechanisms.ObservableFeedback("strain", "O", "coupler.strain@0.5",
                                                   gain=3e4, rate_gain=100.0))),
}


def test_scene_list_is_the_shipped_files():
    assert mechanisms.scenes() == sorted(BUILDERS)


@pytest.mark.parametrize("name", sorted(BUILDERS))
def test_scene_file_equals_its_builder(name):
    assert mechanisms.load(name) == BUILDERS[name]()


@pytest.mark.parametrize("name", sorted(BUILDERS))
def test_toml_round_trip(name, tmp_path):
    mech = mechanisms.load(name)
    path = tmp_path / f"{name}.toml"
    path.write_text(mech.to_toml())
    again = mechanisms.load(path)
    assert again == mech and again.spec == mech.spec


def test_round_trip_of_a_mechanism_made_from_parts():
    steel = dict(density=7800.0, youngs_modulus=2e11)
    mech = Mechanism(
        name="pendulum-ish four-bar",
        links=(RigidLink("crank", 0.05, mass=0.1, inertia=2e-5, centroid=(0.02, 0.001)),
               ElasticLink.rectangular("coupler", 0.28, width=0.02, thickness=0.002, **steel,
                                       discretisation=mechanisms.Ritz(3, 2),
                                       damping=mechanisms.Rayleigh(1.0, 1e-4)),
               RigidLink("rocker", 0.28, mass=0.3, inertia=2e-3, points={"P": (0.1, 0.02)})),
        joints=(Revolute("O", "ground", (0.0, 0.0), "crank", "start"),
                Revolute("A", "crank", "end", "coupler", "start"),
                Revolute("B", "coupler", "end", "rocker", "end"),
                Revolute("C", "ground", (0.25, 0.0), "rocker", "start")),
        drives=(PrescribedDrive("O", rate=-50.0, offset=0.3, harmonics=((2, 0.01, 0.02),)),),
        point_masses=(mechanisms.PointMass("rocker", "P", 0.05),),
        gravity=(0.0, -9.81), initial_angles={"coupler": 1.2, "rocker": 1.9})
    assert mech.spec is None and mech.period == pytest.approx(2 * math.pi / 50)
    again = mechanisms.loads(mech.to_toml())
    assert again == mech


def test_thesis_defaults():
    """The issue's numbers, and beta from zeta = 2 % at the coupler's first pinned-pinned
    frequency computed here from the Euler-Bernoulli closed form."""
    mech = mechanisms.load("four_bar_fem4")
    coupler = mech.link("coupler")
    assert coupler.area == pytest.approx(3.2e-5, rel=1e-15)
    assert coupler.second_moment == pytest.approx(0.02 * 0.0016**3 / 12, rel=1e-15)
    omega1 = math.pi**2 / 0.2794**2 * math.sqrt(2e11 * 0.02 * 0.0016**3 / 12 / (7800 * 3.2e-5))
    assert omega1 == pytest.approx(295.7, abs=0.05)
    assert coupler.damping.beta == pytest.approx(2 * 0.02 / omega1, rel=1e-14)
    assert coupler.geometric_stiffening and not mechanisms.load("four_bar_thesis").link(
        "coupler").geometric_stiffening
    assert mech.gravity == (0.0, 0.0) and mech.drives[0].rate == 100.0
    assert mech.period == pytest.approx(2 * math.pi / 100, rel=1e-15)
    crank = mech.link("crank")
    assert crank.mass == pytest.approx(7800 * 3.2e-5 * 0.0508, rel=1e-14)
    assert crank.inertia == pytest.approx(crank.mass * 0.0508**2 / 12, rel=1e-14)


def test_with_parameter_recomputes_derived_quantities():
    base = mechanisms.load("four_bar_fem4")
    thick = base.with_parameter("links.coupler.thickness", 0.002)
    coupler = thick.link("coupler")
    assert coupler.area == pytest.approx(0.02 * 0.002, rel=1e-15)
    assert coupler.second_moment == pytest.approx(0.02 * 0.002**3 / 12, rel=1e-15)
    # omega_1 grows like h (I/A = h^2/12), so beta = 2 zeta / omega_1 shrinks by 1.6/2.
    assert coupler.damping.beta == pytest.approx(base.link("coupler").damping.beta * 0.8,
                                                 rel=1e-13)
    assert base.link("coupler").second_moment == pytest.approx(0.02 * 0.0016**3 / 12)  # unchanged

    faster = base.with_parameter("drive.rate", 150.0)
    assert faster.period == pytest.approx(2 * math.pi / 150, rel=1e-15)
    damped = base.with_parameter("links.coupler.damping.ratio", 0.05)
    assert damped.link("coupler").damping.beta == pytest.approx(
        2.5 * base.link("coupler").damping.beta, rel=1e-13)
    heavy = base.with_parameters({"gravity": [0.0, -9.81], "links.crank.density": 2700.0})
    assert heavy.gravity == (0.0, -9.81)
    assert heavy.link("crank").mass == pytest.approx(2700 * 3.2e-5 * 0.0508, rel=1e-14)


def test_with_parameter_rejects_bad_paths():
    base = mechanisms.load("four_bar_fem4")
    with pytest.raises(MechanismError, match="did you mean 'thickness'"):
        base.with_parameter("links.coupler.thicknes", 0.002)
    with pytest.raises(MechanismError, match="links.coupler.length is a value"):
        base.with_parameter("links.coupler.length.x", 1.0)
    with pytest.raises(MechanismError, match="must be positive"):
        base.with_parameter("links.coupler.thickness", -0.002)
    with pytest.raises(MechanismError, match="drives.<joint>.rate"):
        mechanisms.load("two_link_arm").with_parameter("drive.rate", 1.0)


def test_replace_recomputes_the_default_period_and_drops_the_spec():
    base = mechanisms.load("slider_crank")
    faster = base.replace(drives=(PrescribedDrive("O", rate=300.0),))
    assert faster.period == pytest.approx(2 * math.pi / 300) and faster.spec is None
    assert mechanisms.load("two_link_arm").replace(name="arm").period == 1.0  # the explicit period
    with pytest.raises(TypeError, match="unknown fields"):
        base.replace(crank_speed=3.0)


def test_studies_table_is_kept_raw():
    text = mechanisms.load("slider_crank").to_toml() + """
[studies.sweep]
parameter = "drive.rate"
values = [100.0, 150.0, 200.0]
observables = ["rod.deflection@0.5"]
"""
    mech = mechanisms.loads(text)
    assert mech.studies == {"sweep": {"parameter": "drive.rate", "values": [100.0, 150.0, 200.0],
                                      "observables": ["rod.deflection@0.5"]}}
    assert mechanisms.loads(mech.to_toml()).studies == mech.studies
    assert mech.with_parameter("drive.rate", 120.0).studies == mech.studies


# --- bad input -------------------------------------------------------------------------------------
def _scene_text(**replacements):
    text = mechanisms.load("four_bar_fem4").to_toml()
    for old, new in replacements.items():
        assert old.replace("_", " ") in text or old in text
        text = text.replace(old, new)
    return text


def _edit(path, value):
    spec = mechanisms.load("four_bar_fem4").to_spec()
    table = spec
    for key in path.split(".")[:-1]:
        table = table[key]
    if value is None:
        del table[path.split(".")[-1]]
    else:
        table[path.split(".")[-1]] = value
    return spec


@pytest.mark.parametrize("path, value, message", [
    ("gravitty", [0.0, 0.0], r"unknown key 'gravitty'; did you mean 'gravity'"),
    ("links.coupler.lenght", 0.3, r"links.coupler: unknown key 'lenght'; did you mean 'length'"),
    ("links.coupler.youngs_modulous", 1.0,
     r"unknown key 'youngs_modulous'; did you mean 'youngs_modulus'"),
    ("links.crank.mass", 1.0, r"either mass and inertia, or width, thickness and density"),
    ("drive.rat", 1.0, r"did you mean 'rate'"),
    ("links.coupler.damping.type", "raleigh", r"did you mean 'rayleigh'"),
])
def test_unknown_keys_suggest_the_nearest(path, value, message):
    spec = _edit(path, value) if "." in path else {**_edit("name", "x"), path: value}
    with pytest.raises(MechanismError, match=message):
        mechanisms.build(spec)


@pytest.mark.parametrize("path, value, message", [
    ("links.coupler.length", None, r"links.coupler: missing key 'length'"),
    ("links.coupler.length", 0.0, r"links.coupler.length must be positive \(m\), got 0"),
    ("links.crank.length", -0.05, r"links.crank.length must be positive \(m\)"),
    ("links.coupler.youngs_modulus", -2e11, r"youngs_modulus must be positive \(Pa\)"),
    ("links.coupler.density", 0, r"density must be positive \(kg/m\^3\)"),
    ("links.crank.thickness", float("inf"), r"thickness must be a finite number"),
    ("links.coupler.width", float("nan"), r"width must be a finite number"),
    ("drive.rate", float("nan"), r"drive.rate must be a finite number"),
    ("links.coupler.discretisation.n_elements", 0, r"n_elements must be an integer >= 1"),
    ("joints.B.link_b", "rocket", r"unknown link 'rocket'.*did you mean 'rocker'"),
    ("joints.A.point_a", "middle", r"link 'crank' has no point 'middle'"),
    ("joints.A.point_a", 0.06, r"distance in \[0, 0.0508\] m"),
    ("drive.joint", "Q", r"drive names joint 'Q'"),
])
def test_bad_values_are_named(path, value, message):
    with pytest.raises(MechanismError, match=message):
        mechanisms.build(_edit(path, value))


def test_point_masses_need_positive_mass():
    spec = mechanisms.load("slider_crank").to_spec()
    spec["point_masses"]["slider"]["mass"] = 0.0
    with pytest.raises(MechanismError, match=r"point_masses.slider.mass must be positive \(kg\)"):
        mechanisms.build(spec)
    with pytest.raises(MechanismError, match="mass must be positive"):
        RigidLink("crank", 0.1, mass=-1.0, inertia=0.0)


def test_toml_nan_is_rejected_with_the_file_name(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(mechanisms.load("four_bar_fem4").to_toml().replace(
        "length = 0.2794", "length = nan", 1))
    with pytest.raises(MechanismError, match=r"bad.toml: links.coupler.length must be a finite"):
        mechanisms.load(path)
    path.write_text("name = 'x'\n[links.crank\n")
    with pytest.raises(MechanismError, match="not valid TOML"):
        mechanisms.load(path)


def test_unknown_scene_name_suggests_one():
    with pytest.raises(MechanismError, match="did you mean 'slider_crank'"):
        mechanisms.load("slider_cranck")
    with pytest.raises(FileNotFoundError):
        mechanisms.load("does/not/exist.toml")


def test_duplicate_names():
    mech = mechanisms.load("four_bar_fem4")
    with pytest.raises(MechanismError, match="duplicate link name 'crank'"):
        mech.replace(links=mech.links + (RigidLink("crank", 0.1, 1.0, 0.1),))
    with pytest.raises(MechanismError, match="duplicate joint name 'A'"):
        mech.replace(joints=mech.joints[:3] + (Revolute("A", "ground", (0.254, 0.0), "rocker",
                                                        "start"),))
    with pytest.raises(MechanismError, match="joint 'O' is driven twice"):
        mech.replace(drives=mech.drives * 2)


def test_a_linkage_with_the_wrong_mobility_cannot_be_assembled():
    mech = mechanisms.load("four_bar_fem4")
    with pytest.raises(MechanismError, match=r"cannot be assembled.*9 rigid coordinates.*7 "
                                             r"constraint equations.*mobility 3"):
        mech.replace(joints=mech.joints[:3])  # rocker pivot C removed
    with pytest.raises(MechanismError, match=r"links \['f1', 'f2'\] are not connected"):
        mech.replace(links=mech.links + (RigidLink("f1", 0.1, 1.0, 0.1),
                                         RigidLink("f2", 0.1, 1.0, 0.1)),
                     joints=mech.joints + (Revolute("F", "f1", "end", "f2", "start"),))


def test_period_needed_and_commensurate():
    arm = mechanisms.load("two_link_arm").to_spec()
    del arm["period"]
    with pytest.raises(MechanismError, match="give the period"):
        mechanisms.build(arm)
    arm["period"] = 0.5
    arm["drives"]["elbow"]["rate"] = 1.0
    with pytest.raises(MechanismError, match="whole number of turns"):
        mechanisms.build(arm)


def _crank_angle(message):
    return float(re.search(r"crank angle (-?[0-9.]+) deg", message).group(1))


def _four_bar_spec(l0, l1, l2, l3, offset):
    spec = mechanisms.load("four_bar_fem4").to_spec()
    for name, length in (("crank", l1), ("coupler", l2), ("rocker", l3)):
        spec["links"][name]["length"] = length
    spec["joints"]["C"]["point_a"] = [l0, 0.0]
    spec["drive"]["offset"] = offset
    return spec


def test_non_grashof_crank_names_the_angle_where_it_fails():
    """Crank 0.2, coupler 0.22, rocker 0.15, ground 0.3 m: s + l = 0.45 > p + q = 0.42, so the loop
    opens where |A - C| = l2 + l3: cos(phi) = (l0^2 + l1^2 - (l2 + l3)^2) / (2 l0 l1), phi turning
    positive from 60 deg (where it assembles)."""
    l0, l1, l2, l3 = 0.3, 0.2, 0.22, 0.15
    with pytest.raises(MechanismError, match="crank cannot turn fully") as info:
        mechanisms.build(_four_bar_spec(l0, l1, l2, l3, math.radians(60.0)))
    expected = math.degrees(math.acos((l0**2 + l1**2 - (l2 + l3) ** 2) / (2 * l0 * l1)))
    assert _crank_angle(str(info.value)) == pytest.approx(expected, abs=0.01)
    assert "s + l = 0.45 m, p + q = 0.42 m" in str(info.value)
    with pytest.raises(MechanismError, match="cannot be assembled at crank angle 180.00 deg"):
        mechanisms.build(_four_bar_spec(l0, l1, l2, l3, math.pi))


def test_change_point_four_bar_names_the_toggle():
    """A parallelogram (s + l = p + q) toggles where all links line up: crank angle 180 deg when
    started at 30 deg."""
    with pytest.raises(MechanismError, match=r"toggle.*joints 'A', 'B'") as info:
        mechanisms.build(_four_bar_spec(0.2, 0.1, 0.2, 0.1, math.radians(30.0)))
    assert _crank_angle(str(info.value)) == pytest.approx(180.0, abs=0.01)


def test_bad_parts_in_python():
    with pytest.raises(MechanismError, match="boundary must be one of"):
        ElasticLink("rod", 0.3, 7800, 2e11, 1e-4, 1e-9, boundary="clamped")
    with pytest.raises(MechanismError, match="no dots"):
        RigidLink("a.b", 0.1, 1.0, 0.1)
    with pytest.raises(MechanismError, match="reserved"):
        RigidLink("ground", 0.1, 1.0, 0.1)
    with pytest.raises(MechanismError, match="ground on side a"):
        Revolute("O", "crank", "start", "ground", (0.0, 0.0))
    with pytest.raises(MechanismError, match="origin must be a pair"):
        Slider("B", "rod", "end", origin=(0.0,))
    with pytest.raises(MechanismError, match=r"harmonics\[0\] order k"):
        PrescribedDrive("O", harmonics=((0, 1.0, 0.0),))
    assert np.isfinite(mechanisms.load("six_bar").period)


DOCS = __import__("pathlib").Path(__file__).resolve().parents[1] / "docs" / "scenes.md"


def test_docs_name_every_key_and_their_example_runs():
    from mechanisms._parts import scene as _load  # the scene reader's key tuples: no public face

    text = DOCS.read_text()

    def shipped(registry):
        """The package's own classes (tests register others, documented where they are defined)."""
        return [cls for cls in registry.values() if cls.__module__.startswith("mechanisms.")]

    joint_keys = tuple(key for joint in shipped(mechanisms.JOINT_TYPES) for key in joint.KEYS)
    keys = set(_load._TOP_KEYS + _load._RIGID_KEYS + _load._ELASTIC_KEYS + joint_keys
               + _load._POINT_MASS_KEYS)
    for registry in (mechanisms.DISCRETISATION_TYPES, mechanisms.DAMPING_TYPES,
                     mechanisms.CONTROLLER_TYPES, mechanisms.DRIVE_TYPES):
        keys.update(key for cls in shipped(registry) for key in cls.KEYS)
    keys.update(mechanisms.DCMotor.KEYS)
    assert [key for key in sorted(keys) if f"`{key}`" not in text] == []
    example = re.search(r"```toml\n(.*?)```", text, re.S).group(1)
    motion = mechanisms.nominal_motion(mechanisms.loads(example), n_steps=16)
    assert motion.constraint_residual < 1e-12
