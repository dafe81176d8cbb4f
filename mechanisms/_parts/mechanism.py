"""The mechanism: its parts, validated together when it is made."""

from __future__ import annotations

import dataclasses
import difflib
import math
from dataclasses import dataclass, field
from typing import Any, Mapping

from . import spec as _spec
from .checks import (
    GROUND,
    MAX_TURNS,
    MIN_LENGTH_FRACTION,
    MIN_PERIOD_FRACTION,
    MechanismError,
    _check_number,
    _check_pair,
)
from .controllers import CONTROLLER_TYPES, Controller
from .drives import DRIVE_TYPES, Drive
from .grashof import check_four_bar
from .joints import JOINT_TYPES, Joint
from .links import ElasticLink, Link, PointMass, RigidLink, _pin_position
from .scene import parts_from_spec


@dataclass(frozen=True)
class Mechanism:
    """An immutable planar mechanism, validated when it is made.

    ``initial_angles`` maps link names to a guess of their frame angle at ``t = 0`` (rad), used to pick
    the assembly branch. ``period`` (s) defaults to ``2 pi / |rate|`` of the first drive; every drive's
    ``rate * period`` must be a whole number of turns so that the nominal motion is periodic.

    ``spec`` is the scene description (the TOML tables as a dict) the mechanism was built from, kept
    so that ``with_parameter("links.coupler.thickness", 2e-3)`` rebuilds it with every derived
    quantity (area, I, Rayleigh beta from a damping ratio) recomputed; ``None`` for mechanisms made
    from parts. ``studies`` is the scene's raw ``[studies]`` table, kept for the ``studies`` package
    and not interpreted here.
    """

    name: str
    links: tuple[Link, ...]
    joints: tuple[Joint, ...]
    drives: tuple[Drive, ...]
    point_masses: tuple[PointMass, ...] = ()
    gravity: tuple[float, float] = (0.0, 0.0)
    initial_angles: Mapping[str, float] = field(default_factory=dict)
    period: float | None = None
    controllers: tuple[Controller, ...] = ()
    spec: Mapping[str, Any] | None = field(default=None, compare=False, repr=False)
    studies: Mapping[str, Any] = field(default_factory=dict, compare=False, repr=False)
    period_is_default: bool = field(default=False, init=False, compare=False, repr=False)

    def __post_init__(self) -> None:
        for key in ("links", "joints", "drives", "point_masses", "controllers"):
            object.__setattr__(self, key, tuple(getattr(self, key)))
        object.__setattr__(self, "gravity", tuple(self.gravity))
        _validate(self)

    # --- lookup ---------------------------------------------------------------------------------------
    def link(self, name: str) -> Link:
        """The link called ``name``."""
        for link in self.links:
            if link.name == name:
                return link
        raise KeyError(f"no link {name!r}; links are {[l.name for l in self.links]}")

    def joint(self, name: str) -> Joint:
        """The joint called ``name``."""
        for joint in self.joints:
            if joint.name == name:
                return joint
        raise KeyError(f"no joint {name!r}; joints are {[j.name for j in self.joints]}")

    # --- variants for sweeps --------------------------------------------------------------------------
    def replace(self, **changes: Any) -> "Mechanism":
        """A new validated mechanism with dataclass fields replaced (``links=..., period=...``).

        The result carries no ``spec`` (it would no longer describe it); to change one scene
        parameter and keep derived quantities consistent use ``with_parameter``.
        """
        unknown = set(changes) - {f.name for f in dataclasses.fields(self) if f.init}
        if unknown:
            raise TypeError(f"Mechanism.replace() got unknown fields {sorted(unknown)}")
        if "period" not in changes and self.period_is_default:
            changes["period"] = None  # recompute from the (possibly new) drives
        changes.setdefault("spec", None)
        return dataclasses.replace(self, **changes)

    def with_parameter(self, path: str, value: Any) -> "Mechanism":
        """A new validated mechanism with one scene parameter changed, named by its dotted path in
        the scene file, e.g. ``"drive.rate"``, ``"links.coupler.thickness"``,
        ``"links.coupler.damping.ratio"``, ``"gravity"``. Derived quantities are recomputed."""
        return self.with_parameters({path: value})

    def with_parameters(self, changes: Mapping[str, Any]) -> "Mechanism":
        """Like ``with_parameter`` for several ``{path: value}`` at once."""
        spec = _spec.to_spec(self)
        for path, value in changes.items():
            spec = _spec.set_path(spec, path, value)
        return Mechanism.from_spec(spec, source=f"{self.name} with {dict(changes)}")

    @property
    def torque_drives(self) -> tuple:
        """The drives that apply a torque the dynamics answer (``IMPOSES_MOTION`` False: torque drives),
        in order."""
        return tuple(d for d in self.drives if not d.IMPOSES_MOTION)

    def without_feedback(self) -> "Mechanism":
        """The same machine with every feedback removed: the torque drives' ``kp``, ``kd`` set to 0
        and the controllers dropped; the feedforward torque and the motors (characteristic, rotor
        inertia, gear), flywheels and torque limits kept."""
        if self.spec is not None:
            return Mechanism.from_spec(_spec.without_feedback_spec(self.spec),
                                       source=f"{self.name} without feedback")
        return self.replace(drives=tuple(d.without_feedback() for d in self.drives), controllers=())

    # --- the scene description ------------------------------------------------------------------------
    @classmethod
    def from_spec(cls, spec: Mapping[str, Any], *, source: str = "scene") -> "Mechanism":
        """A validated mechanism from a scene spec (the dict a TOML scene file parses to; what
        ``mechanisms.build`` takes). Raises ``MechanismError`` naming ``source``, the key path and
        what was expected."""
        try:
            return cls(**parts_from_spec(spec))
        except MechanismError as error:
            raise MechanismError(f"{source}: {error}") from None

    def to_spec(self) -> dict[str, Any]:
        """The scene description as nested dicts (what ``mechanisms.build`` takes)."""
        return _spec.to_spec(self)

    def to_toml(self) -> str:
        """The scene as TOML text that ``mechanisms.load`` reads back to an equal mechanism."""
        return _spec.dumps(self.to_spec())


def _by_name(parts: tuple, types: tuple[type, ...], kind: str) -> dict[str, Any]:
    """Parts keyed by their names, checking their types and that no name repeats."""
    named: dict[str, Any] = {}
    for part in parts:
        if not isinstance(part, types):
            raise MechanismError(f"{kind}s must be {' or '.join(t.__name__ for t in types)}, got "
                                 f"{part!r}")
        if part.name in named:
            raise MechanismError(f"duplicate {kind} name {part.name!r}")
        named[part.name] = part
    return named


def _validate(mech: Mechanism) -> None:
    """Checks how the parts fit together; each failure names the part and the fix."""
    if not isinstance(mech.name, str) or not mech.name:
        raise MechanismError(f"mechanism name must be a non-empty string, got {mech.name!r}")
    if not mech.links:
        raise MechanismError(f"mechanism {mech.name!r} has no links")
    links: dict[str, Link] = _by_name(mech.links, (RigidLink, ElasticLink), "link")

    def known_link(owner: str, name: str) -> Link:
        if name not in links:
            close = difflib.get_close_matches(str(name), list(links) + [GROUND], n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise MechanismError(f"{owner} names unknown link {name!r} (links: {list(links)}, or "
                                 f"{GROUND!r}){hint}")
        return links[name]

    joints: dict[str, Joint] = _by_name(mech.joints, tuple(JOINT_TYPES.values()), "joint")
    neighbours: dict[str, set[str]] = {name: set() for name in links}
    grounded: set[str] = set()
    for joint in mech.joints:
        owner = f"joint {joint.name!r}"
        ends = joint.ends
        for link_name, point in ends:
            _pin_position(known_link(owner, link_name), point, owner)
        if len(ends) == 1:  # the other side is the ground
            grounded.add(ends[0][0])
        for (first, _), (second, _) in zip(ends, ends[1:]):
            neighbours[first].add(second)
            neighbours[second].add(first)

    driven: set[str] = set()
    for drive in mech.drives:
        if not isinstance(drive, tuple(DRIVE_TYPES.values())):
            raise MechanismError(f"drives must be drives of a registered kind "
                                 f"({', '.join(cls.__name__ for cls in DRIVE_TYPES.values())}: "
                                 f"mechanisms.register_drive), got {drive!r}")
        joint = joints.get(drive.joint)
        if joint is None or joint.drive_terms() is None:
            drivable = [j.name for j in mech.joints if j.drive_terms() is not None]
            raise MechanismError(f"drive names joint {drive.joint!r}, which is not a revolute joint "
                                 f"of the mechanism (joints a drive can act at: {drivable})")
        if drive.joint in driven:
            raise MechanismError(f"joint {drive.joint!r} is driven twice")
        driven.add(drive.joint)
    if not mech.drives:
        drivable = [j.name for j in mech.joints if j.drive_terms() is not None]
        raise MechanismError(f"mechanism {mech.name!r} has no drive: a scene needs a [drive] table, e.g. "
                             f"type = \"prescribed\", joint = \"{drivable[0] if drivable else 'O'}\", "
                             f"rate = 100.0 (rad/s) (or one [drives.<joint>] table per drive; docs/scenes.md); "
                             f"joints a drive can act at: {drivable}")

    torque_joints = [d.joint for d in mech.torque_drives]
    _by_name(mech.controllers, tuple(CONTROLLER_TYPES.values()), "controller")
    for controller in mech.controllers:
        if controller.joint not in torque_joints:
            raise MechanismError(f"controller {controller.name!r} names joint {controller.joint!r}, "
                                 f"which has no torque drive (torque drives act at "
                                 f"{torque_joints}); a controller adds to a torque drive's torque")

    for pm in mech.point_masses:
        owner = f"point mass on {pm.link!r}"
        _pin_position(known_link(owner, pm.link), pm.point, owner)
    _check_pair(f"mechanism {mech.name!r}", "gravity", mech.gravity, "m/s^2")
    for name, angle in mech.initial_angles.items():
        known_link("initial_angles", name)
        _check_number("initial_angles", name, angle, "rad")

    # Every link must hang together with the ground, else it floats freely.
    reached, frontier = set(grounded), list(grounded)
    while frontier:
        for other in neighbours[frontier.pop()] - reached:
            reached.add(other)
            frontier.append(other)
    floating = [name for name in links if name not in reached]
    if floating:
        raise MechanismError(f"links {floating} are not connected to the ground by joints")

    # Mobility (Gruebler): the rigid coordinates (3 per link) must be fixed by the joints and drives,
    # so that the nominal motion is determined and the rigid subsystem is square.
    n_rigid = 3 * len(mech.links)
    n_equations = sum(j.n_equations for j in mech.joints) + len(mech.drives)
    if n_equations != n_rigid:
        mobility = n_rigid - n_equations + len(mech.drives)
        raise MechanismError(
            f"linkage {mech.name!r} cannot be assembled as a driven mechanism: {len(mech.links)} "
            f"links have {n_rigid} rigid coordinates but the joints and drives give {n_equations} "
            f"constraint equations (mobility {mobility} with {len(mech.drives)} drive(s)); "
            f"{'add' if n_equations < n_rigid else 'remove'} joints or drives so that they match")

    # Period: default from the first drive; all drives must repeat over it.
    period, is_default = mech.period, mech.period is None
    if is_default:
        rate = mech.drives[0].rate
        if rate == 0.0:
            raise MechanismError(f"mechanism {mech.name!r}: the first drive has rate 0, so give the "
                                 f"period of its motion explicitly (period = ... s)")
        period = 2.0 * math.pi / abs(rate)
    _check_number(f"mechanism {mech.name!r}", "period", period, "s", positive=True)
    _check_physical_sense(mech, period)
    for drive in mech.drives:
        turns = drive.rate * period / (2.0 * math.pi)
        travel = harmonic_travel(drive)
        if abs(turns) <= MAX_TURNS and not abs(turns) + travel / (2.0 * math.pi) <= MAX_TURNS:  # also nan
            raise MechanismError(
                f"drive at joint {drive.joint!r}: its harmonics move the joint through {travel:.3g} rad per "
                f"period (each harmonic (k, cos_k, sin_k) travels 4 k sqrt(cos_k^2 + sin_k^2) rad), with "
                f"its rate {abs(turns):.3g} turns; at most {MAX_TURNS} turns in all (one period is resolved "
                f"by the studies' n_steps, and the accelerations grow as k^2 times the amplitude): give "
                f"harmonics of a few radians")
        if not abs(turns) <= MAX_TURNS:  # also inf from an overflowing product
            raise MechanismError(f"drive at joint {drive.joint!r}: rate {drive.rate} rad/s with period "
                                 f"{period:.6g} s turns {abs(turns):.3g} times per period; at most "
                                 f"{MAX_TURNS} (one period is resolved by the studies' n_steps and "
                                 f"scanned at 4096 crank angles per turn): give a shorter period")
        if abs(turns - round(turns)) > 1e-9 * max(1.0, abs(turns)):
            raise MechanismError(f"drive at joint {drive.joint!r}: rate {drive.rate} rad/s turns "
                                 f"{turns:.6g} times per period {period:.6g} s; the nominal motion "
                                 f"is periodic only for a whole number of turns")
    object.__setattr__(mech, "period", float(period))
    object.__setattr__(mech, "period_is_default", is_default)

    check_four_bar(mech, links)


def harmonic_travel(drive) -> float:
    """The angle (rad) a drive's harmonics move its joint through in one period: a harmonic
    ``cos_k cos(k w t) + sin_k sin(k w t)`` of amplitude ``A = sqrt(cos_k^2 + sin_k^2)`` swings k
    times over ``2 A`` and back, ``4 k A`` in all (its acceleration peaks at ``k^2 w^2 A``)."""
    return float(sum(4.0 * abs(k) * math.hypot(c, s) for k, c, s in getattr(drive, "harmonics", ())))


def _check_physical_sense(mech, period: float) -> None:
    """Refuse a link far shorter than the mechanism's longest, and a period far shorter than its
    elastic links' natural periods (docs/scenes.md, "Limits"): both are judged relative to the
    mechanism itself, so a millimetre-scale machine is as valid as a metre-scale one."""
    longest = max(link.length for link in mech.links)
    for link in mech.links:
        if link.length < MIN_LENGTH_FRACTION * longest:
            raise MechanismError(
                f"links.{link.name}.length: {link.length:.3g} m is below {MIN_LENGTH_FRACTION:g} of the "
                f"mechanism's longest link ({longest:.3g} m), limit {MIN_LENGTH_FRACTION * longest:.3g} m: "
                f"no joint or deflection is resolved at that scale; check the unit (metres)")
    elastic = [link for link in mech.links if hasattr(link, "first_bending_frequency")]
    if not elastic:
        return
    shortest = min(2.0 * math.pi / link.first_bending_frequency() for link in elastic)
    if period < MIN_PERIOD_FRACTION * shortest:
        raise MechanismError(
            f"mechanism {mech.name!r}: period {period:.3g} s is below {MIN_PERIOD_FRACTION:g} of its "
            f"elastic links' shortest natural period ({shortest:.3g} s, the first bending mode), limit "
            f"{MIN_PERIOD_FRACTION * shortest:.3g} s: the drive would turn {shortest / period:.3g} times "
            f"per elastic oscillation; check the unit (seconds) or the drive's rate")

