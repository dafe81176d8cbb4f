"""Operations on scene specs: a mechanism's spec, a path set in a spec, feedback removed, TOML text.

A spec is the nested dicts a TOML scene file parses to (``docs/scenes.md``); ``Mechanism.from_spec``
reads one back.
"""

from __future__ import annotations

import copy
import math
from typing import Any, Mapping

from .checks import MechanismError
from .drives import DRIVE_TYPES
from .links import ElasticLink, RigidLink


def to_spec(mech) -> dict[str, Any]:
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
        entry = drive.to_table()
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
    if link.damping is not None:
        entry["damping"] = link.damping.to_table()
    return entry


def without_feedback_spec(spec: Mapping[str, Any]) -> dict[str, Any]:
    """A copy of ``spec`` without feedback (``Mechanism.without_feedback``): every drive's table without
    its feedback gains (its kind's ``table_without_feedback``: a torque drive's ``kp`` and ``kd`` 0), the
    ``[controllers]`` tables removed."""
    result = copy.deepcopy(dict(spec))
    result.pop("controllers", None)
    tables = [result["drive"]] if isinstance(result.get("drive"), dict) else list(
        (result.get("drives") or {}).values())
    for table in tables:
        kind = DRIVE_TYPES.get(table.get("type", next(iter(DRIVE_TYPES)))) if isinstance(table, dict) else None
        if kind is not None:
            table.update(kind.table_without_feedback(table))
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


