"""Scene files: TOML text <-> nested dicts ("specs") <-> validated ``Mechanism``.

The format is documented key by key in ``docs/scenes.md``. A spec is what ``tomllib`` returns for a
scene file. ``build(spec)`` checks every key (unknown keys get the nearest valid one suggested), turns
section dimensions and damping ratios into the parts' derived quantities, and returns a ``Mechanism``
that keeps the spec, so ``Mechanism.with_parameter("links.coupler.thickness", 2e-3)`` edits the spec
and rebuilds with everything derived recomputed.
"""

from __future__ import annotations

import copy
import difflib
import math
import tomllib
from importlib import resources
from pathlib import Path
from typing import Any, Mapping

from ._parts import (
    CONTROLLER_TYPES,
    DISCRETISATION_TYPES,
    JOINT_TYPES,
    DampingMatrix,
    DCMotor,
    ElasticLink,
    Mechanism,
    MechanismError,
    ModalDamping,
    PointMass,
    PrescribedDrive,
    Rayleigh,
    RigidLink,
    TorqueDrive,
    UserShapes,
    _is_number,
)

_TOP_KEYS = ("name", "description", "period", "gravity", "initial_angles", "links", "joints",
             "drive", "drives", "point_masses", "controllers", "studies")
_RIGID_KEYS = ("type", "length", "mass", "inertia", "centroid", "points", "width", "thickness",
               "density")
_ELASTIC_KEYS = ("type", "length", "density", "youngs_modulus", "width", "thickness", "area",
                 "second_moment", "discretisation", "boundary", "axial", "geometric_stiffening",
                 "rotary_inertia", "damping", "yield_strength", "outer_fibre")
_DISCRETISATION_KEYS = tuple(dict.fromkeys(key for cls in DISCRETISATION_TYPES.values()
                                           for key in cls.KEYS))
_DAMPING_KEYS = {"rayleigh": ("type", "alpha", "beta", "ratio"), "modal": ("type", "ratios"),
                 "matrix": ("type", "matrix"), "none": ("type",)}
_PRESCRIBED_KEYS = ("type", "joint", "rate", "offset", "harmonics")
_TORQUE_KEYS = _PRESCRIBED_KEYS + ("kp", "kd", "motor", "flywheel", "torque_limit", "feedforward")
_MOTOR_KEYS = ("stall_torque", "no_load_speed", "resistance", "torque_constant", "supply_voltage",
               "rotor_inertia", "gear_ratio")
_POINT_MASS_KEYS = ("link", "point", "mass", "inertia")

_REQUIRED = object()


class _Table:
    """One table of a spec, read key by key with its dotted path in every error message."""

    def __init__(self, data: object, path: str, allowed: tuple[str, ...]):
        if not isinstance(data, Mapping):
            raise MechanismError(f"{path} must be a table, got {data!r}")
        for key in data:
            if key not in allowed:
                close = difflib.get_close_matches(str(key), allowed, n=1, cutoff=0.5)
                hint = f"; did you mean {close[0]!r}?" if close else ""
                raise MechanismError(f"{path}: unknown key {key!r}{hint} (valid keys: "
                                     f"{', '.join(allowed)})")
        self.data, self.path = data, path

    def _at(self, key: str) -> str:
        return f"{self.path}.{key}" if self.path else key

    def has(self, key: str) -> bool:
        return key in self.data

    def raw(self, key: str, default: Any = _REQUIRED) -> Any:
        if key in self.data:
            return self.data[key]
        if default is _REQUIRED:
            raise MechanismError(f"{self.path or 'scene'}: missing key {key!r}")
        return default

    def number(self, key: str, unit: str, default: Any = _REQUIRED, *, positive: bool = False,
               nonnegative: bool = False) -> float:
        value = self.raw(key, default)
        if not _is_number(value) or not math.isfinite(value):
            raise MechanismError(f"{self._at(key)} must be a finite number ({unit}), got "
                                 f"{value!r}")
        if positive and not value > 0:
            raise MechanismError(f"{self._at(key)} must be positive ({unit}), got {value!r}")
        if nonnegative and not value >= 0:
            raise MechanismError(f"{self._at(key)} must be zero or positive ({unit}), got "
                                 f"{value!r}")
        return float(value)

    def integer(self, key: str, default: Any = _REQUIRED, *, minimum: int | None = None,
                maximum: int | None = None, why: str = "") -> int:
        """An integer value; with ``maximum`` (and the reason ``why``) an upper bound too."""
        value = self.raw(key, default)
        if not isinstance(value, int) or isinstance(value, bool):
            raise MechanismError(f"{self._at(key)} must be an integer, got {value!r}")
        if minimum is not None and value < minimum:
            raise MechanismError(f"{self._at(key)} must be an integer >= {minimum}, got {value!r}")
        if maximum is not None and value > maximum:
            raise MechanismError(f"{self._at(key)} must be at most {maximum} ({why}), got {value!r}")
        return value

    def string(self, key: str, default: Any = _REQUIRED, choices: tuple[str, ...] = ()) -> str:
        value = self.raw(key, default)
        if not isinstance(value, str):
            raise MechanismError(f"{self._at(key)} must be a string, got {value!r}")
        if choices and value not in choices:
            close = difflib.get_close_matches(value, choices, n=1, cutoff=0.5)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise MechanismError(f"{self._at(key)} must be one of {choices}, got {value!r}{hint}")
        return value

    def boolean(self, key: str, default: bool) -> bool:
        value = self.raw(key, default)
        if not isinstance(value, bool):
            raise MechanismError(f"{self._at(key)} must be true or false, got {value!r}")
        return value

    def pair(self, key: str, unit: str, default: Any = _REQUIRED) -> tuple[float, float]:
        value = self.raw(key, default)
        if (not isinstance(value, (list, tuple)) or len(value) != 2
                or not all(_is_number(v) and math.isfinite(v) for v in value)):
            raise MechanismError(f"{self._at(key)} must be a pair [x, y] of finite numbers "
                                 f"({unit}), got {value!r}")
        return (float(value[0]), float(value[1]))

    def point(self, key: str) -> str | float:
        value = self.raw(key)
        if isinstance(value, str):
            return value
        if _is_number(value) and math.isfinite(value):
            return float(value)
        raise MechanismError(f"{self._at(key)} must be 'start', 'end', a named point or a "
                             f"distance along the link in metres, got {value!r}")

    def table(self, key: str) -> Mapping[str, Any]:
        value = self.raw(key, {})
        if not isinstance(value, Mapping):
            raise MechanismError(f"{self._at(key)} must be a table, got {value!r}")
        return value


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
    kind = _Table(d, f"{t.path}.discretisation", _DISCRETISATION_KEYS
                  ).string("type", next(iter(DISCRETISATION_TYPES)), tuple(DISCRETISATION_TYPES))
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
    all_damping_keys = tuple(dict.fromkeys(k for keys in _DAMPING_KEYS.values() for k in keys))
    kind = _Table(d, f"{t.path}.damping", all_damping_keys).string("type", "rayleigh",
                                                                    tuple(_DAMPING_KEYS))
    dt = _Table(d, f"{t.path}.damping", _DAMPING_KEYS[kind])
    if kind == "none":
        return link
    if kind == "rayleigh":
        if dt.has("ratio"):
            if dt.has("beta") or dt.has("alpha"):
                raise MechanismError(f"{dt.path}: give either ratio (stiffness-proportional damping "
                                     f"with that ratio at the first bending frequency) or alpha "
                                     f"and beta, not both")
            # C = beta K gives the ratio beta omega / 2 at omega: beta = 2 zeta / omega_1.
            ratio = dt.number("ratio", "1", nonnegative=True)
            damping = Rayleigh(0.0, 2.0 * ratio / link.first_bending_frequency())
        else:
            damping = Rayleigh(dt.number("alpha", "1/s", 0.0, nonnegative=True),
                               dt.number("beta", "s", 0.0, nonnegative=True))
    elif kind == "modal":
        ratios = dt.raw("ratios")
        if not isinstance(ratios, list):
            raise MechanismError(f"{dt.path}.ratios must be a list of damping ratios, got "
                                 f"{ratios!r}")
        damping = ModalDamping(tuple(ratios))
    else:
        matrix = dt.raw("matrix")
        if not isinstance(matrix, list) or not all(isinstance(row, list) for row in matrix):
            raise MechanismError(f"{dt.path}.matrix must be a list of rows (N s/m), got {matrix!r}")
        damping = DampingMatrix(tuple(tuple(row) for row in matrix))
    return ElasticLink(**{**{f: getattr(link, f) for f in link.__dataclass_fields__},
                          "damping": damping})


def _joint(name: str, data: object, path: str):
    """A joint from its ``[joints.<name>]`` table: the class its ``type`` names reads its own keys."""
    every_key = tuple(dict.fromkeys(key for cls in JOINT_TYPES.values() for key in cls.KEYS))
    kind = _Table(data, path, every_key).string("type", next(iter(JOINT_TYPES)), tuple(JOINT_TYPES))
    cls = JOINT_TYPES[kind]
    return cls.from_table(name, _Table(data, path, cls.KEYS))


def _drive(data: object, path: str, joint: str | None) -> PrescribedDrive | TorqueDrive:
    kind = _Table(data, path, _TORQUE_KEYS).string("type", "prescribed", ("prescribed", "torque"))
    t = _Table(data, path, _TORQUE_KEYS if kind == "torque" else _PRESCRIBED_KEYS)
    if joint is not None and t.has("joint"):
        raise MechanismError(f"{path}: the joint is the table name {joint!r}; remove key 'joint'")
    harmonics = t.raw("harmonics", [])
    if not isinstance(harmonics, list) or not all(isinstance(h, list) and len(h) == 3
                                                  for h in harmonics):
        raise MechanismError(f"{path}.harmonics must be a list of [k, cos_k, sin_k] (rad), got "
                             f"{harmonics!r}")
    common = dict(joint=joint if joint is not None else t.string("joint"),
                  rate=t.number("rate", "rad/s", 0.0), offset=t.number("offset", "rad", 0.0),
                  harmonics=tuple(tuple(h) for h in harmonics))
    if kind == "torque":
        limit = t.number("torque_limit", "N m", positive=True) if t.has("torque_limit") else math.inf
        return TorqueDrive(**common, kp=t.number("kp", "N m/rad", 0.0, nonnegative=True),
                           kd=t.number("kd", "N m s/rad", 0.0, nonnegative=True),
                           motor=_motor(t.table("motor"), f"{path}.motor") if t.has("motor") else None,
                           flywheel=t.number("flywheel", "kg m^2", 0.0, nonnegative=True),
                           torque_limit=limit, feedforward=t.boolean("feedforward", True))
    return PrescribedDrive(**common)


def _motor(data: object, path: str) -> DCMotor:
    """A ``[drive.motor]`` table: the characteristic by ``stall_torque`` and ``no_load_speed`` or by
    the armature constants ``resistance``, ``torque_constant``, ``supply_voltage``."""
    t = _Table(data, path, _MOTOR_KEYS)
    extra = dict(rotor_inertia=t.number("rotor_inertia", "kg m^2", 0.0, nonnegative=True),
                 gear_ratio=t.number("gear_ratio", "1", 1.0, positive=True))
    characteristic = [k for k in ("stall_torque", "no_load_speed") if t.has(k)]
    armature = [k for k in ("resistance", "torque_constant", "supply_voltage") if t.has(k)]
    if characteristic and armature:
        raise MechanismError(f"{path}: give either stall_torque and no_load_speed or the armature "
                             f"constants resistance, torque_constant and supply_voltage, not both")
    if armature:
        return DCMotor.from_armature(resistance=t.number("resistance", "ohm", positive=True),
                                     torque_constant=t.number("torque_constant", "N m/A",
                                                              positive=True),
                                     supply_voltage=t.number("supply_voltage", "V", positive=True),
                                     **extra)
    return DCMotor(t.number("stall_torque", "N m", positive=True),
                   t.number("no_load_speed", "rad/s", positive=True), **extra)


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


def build(spec: Mapping[str, Any], *, source: str = "scene") -> Mechanism:
    """A validated ``Mechanism`` from a scene spec (the dict a TOML scene file parses to).

    Raises ``MechanismError`` naming ``source``, the key path and what was expected.
    """
    try:
        return _build(spec)
    except MechanismError as error:
        raise MechanismError(f"{source}: {error}") from None


def _build(spec: Mapping[str, Any]) -> Mechanism:
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
    return Mechanism(
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


# ---------------------------------------------------------------------------------------------------
# Mechanism -> spec, paths, TOML text
# ---------------------------------------------------------------------------------------------------
def to_spec(mech: Mechanism) -> dict[str, Any]:
    """The spec of a mechanism: its own if it was built from one, else written from its parts."""
    if mech.spec is not None:
        return copy.deepcopy(dict(mech.spec))
    spec: dict[str, Any] = {"name": mech.name}
    if not mech.period_is_default:
        spec["period"] = mech.period
    if mech.gravity != (0.0, 0.0):
        spec["gravity"] = list(mech.gravity)
    if mech.initial_angles:
        spec["initial_angles"] = dict(mech.initial_angles)
    spec["links"] = {link.name: _link_spec(link) for link in mech.links}
    spec["joints"] = {}
    for joint in mech.joints:
        spec["joints"][joint.name] = joint.to_table()
    spec["drives"] = {}
    for drive in mech.drives:
        entry = {"type": "torque" if isinstance(drive, TorqueDrive) else "prescribed",
                 "rate": drive.rate, "offset": drive.offset,
                 "harmonics": [list(h) for h in drive.harmonics]}
        if isinstance(drive, TorqueDrive):
            entry.update(kp=drive.kp, kd=drive.kd, flywheel=drive.flywheel,
                         feedforward=drive.feedforward)
            if math.isfinite(drive.torque_limit):
                entry["torque_limit"] = drive.torque_limit
            if drive.motor is not None:
                entry["motor"] = {key: getattr(drive.motor, key) for key in
                                  ("stall_torque", "no_load_speed", "rotor_inertia", "gear_ratio")}
        spec["drives"][drive.joint] = entry
    if mech.controllers:
        spec["controllers"] = {c.name: c.to_table() for c in mech.controllers}
    if mech.point_masses:
        spec["point_masses"] = {f"mass{i}": {"link": pm.link, "point": pm.point, "mass": pm.mass,
                                             "inertia": pm.inertia}
                                for i, pm in enumerate(mech.point_masses)}
    if mech.studies:
        spec["studies"] = copy.deepcopy(dict(mech.studies))
    return spec


def _link_spec(link: RigidLink | ElasticLink) -> dict[str, Any]:
    if isinstance(link, RigidLink):
        entry: dict[str, Any] = {"type": "rigid", "length": link.length, "mass": link.mass,
                                 "inertia": link.inertia}
        if link.centroid is not None:
            entry["centroid"] = list(link.centroid)
        if link.points:
            entry["points"] = {key: list(p) for key, p in link.points.items()}
        return entry
    if isinstance(link.discretisation, UserShapes):
        raise MechanismError(f"link {link.name!r}: user shape functions cannot be written to a "
                             f"scene; use Ritz or Fem, or change the parts with Mechanism.replace")
    entry = {"type": "elastic", "length": link.length, "density": link.density,
             "youngs_modulus": link.youngs_modulus, "area": link.area,
             "second_moment": link.second_moment, "boundary": link.boundary, "axial": link.axial,
             "geometric_stiffening": link.geometric_stiffening,
             "rotary_inertia": link.rotary_inertia}
    if link.yield_strength is not None:
        entry["yield_strength"] = link.yield_strength
    if link.outer_fibre is not None:
        entry["outer_fibre"] = link.outer_fibre
    entry["discretisation"] = link.discretisation.to_table()
    if isinstance(link.damping, Rayleigh):
        entry["damping"] = {"type": "rayleigh", "alpha": link.damping.alpha,
                            "beta": link.damping.beta}
    elif isinstance(link.damping, ModalDamping):
        entry["damping"] = {"type": "modal", "ratios": list(link.damping.ratios)}
    elif isinstance(link.damping, DampingMatrix):
        entry["damping"] = {"type": "matrix", "matrix": [list(r) for r in link.damping.matrix]}
    return entry


def without_feedback_spec(spec: Mapping[str, Any]) -> dict[str, Any]:
    """A copy of ``spec`` without feedback (``Mechanism.without_feedback``): every torque drive's
    ``kp`` and ``kd`` set to 0, the ``[controllers]`` tables removed."""
    result = copy.deepcopy(dict(spec))
    result.pop("controllers", None)
    tables = [result["drive"]] if isinstance(result.get("drive"), dict) else list(
        (result.get("drives") or {}).values())
    for table in tables:
        if isinstance(table, dict) and table.get("type") == "torque":
            table["kp"] = table["kd"] = 0.0
    return result


def set_path(spec: Mapping[str, Any], path: str, value: Any) -> dict[str, Any]:
    """A copy of ``spec`` with the value at dotted ``path`` (e.g. ``"links.coupler.thickness"``) set;
    missing tables on the way are created, and ``build`` then checks the key."""
    if not isinstance(path, str) or not path or any(not part for part in path.split(".")):
        raise MechanismError(f"parameter path must be dotted keys like 'links.coupler.thickness', "
                             f"got {path!r}")
    result = copy.deepcopy(dict(spec))
    table, parts = result, path.split(".")
    for depth, key in enumerate(parts[:-1]):
        if key not in table:
            table[key] = {}
        elif not isinstance(table[key], dict):
            raise MechanismError(f"parameter path {path!r}: {'.'.join(parts[:depth + 1])} is a "
                                 f"value ({table[key]!r}), not a table")
        table = table[key]
    if path == "drive.rate" and "drive" not in spec and "drives" in spec:
        raise MechanismError("parameter path 'drive.rate': this scene declares [drives.<joint>] "
                             "tables; use 'drives.<joint>.rate'")
    table[parts[-1]] = copy.deepcopy(value)
    return result


def _toml_key(key: str) -> str:
    return key if key.replace("_", "").replace("-", "").isalnum() else _toml_value(key)


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise MechanismError(f"cannot write the non-finite number {value!r} to TOML")
        return repr(value)
    if isinstance(value, str):
        escaped = value.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n")
        return f'"{escaped}"'
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, Mapping):
        return "{" + ", ".join(f"{_toml_key(k)} = {_toml_value(v)}" for k, v in value.items()) + "}"
    raise MechanismError(f"cannot write {value!r} ({type(value).__name__}) to TOML")


def dumps(spec: Mapping[str, Any]) -> str:
    """TOML text of a spec: scalars and arrays first, then one ``[table]`` per nested table."""
    lines: list[str] = []

    def emit(table: Mapping[str, Any], prefix: str) -> None:
        scalars = {k: v for k, v in table.items() if not isinstance(v, Mapping)}
        tables = {k: v for k, v in table.items() if isinstance(v, Mapping)}
        if prefix and (scalars or not tables):
            lines.append(f"\n[{prefix}]")
        lines.extend(f"{_toml_key(k)} = {_toml_value(v)}" for k, v in scalars.items())
        for key, sub in tables.items():
            emit(sub, f"{prefix}.{_toml_key(key)}" if prefix else _toml_key(key))

    emit(spec, "")
    return "\n".join(lines).lstrip("\n") + "\n"


# ---------------------------------------------------------------------------------------------------
# Files and built-in scenes
# ---------------------------------------------------------------------------------------------------
def scenes() -> list[str]:
    """Names of the scenes shipped with the package, for ``mechanisms.load(name)``."""
    folder = resources.files("mechanisms") / "scenes"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".toml"))


def load(path_or_name: str | Path) -> Mechanism:
    """A ``Mechanism`` from a built-in scene name (see ``scenes()``) or a ``.toml`` file path."""
    if not isinstance(path_or_name, (str, Path)):
        raise TypeError(f"load() takes a scene name or a path, got {type(path_or_name).__name__}")
    path = Path(path_or_name)
    if path.suffix == ".toml" or path.exists():
        if not path.is_file():
            raise FileNotFoundError(f"scene file {str(path)!r} does not exist")
        source = str(path)
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError as error:
            raise MechanismError(f"{source}: not a TOML text file (not UTF-8: byte {error.start} is "
                                 f"{error.object[error.start:error.start + 1]!r})") from None
    else:
        names = scenes()
        if str(path_or_name) not in names:
            close = difflib.get_close_matches(str(path_or_name), names, n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise MechanismError(f"no built-in scene {str(path_or_name)!r}{hint} (built-in scenes: "
                                 f"{', '.join(names)}; or give a path to a .toml file)")
        text = (resources.files("mechanisms") / "scenes" / f"{path_or_name}.toml").read_text(
            encoding="utf-8")
        source = f"scene {path_or_name!r}"
    return loads(text, source=source)


def loads(text: str, *, source: str = "scene") -> Mechanism:
    """A ``Mechanism`` from TOML text."""
    try:
        spec = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise MechanismError(f"{source}: not valid TOML: {error}") from None
    return build(spec, source=source)
