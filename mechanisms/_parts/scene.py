"""A scene spec (nested dicts, what ``tomllib`` returns for a scene file) -> the parts of a mechanism.

The format is documented key by key in ``docs/scenes.md``. ``parts_from_spec`` checks every key
(unknown keys get the nearest valid one suggested) and turns section dimensions and damping ratios
into the parts' derived quantities; ``Mechanism.from_spec`` makes the mechanism of them.
"""

from __future__ import annotations

import copy
from typing import Any, Mapping

from .checks import MechanismError
from .controllers import CONTROLLER_TYPES
from .damping import DAMPING_TYPES
from .discretisations import DEFAULT_DISCRETISATION, DISCRETISATION_TYPES
from .drives import DRIVE_TYPES
from .joints import JOINT_TYPES
from .links import ElasticLink, PointMass, RigidLink
from .table import _REQUIRED, _Table

_TOP_KEYS = ("name", "description", "period", "gravity", "initial_angles", "links", "joints",
             "drive", "drives", "point_masses", "controllers", "studies")
_RIGID_KEYS = ("type", "length", "mass", "inertia", "centroid", "points", "width", "thickness",
               "density")
_ELASTIC_KEYS = ("type", "length", "density", "youngs_modulus", "width", "thickness", "area",
                 "second_moment", "discretisation", "boundary", "axial", "geometric_stiffening",
                 "rotary_inertia", "damping", "yield_strength", "outer_fibre")
_POINT_MASS_KEYS = ("link", "point", "mass", "inertia")

def _rigid_link(name: str, t: _Table) -> RigidLink:
    length = t.number("length", "m", positive=True)
    centroid = t.pair("centroid", "m") if t.has("centroid") else None
    points_table = t.table("points")
    points = {key: _Table({"p": value}, f"{t.path}.points", ("p",)).pair("p", "m")
              for key, value in points_table.items()}
    section = [key for key in ("width", "thickness", "density") if t.has(key)]
    explicit = [key for key in ("mass", "inertia") if t.has(key)]
    if section and explicit:
        raise MechanismError(f"{t.path}: give either mass and inertia, or width, thickness and "
                             f"density (a uniform bar), not both (got {section + explicit})")
    if section:
        return RigidLink.uniform(name, length, width=t.number("width", "m", positive=True),
                                 thickness=t.number("thickness", "m", positive=True),
                                 density=t.number("density", "kg/m^3", positive=True),
                                 centroid=centroid, points=points)
    if not explicit:
        raise MechanismError(f"{t.path}: missing mass and inertia (or width, thickness and density "
                             f"for a uniform bar)")
    return RigidLink(name, length, mass=t.number("mass", "kg", positive=True),
                     inertia=t.number("inertia", "kg m^2", nonnegative=True), centroid=centroid,
                     points=points)


def _elastic_link(name: str, t: _Table) -> ElasticLink:
    length = t.number("length", "m", positive=True)
    density = t.number("density", "kg/m^3", positive=True)
    modulus = t.number("youngs_modulus", "Pa", positive=True)
    rectangle = [key for key in ("width", "thickness") if t.has(key)]
    explicit = [key for key in ("area", "second_moment") if t.has(key)]
    if rectangle and explicit:
        raise MechanismError(f"{t.path}: give either width and thickness (a rectangle bending about "
                             f"the thin direction) or area and second_moment, not both")
    if rectangle or not explicit:
        width, thickness = t.number("width", "m", positive=True), t.number("thickness", "m",
                                                                           positive=True)
        area, second_moment = width * thickness, width * thickness**3 / 12.0
    else:
        area = t.number("area", "m^2", positive=True)
        second_moment = t.number("second_moment", "m^4", positive=True)

    d = t.table("discretisation")
    every_key = tuple(dict.fromkeys(key for cls in DISCRETISATION_TYPES.values() for key in cls.KEYS))
    kind = _Table(d, f"{t.path}.discretisation", every_key).string(
        "type", DEFAULT_DISCRETISATION, tuple(DISCRETISATION_TYPES))
    cls = DISCRETISATION_TYPES[kind]
    discretisation = cls.from_table(_Table(d, f"{t.path}.discretisation", cls.KEYS))

    link = ElasticLink(name, length, density=density, youngs_modulus=modulus, area=area,
                       second_moment=second_moment, discretisation=discretisation,
                       boundary=t.string("boundary", "pinned-pinned",
                                         ("pinned-pinned", "clamped-free")),
                       axial=t.boolean("axial", True),
                       geometric_stiffening=t.boolean("geometric_stiffening", True),
                       rotary_inertia=t.boolean("rotary_inertia", False),
                       yield_strength=(t.number("yield_strength", "Pa", positive=True)
                                       if t.has("yield_strength") else None),
                       outer_fibre=(t.number("outer_fibre", "m", positive=True)
                                    if t.has("outer_fibre") else None))
    if not t.has("damping"):
        return link
    d = t.table("damping")
    kinds = {**{kind: cls.KEYS for kind, cls in DAMPING_TYPES.items()}, "none": ("type",)}
    every_key = tuple(dict.fromkeys(k for keys in kinds.values() for k in keys))
    kind = _Table(d, f"{t.path}.damping", every_key).string("type", next(iter(DAMPING_TYPES)),
                                                           tuple(kinds))
    if kind == "none":
        return link
    cls = DAMPING_TYPES[kind]
    damping = cls.from_table(_Table(d, f"{t.path}.damping", cls.KEYS), link)
    return ElasticLink(**{**{f: getattr(link, f) for f in link.__dataclass_fields__},
                          "damping": damping})


def _joint(name: str, data: object, path: str):
    """A joint from its ``[joints.<name>]`` table: the class its ``type`` names reads its own keys."""
    every_key = tuple(dict.fromkeys(key for cls in JOINT_TYPES.values() for key in cls.KEYS))
    kind = _Table(data, path, every_key).string("type", next(iter(JOINT_TYPES)), tuple(JOINT_TYPES))
    cls = JOINT_TYPES[kind]
    return cls.from_table(name, _Table(data, path, cls.KEYS))


def _drive(data: object, path: str, joint: str | None):
    """A drive from its ``[drive]`` table (``joint`` None: its ``joint`` key names the joint) or its
    ``[drives.<joint>]`` table: the class its ``type`` names reads its own keys."""
    every_key = tuple(dict.fromkeys(key for cls in DRIVE_TYPES.values() for key in cls.KEYS))
    kind = _Table(data, path, every_key).string("type", next(iter(DRIVE_TYPES)), tuple(DRIVE_TYPES))
    cls = DRIVE_TYPES[kind]
    t = _Table(data, path, cls.KEYS)
    if joint is not None and t.has("joint"):
        raise MechanismError(f"{path}: the joint is the table name {joint!r}; remove key 'joint'")
    return cls.from_table(joint, t)


def _controller(name: str, data: object, path: str):
    """A controller from its ``[controllers.<name>]`` table: its ``type`` picks the class, which
    reads its own keys."""
    every_key = tuple(dict.fromkeys(key for cls in CONTROLLER_TYPES.values() for key in cls.KEYS))
    kind = _Table(data, path, every_key).string("type", _REQUIRED, tuple(CONTROLLER_TYPES))
    cls = CONTROLLER_TYPES[kind]
    return cls.from_table(name, _Table(data, path, cls.KEYS))


def _named_tables(t: _Table, key: str) -> dict[str, Any]:
    tables = t.table(key)
    for name in tables:
        if not isinstance(tables[name], Mapping):
            raise MechanismError(f"{key}.{name} must be a table, got {tables[name]!r}")
    return dict(tables)


def parts_from_spec(spec: Mapping[str, Any]) -> dict[str, Any]:
    """The keyword arguments of ``Mechanism`` (its parts, with ``spec`` itself kept) read from a
    scene spec; raises ``MechanismError`` naming the key path and what was expected."""
    top = _Table(spec, "scene", _TOP_KEYS)
    top.path = ""  # top-level keys print as "links.coupler.length", not "scene.links..."
    links = []
    for name, data in _named_tables(top, "links").items():
        path = f"links.{name}"
        kind = _Table(data, path, tuple(dict.fromkeys(_RIGID_KEYS + _ELASTIC_KEYS))).string(
            "type", _REQUIRED, ("rigid", "elastic"))
        links.append(_rigid_link(name, _Table(data, path, _RIGID_KEYS)) if kind == "rigid"
                     else _elastic_link(name, _Table(data, path, _ELASTIC_KEYS)))
    if not links:
        raise MechanismError("the scene has no [links.<name>] tables")
    joints = [_joint(name, data, f"joints.{name}")
              for name, data in _named_tables(top, "joints").items()]
    if top.has("drive") and top.has("drives"):
        raise MechanismError("give either one [drive] table or [drives.<joint>] tables, not both")
    drives = ([_drive(top.table("drive"), "drive", None)] if top.has("drive") else
              [_drive(data, f"drives.{joint}", joint)
               for joint, data in _named_tables(top, "drives").items()])
    point_masses = []
    for name, data in _named_tables(top, "point_masses").items():
        t = _Table(data, f"point_masses.{name}", _POINT_MASS_KEYS)
        point_masses.append(PointMass(t.string("link"), t.point("point"),
                                      t.number("mass", "kg", positive=True),
                                      t.number("inertia", "kg m^2", 0.0, nonnegative=True)))
    controllers = [_controller(name, data, f"controllers.{name}")
                   for name, data in _named_tables(top, "controllers").items()]
    angles = top.table("initial_angles")
    initial_angles = {name: _Table({"a": value}, "initial_angles", ("a",)).number("a", "rad")
                      for name, value in angles.items()}
    top.string("description", "")  # checked only: documentation, kept in the spec
    period = top.number("period", "s", positive=True) if top.has("period") else None
    return dict(
        name=top.string("name"),
        links=tuple(links),
        joints=tuple(joints),
        drives=tuple(drives),
        point_masses=tuple(point_masses),
        gravity=top.pair("gravity", "m/s^2", (0.0, 0.0)),
        initial_angles=initial_angles,
        period=period,
        controllers=tuple(controllers),
        spec=copy.deepcopy(dict(spec)),
        studies=copy.deepcopy(dict(top.table("studies"))),
    )


