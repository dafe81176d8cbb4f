"""``flexvib show SCENE``: what a scene holds and what it offers, without running anything.

Its links (kind, length, section, discretisation, damping), joints, drives, controllers, the
values ``--set PATH=VALUE`` may change, the observables it offers (each link's quantities with the
names they take, the joints' force components, the drives' torques, the named points), and the
studies it declares; ``--out FILE.png`` draws the mechanism at t = 0 with the names of its links and
joints.

Everything is asked of the objects and their registries, never of a list of kinds written here: a
part's table is its own ``to_table`` (through ``Mechanism.to_spec``), a link's quantities are those
of ``mechanisms.quantity_names()`` that the assembled model accepts for it (``Model.observable``
refuses a rigid link's deflection), a joint's force components are its ``force_components()``, a
drive's torque is ``drive.<joint>.torque``. A joint, discretisation, controller or observable
registered from outside shows up with no change here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

#: The fraction of a link's length used to probe whether a quantity taking ``@fraction`` applies.
PROBE_FRACTION = 0.5
#: Scene keys shown in the header, not as --set values of a part.
_TEXT_KEYS = ("name", "description")


@dataclass(frozen=True)
class Offered:
    """The observables a scene offers: ``link_quantities`` {link: [(spec pattern, unit), ...]},
    ``points`` {link: named points for ``@POINT``}, ``joint_forces`` [(spec, unit)], ``drive_torques``
    [(spec, unit)], ``default`` the specs reported when none are asked for."""

    link_quantities: dict[str, list[tuple[str, str]]] = field(default_factory=dict)
    points: dict[str, list[str]] = field(default_factory=dict)
    joint_forces: list[tuple[str, str]] = field(default_factory=list)
    drive_torques: list[tuple[str, str]] = field(default_factory=list)
    default: tuple[str, ...] = ()


def offered_observables(mechanism: Any) -> Offered:
    """What ``observables = [...]`` of the scene may name, found by asking the assembled model to
    make each candidate spec (a refused one is not offered)."""
    import linearize
    import mechanisms

    model = mechanisms.assemble(mechanism)
    offered = Offered(default=tuple(linearize.default_observables(mechanism)))
    for link in mechanism.links:
        found = []
        for quantity in mechanisms.quantity_names():
            for spec, shown in ((f"{link.name}.{quantity}@{PROBE_FRACTION}", f"{link.name}.{quantity}@F"),
                                (f"{link.name}.{quantity}", f"{link.name}.{quantity}")):
                unit = _unit_of(model, spec)
                if unit is not None:
                    found.append((shown, unit))
                    break
        offered.link_quantities[link.name] = found
        offered.points[link.name] = ["start", "end", *getattr(link, "points", {})]
    for joint in mechanism.joints:
        for component in (*joint.force_components(), "force"):
            spec = f"joint.{joint.name}.{component}"
            unit = _unit_of(model, spec)
            if unit is not None and (spec, unit) not in offered.joint_forces:
                offered.joint_forces.append((spec, unit))
    for drive in mechanism.drives:
        spec = f"drive.{drive.joint}.torque"
        unit = _unit_of(model, spec)
        if unit is not None:
            offered.drive_torques.append((spec, unit))
    return offered


def _unit_of(model: Any, spec: str) -> str | None:
    """The unit of observable ``spec`` of ``model``, or None when the model refuses it (a bad input
    for this link or joint: a ``ValueError``, as every refusal of a spec is)."""
    try:
        observable = model.observable(spec)
    except ValueError:
        return None
    return str(getattr(observable, "unit", "")) or "1"


def settable_values(spec: Mapping[str, Any], prefix: str = "") -> list[tuple[str, Any]]:
    """``[(dotted path, value), ...]``: every value of a scene spec that ``--set PATH=VALUE`` may
    replace (numbers, booleans, strings and lists), depth first in the file's order."""
    out: list[tuple[str, Any]] = []
    for key, value in spec.items():
        path = f"{prefix}{key}"
        if isinstance(value, Mapping):
            out += settable_values(value, f"{path}.")
        elif not (prefix == "" and key in _TEXT_KEYS):
            out.append((path, value))
    return out


def _value(value: Any) -> str:
    """A scene value as a person reads it: numbers to 6 significant digits, lists shortened."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, (list, tuple)):
        shown = ", ".join(_value(v) for v in value[:4])
        return f"[{shown}{', ...' if len(value) > 4 else ''}]" + (f" ({len(value)} entries)" if len(value) > 4 else "")
    return str(value)


def _part(table: Mapping[str, Any], units: Mapping[str, str], skip: tuple[str, ...] = ()) -> str:
    """A part's table in one line: ``key value unit`` pairs, sub-tables as ``name: type (key value)``."""
    words, tables = [], []
    for key, value in table.items():
        if key in skip:
            continue
        if isinstance(value, Mapping):
            inner = {k: v for k, v in value.items() if k != "type"}
            kind = f"{value['type']} " if "type" in value else ""
            tables.append(f"{key}: {kind}({', '.join(f'{k} {_value(v)}' for k, v in inner.items())})"
                          if inner else f"{key}: {kind.strip()}")
        else:
            unit = units.get(key, "")
            words.append(f"{key} {_value(value)}" + (f" {unit}" if unit and unit != "1" else ""))
    return "; ".join([", ".join(words)] + tables) if words else "; ".join(tables)


def describe(mechanism: Any) -> str:
    """The text ``flexvib show`` prints for ``mechanism``."""
    from .._mechanism import _UNITS

    spec = mechanism.to_spec()
    lines = [f"scene {mechanism.name}" + (f": {spec['description']}" if spec.get("description") else ""),
             f"period {mechanism.period:.6g} s" + "".join(
                 f"; drive at {d.joint} {d.rate:.6g} rad/s" for d in mechanism.drives if d.rate)
             + f"; gravity ({mechanism.gravity[0]:g}, {mechanism.gravity[1]:g}) m/s^2"]
    links = spec.get("links", {})
    lines += ["", f"links ({len(mechanism.links)})"]
    width = max((len(name) for name in links), default=4)
    for link in mechanism.links:
        table = links.get(link.name, {})
        kind = table.get("type", "")
        lines.append(f"  {link.name:{width}s}  {kind:8s} {_part(table, _UNITS, skip=('type',))}")
        if math.isfinite(getattr(link, "mass", math.nan)):
            lines[-1] += f"  [mass {link.mass:.4g} kg]"
    lines += ["", f"joints ({len(mechanism.joints)})"]
    width = max((len(joint.name) for joint in mechanism.joints), default=4)
    for joint in mechanism.joints:
        table = joint.to_table()
        lines.append(f"  {joint.name:{width}s}  {table.get('type', '')}: {_part(table, _UNITS, skip=('type',))}")
    drives = spec.get("drives") or ({spec["drive"].get("joint", "?"): spec["drive"]} if "drive" in spec else {})
    lines += ["", f"drives ({len(mechanism.drives)})"]
    for joint, table in drives.items():
        lines.append(f"  at {joint}: {table.get('type', '')}: {_part(table, _UNITS, skip=('type', 'joint'))}")
    lines += ["", f"controllers ({len(mechanism.controllers)})"]
    for controller in mechanism.controllers:
        table = controller.to_table()
        lines.append(f"  {controller.name}: {table.get('type', '')}: {_part(table, _UNITS, skip=('type',))}")
    if not mechanism.controllers:
        lines.append("  none")
    if mechanism.point_masses:
        lines += ["", f"point masses ({len(mechanism.point_masses)})"]
        lines += [f"  on {pm.link} at {_value(pm.point)}: mass {pm.mass:.6g} kg, inertia {pm.inertia:.6g} kg m^2"
                  for pm in mechanism.point_masses]
    lines += ["", *_observables_text(offered_observables(mechanism))]
    studies = spec.get("studies") or {}
    declared = [key for key, value in studies.items() if isinstance(value, Mapping)]
    lines += ["", "studies declared: " + (", ".join(declared) if declared else
                                          "none ([studies] absent: flexvib run runs the default set)")]
    values = [(path, value) for path, value in settable_values(spec)]
    lines += ["", f"values --set PATH=VALUE may change ({len(values)}; studies.<study>.<key> too, "
                  f"docs/studies.md)"]
    width = max((len(path) for path, _ in values), default=4)
    for path, value in values:
        unit = _UNITS.get(path.rsplit(".", 1)[-1], "")
        lines.append(f"  {path:{width}s}  {_value(value)}" + (f" {unit}" if unit and unit != "1" else ""))
    return "\n".join(lines)


def _observables_text(offered: Offered) -> list[str]:
    lines = ["observables (for [studies] observables = [...]; F a fraction of the link's length in [0, 1], "
             "POINT a named point)",
             f"  default: {', '.join(offered.default) or 'none (no elastic link)'}"]
    for link, found in offered.link_quantities.items():
        if found:
            lines.append(f"  {link}: " + ", ".join(f"{spec} ({unit})" for spec, unit in found))
    lines.append("  named points (point_error*@POINT): "
                 + "; ".join(f"{link}: {', '.join(points)}" for link, points in offered.points.items()))
    if offered.joint_forces:
        lines.append("  joint forces: " + ", ".join(f"{spec} ({unit})" for spec, unit in offered.joint_forces))
    if offered.drive_torques:
        lines.append("  drive torques: " + ", ".join(f"{spec} ({unit})" for spec, unit in offered.drive_torques))
    return lines


def draw(mechanism: Any, out: str | Path) -> Path:
    """Draw ``mechanism`` at t = 0 (its rigid nominal position) with the names of its links and
    joints into ``out`` (PNG or any format matplotlib writes)."""
    from types import SimpleNamespace

    import mechanisms

    from .._drawing import draw_names, mechanism_drawing
    from .._plots import _pyplot

    nominal = mechanisms.nominal_motion(mechanism, n_steps=8)
    drawing = mechanism_drawing(SimpleNamespace(mechanism=mechanism, nominal=nominal))
    plt = _pyplot()
    figure, ax = plt.subplots(figsize=(6.4, 4.8), layout="constrained")
    draw_names(ax, drawing, 0)
    ax.set_title(f"{mechanism.name} at t = 0 (rigid nominal position)", fontsize="medium")
    figure.savefig(out, dpi=110)
    plt.close(figure)
    return Path(out)
