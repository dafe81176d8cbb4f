"""Drives: a prescribed motion or a torque at a revolute joint, and the DC motor of a torque drive.

A drive kind is a frozen class entered in ``DRIVE_TYPES`` by ``register_drive`` (the scene loader, the
``Mechanism``'s checks and the scene writer find it there). It has the fields ``joint``, ``rate``,
``offset``, ``harmonics`` and ``profile`` (its nominal law, ``drive_law``) and declares:

- ``TYPE`` and ``KEYS``, ``from_table(joint, table)`` and ``to_table()``: its scene table
  (``[drive]`` or ``[drives.<joint>]``), and ``table_without_feedback(table)``, that table with its
  feedback gains zeroed;
- ``IMPOSES_MOTION``: True for a drive that imposes its joint's angle (one rheonomic constraint row,
  the drive torque its multiplier), False for one that applies a torque the dynamics answer (the
  assembler then reads the torque drive's law: ``kp``, ``kd``, ``motor``, ``torque_limit``);
- ``feedforward`` (whether the nominal inverse-dynamics torque is applied) and ``inertia`` (kg m^2
  turning with the driven side);
- ``kinematic()``: the drive that imposes its nominal motion (itself when it imposes motion), which
  the nominal (rigid) motion is computed with; ``without_feedback()``: itself with no feedback gains.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Callable, Union

import numpy as np

from .checks import (
    MAX_HARMONIC_ORDER,
    MAX_HARMONICS,
    MechanismError,
    _check_count,
    _check_number,
    _is_number,
    register_class,
)
from .table import _Table

#: The drive kinds by scene ``type`` (``register_drive``); the first is a scene's default.
DRIVE_TYPES: dict[str, type] = {}

_INTERFACE = ("TYPE", "KEYS", "IMPOSES_MOTION", "from_table", "to_table", "table_without_feedback",
              "kinematic", "without_feedback", "angle", "inertia", "feedforward")

#: The keys every drive's table shares (its nominal law).
LAW_KEYS = ("type", "joint", "rate", "offset", "harmonics")


def register_drive(cls: type) -> type:
    """Enter the drive class ``cls`` in ``DRIVE_TYPES`` under its ``TYPE`` and return it (a class
    decorator). The interface is the module docstring's; see ``mechanisms.PrescribedDrive``."""
    return register_class(DRIVE_TYPES, cls, _INTERFACE, "drive", "mechanisms.PrescribedDrive")


def law_from_table(joint: str, t: _Table) -> dict[str, Any]:
    """The nominal law's fields (``joint``, ``rate``, ``offset``, ``harmonics``) from a drive's table ``t``
    (``joint``: the table's name, or None to read its ``joint`` key)."""
    harmonics = t.raw("harmonics", [])
    if not isinstance(harmonics, list) or not all(isinstance(h, list) and len(h) == 3
                                                  for h in harmonics):
        raise MechanismError(f"{t.path}.harmonics must be a list of [k, cos_k, sin_k] (rad), got "
                             f"{harmonics!r}")
    return dict(joint=joint if joint is not None else t.string("joint"),
                rate=t.number("rate", "rad/s", 0.0), offset=t.number("offset", "rad", 0.0),
                harmonics=tuple(tuple(h) for h in harmonics))


def _law_table(drive: Any) -> dict[str, Any]:
    """The nominal law's part of a drive's scene table (the joint is the table's name)."""
    return {"type": drive.TYPE, "rate": drive.rate, "offset": drive.offset,
            "harmonics": [list(h) for h in drive.harmonics]}


def _check_drive(drive: "PrescribedDrive | TorqueDrive") -> None:
    owner = f"drive at joint {drive.joint!r}"
    _check_number(owner, "rate", drive.rate, "rad/s")
    if drive.profile is not None and drive.harmonics:
        raise MechanismError(f"{owner}: a speed profile replaces offset + rate t; harmonics of the "
                             f"period (got {len(drive.harmonics)}) have no meaning along it: drop them")
    _check_number(owner, "offset", drive.offset, "rad")
    if len(drive.harmonics) > MAX_HARMONICS:
        raise MechanismError(f"{owner}: harmonics has {len(drive.harmonics)} entries; at most "
                             f"{MAX_HARMONICS} (the motion is sampled n_steps times per period)")
    for i, harmonic in enumerate(drive.harmonics):
        if len(harmonic) != 3:
            raise MechanismError(f"{owner}: harmonics[{i}] must be (k, cos_k, sin_k), got "
                                 f"{harmonic!r}")
        _check_count(owner, f"harmonics[{i}] order k", harmonic[0], 1, MAX_HARMONIC_ORDER,
                     "the motion is sampled n_steps times per period, at most 65536")
        _check_number(owner, f"harmonics[{i}] cos_k", harmonic[1], "rad")
        _check_number(owner, f"harmonics[{i}] sin_k", harmonic[2], "rad")


@dataclass(frozen=True)
class RampShape:
    """How a speed ramp goes from its start to its stop speed: ``fraction(u)`` of the change done at
    the ramp's fraction of time ``u`` in [0, 1], as ``(F, f, f')`` with ``f(0) = 0``, ``f(1) = 1``,
    ``F(u)`` the integral of ``f`` from 0 and ``f'`` its derivative (arrays of ``u``'s shape)."""

    name: str
    fraction: Callable[[Any], tuple[Any, Any, Any]]


#: The registered ramp shapes by name (``register_ramp_shape``): a run-up's ``profile``.
RAMP_SHAPES: dict[str, RampShape] = {}


def register_ramp_shape(shape: RampShape) -> RampShape:
    """Add ``shape`` to ``RAMP_SHAPES`` under its name (a name taken raises ``MechanismError``)."""
    if shape.name in RAMP_SHAPES and RAMP_SHAPES[shape.name] is not shape:
        raise MechanismError(f"ramp shape {shape.name!r} is already registered "
                             f"({', '.join(RAMP_SHAPES)})")
    RAMP_SHAPES[shape.name] = shape
    return shape


def _linear_fraction(u):
    return 0.5 * u * u, u, 1.0 + 0.0 * u


def _smooth_fraction(u):
    # half a cosine: the acceleration starts and ends at zero, no jerk at the ramp's ends
    sin, cos = (math.sin, math.cos) if isinstance(u, float) else (np.sin, np.cos)
    return (0.5 * u - sin(math.pi * u) / (2.0 * math.pi), 0.5 * (1.0 - cos(math.pi * u)),
            0.5 * math.pi * sin(math.pi * u))


register_ramp_shape(RampShape("linear", _linear_fraction))
register_ramp_shape(RampShape("smooth", _smooth_fraction))


@dataclass(frozen=True)
class SpeedRamp:
    """A drive rate (rad/s) going from ``start`` at t = 0 to ``stop`` at ``duration`` (s) along the
    ramp shape ``shape`` (a name of ``RAMP_SHAPES``: ``"linear"``, ``"smooth"``), held at ``stop``
    after it and at ``start`` before t = 0. ``law(t)`` is the angle turned since t = 0 (rad), the
    rate and its derivative (rad/s^2): a drive carrying it as its ``profile`` follows
    ``offset + angle(t)`` instead of ``offset + rate t`` (a run-up or run-down, ``start > stop``)."""

    start: float
    stop: float
    duration: float
    shape: str = "linear"

    def __post_init__(self) -> None:
        for name in ("start", "stop"):
            _check_number("speed ramp", name, getattr(self, name), "rad/s")
        _check_number("speed ramp", "duration", self.duration, "s", positive=True)
        if self.shape not in RAMP_SHAPES:
            raise MechanismError(f"speed ramp: shape must be one of {sorted(RAMP_SHAPES)}, got "
                                 f"{self.shape!r}")

    def law(self, t):
        """``(angle, rate, acceleration)`` at ``t`` (s, a float or an array of floats)."""
        change, duration = self.stop - self.start, self.duration
        fraction = RAMP_SHAPES[self.shape].fraction
        if isinstance(t, float):   # one time, as the integrator asks: plain floats, no arrays
            if t <= 0.0:
                return self.start * t, self.start, 0.0
            if t >= duration:
                return (self.start * duration + change * duration * float(fraction(1.0)[0])
                        + self.stop * (t - duration), self.stop, 0.0)
            big_f, f, df = fraction(t / duration)
            return (self.start * t + change * duration * float(big_f), self.start + change * float(f),
                    change / duration * float(df))
        t = np.asarray(t, dtype=float)
        big_f, f, df = fraction(np.clip(t / duration, 0.0, 1.0))
        inside = (t > 0.0) & (t < duration)
        angle = (self.start * np.minimum(t, duration) + change * duration * big_f
                 + self.stop * np.maximum(t - duration, 0.0))
        angle = np.where(t < 0.0, self.start * t, angle)
        rate = self.start + change * f
        acc = np.where(inside, change / duration * df, 0.0)
        if angle.ndim == 0:
            return float(angle), float(rate), float(acc)
        return angle, rate, acc


def drive_law(drive: "PrescribedDrive | TorqueDrive", period: float | None, t
              ) -> tuple[float, float, float]:
    """Nominal relative angle of a drive at time ``t`` (s) with its first and second derivatives:
    ``offset + rate t + sum_k cos_k cos(k w t) + sin_k sin(k w t)``, ``w = 2 pi / period``, or with
    a ``profile`` (a ``SpeedRamp``: an object with ``law(t)``) ``offset + profile.law(t)``.
    ``t`` may also be an array: the three results are then arrays of its shape."""
    if drive.profile is not None:
        angle, rate, acc = drive.profile.law(t)
        return drive.offset + angle, rate, acc
    angle = drive.offset + drive.rate * t
    rate = drive.rate + 0.0 * t
    acc = 0.0 * t
    if drive.harmonics:
        w = 2.0 * math.pi / period
        for k, ck, sk in drive.harmonics:
            kw = k * w
            c, s = np.cos(kw * t), np.sin(kw * t)
            angle += ck * c + sk * s
            rate += kw * (-ck * s + sk * c)
            acc -= kw * kw * (ck * c + sk * s)
    return angle, rate, acc


def _drive_angle(drive: "PrescribedDrive | TorqueDrive", t: float,
                 period: float | None) -> tuple[float, float, float]:
    """The drive's nominal relative angle (rad), its rate (rad/s) and acceleration (rad/s^2) at
    time ``t`` (s); ``period`` (s) sets the harmonics' fundamental (``drive_law``)."""
    return drive_law(drive, period, t)


@register_drive
@dataclass(frozen=True)
class PrescribedDrive:
    """Prescribes the relative rotation at revolute joint ``joint``: the angle of ``link_b``'s material
    tangent minus that of ``link_a`` (ground: absolute angle) follows

        angle(t) = offset + rate t + sum_k (cos_k cos(k w t) + sin_k sin(k w t)),  w = 2 pi / period

    with ``harmonics`` a tuple of ``(k, cos_k, sin_k)``. One constraint equation (rheonomic).
    ``inertia`` (kg m^2) turns with ``link_b`` about the joint: the rotor and flywheel a torque
    drive carries into its nominal motion (``TorqueDrive.inertia``); not a scene key."""

    TYPE = "prescribed"
    KEYS = LAW_KEYS
    IMPOSES_MOTION = True
    #: a prescribed drive applies no torque law: its torque is the constraint's multiplier
    feedforward = False

    joint: str
    rate: float = 0.0
    offset: float = 0.0
    harmonics: tuple[tuple[int, float, float], ...] = ()
    inertia: float = 0.0
    profile: Any = None

    def __post_init__(self) -> None:
        _check_drive(self)
        _check_number(f"drive at joint {self.joint!r}", "inertia", self.inertia, "kg m^2",
                      nonnegative=True)

    @classmethod
    def from_table(cls, joint: str | None, t: _Table) -> "PrescribedDrive":
        return cls(**law_from_table(joint, t))

    def to_table(self) -> dict[str, Any]:
        return _law_table(self)

    @staticmethod
    def table_without_feedback(table: dict[str, Any]) -> dict[str, Any]:
        return table

    def kinematic(self) -> "PrescribedDrive":
        return self

    def without_feedback(self) -> "PrescribedDrive":
        return self

    angle = _drive_angle


@dataclass(frozen=True)
class DCMotor:
    """A DC motor with a linear speed-torque characteristic behind a gear of ratio ``gear_ratio``
    (motor speed / crank speed). At full supply voltage the motor gives ``stall_torque`` (N m) at
    rest and none at ``no_load_speed`` (rad/s, motor shaft); at the command ``v`` in [-1, 1] (the
    voltage over the supply voltage) its torque is ``stall_torque (v - omega_m / no_load_speed)``.
    At the crank (angle rate ``theta'``, ``omega_m = G theta'``):

        tau = G stall_torque v - c theta',     c = G^2 stall_torque / no_load_speed (back EMF),

    and the rotor adds ``G^2 rotor_inertia`` (kg m^2) on the crank. From armature constants
    (``from_armature``): ``stall_torque = k_t V / R``, ``no_load_speed = V / k_t`` (SI: the
    back-EMF constant equals the torque constant ``k_t``)."""

    #: the keys of its scene table (a torque drive's ``motor``)
    KEYS = ("stall_torque", "no_load_speed", "resistance", "torque_constant", "supply_voltage",
            "rotor_inertia", "gear_ratio")

    stall_torque: float
    no_load_speed: float
    rotor_inertia: float = 0.0
    gear_ratio: float = 1.0

    def __post_init__(self) -> None:
        _check_number("motor", "stall_torque", self.stall_torque, "N m", positive=True)
        _check_number("motor", "no_load_speed", self.no_load_speed, "rad/s", positive=True)
        _check_number("motor", "rotor_inertia", self.rotor_inertia, "kg m^2", nonnegative=True)
        _check_number("motor", "gear_ratio", self.gear_ratio, "1", positive=True)

    @classmethod
    def from_armature(cls, *, resistance: float, torque_constant: float, supply_voltage: float,
                      rotor_inertia: float = 0.0, gear_ratio: float = 1.0) -> "DCMotor":
        """The motor of armature resistance (ohm), torque constant (N m/A = V s/rad) and supply
        voltage (V)."""
        _check_number("motor", "resistance", resistance, "ohm", positive=True)
        _check_number("motor", "torque_constant", torque_constant, "N m/A", positive=True)
        _check_number("motor", "supply_voltage", supply_voltage, "V", positive=True)
        return cls(torque_constant * supply_voltage / resistance, supply_voltage / torque_constant,
                   rotor_inertia, gear_ratio)

    @property
    def back_emf_damping(self) -> float:
        """``c = G^2 stall_torque / no_load_speed`` (N m s/rad at the crank)."""
        return self.gear_ratio ** 2 * self.stall_torque / self.no_load_speed

    @property
    def peak_command(self) -> float:
        """The largest command at the crank, ``G stall_torque`` (N m): full supply voltage."""
        return self.gear_ratio * self.stall_torque

    @property
    def reflected_inertia(self) -> float:
        """The rotor's inertia seen at the crank, ``G^2 rotor_inertia`` (kg m^2)."""
        return self.gear_ratio ** 2 * self.rotor_inertia

    @classmethod
    def from_table(cls, data: object, path: str) -> "DCMotor":
        """A ``[drive.motor]`` table: the characteristic by ``stall_torque`` and ``no_load_speed`` or by
        the armature constants ``resistance``, ``torque_constant``, ``supply_voltage``."""
        t = _Table(data, path, cls.KEYS)
        extra = dict(rotor_inertia=t.number("rotor_inertia", "kg m^2", 0.0, nonnegative=True),
                     gear_ratio=t.number("gear_ratio", "1", 1.0, positive=True))
        characteristic = [k for k in ("stall_torque", "no_load_speed") if t.has(k)]
        armature = [k for k in ("resistance", "torque_constant", "supply_voltage") if t.has(k)]
        if characteristic and armature:
            raise MechanismError(f"{path}: give either stall_torque and no_load_speed or the armature "
                                 f"constants resistance, torque_constant and supply_voltage, not both")
        if armature:
            return cls.from_armature(resistance=t.number("resistance", "ohm", positive=True),
                                     torque_constant=t.number("torque_constant", "N m/A", positive=True),
                                     supply_voltage=t.number("supply_voltage", "V", positive=True),
                                     **extra)
        return cls(t.number("stall_torque", "N m", positive=True),
                   t.number("no_load_speed", "rad/s", positive=True), **extra)

    def to_table(self) -> dict[str, float]:
        return {key: getattr(self, key) for key in ("stall_torque", "no_load_speed", "rotor_inertia",
                                                    "gear_ratio")}



@register_drive
@dataclass(frozen=True)
class TorqueDrive:
    """A torque on ``link_b`` of revolute joint ``joint`` (reaction on ``link_a``). The nominal motion
    follows ``PrescribedDrive(joint, rate, offset, harmonics)``; the applied torque is the nominal
    inverse-dynamics torque (the feedforward; ``feedforward=False`` switches it off) plus a PD
    correction on the deviation from it:

        tau = tau_nominal(t) + kp (angle_nominal - angle) + kd (rate_nominal - rate)

    plus what the mechanism's controllers acting at this joint add. Without the feedforward the
    nominal motion is only the reference of the feedback (and the motion the linearisation is
    about): the machine follows it only as closely as the feedback forces it to. ``motor`` (a ``DCMotor`` or
    ``None``: an ideal torque source) adds its back-EMF damping ``c (rate_nominal - rate)`` (its
    feedforward voltage covers the back EMF of the nominal speed) and its rotor inertia;
    ``flywheel`` (kg m^2) is an inertia on ``link_b`` about the joint. The torque saturates at
    ``+-torque_limit`` (N m) and, with a motor, where the command reaches the supply voltage
    (``|tau + c rate| <= G stall_torque``), in nonlinear runs; the linearisation uses the
    unsaturated law and its linear range reports the peak demanded torque against the limits.
    """

    TYPE = "torque"
    KEYS = LAW_KEYS + ("kp", "kd", "motor", "flywheel", "torque_limit", "feedforward")
    IMPOSES_MOTION = False

    joint: str
    rate: float = 0.0
    offset: float = 0.0
    harmonics: tuple[tuple[int, float, float], ...] = ()
    kp: float = 0.0
    kd: float = 0.0
    motor: DCMotor | None = None
    flywheel: float = 0.0
    torque_limit: float = math.inf
    feedforward: bool = True
    profile: Any = None

    def __post_init__(self) -> None:
        _check_drive(self)
        owner = f"drive at joint {self.joint!r}"
        if not isinstance(self.feedforward, bool):
            raise MechanismError(f"{owner}: feedforward must be true or false, got "
                                 f"{self.feedforward!r}")
        _check_number(owner, "kp", self.kp, "N m/rad", nonnegative=True)
        _check_number(owner, "kd", self.kd, "N m s/rad", nonnegative=True)
        _check_number(owner, "flywheel", self.flywheel, "kg m^2", nonnegative=True)
        if not (self.torque_limit == math.inf or (_is_number(self.torque_limit)
                                                 and self.torque_limit > 0)):
            raise MechanismError(f"{owner}: torque_limit must be a positive number (N m), got "
                                 f"{self.torque_limit!r}")
        if self.motor is not None and not isinstance(self.motor, DCMotor):
            raise MechanismError(f"{owner}: motor must be a DCMotor or None, got {self.motor!r}")

    @classmethod
    def from_table(cls, joint: str | None, t: _Table) -> "TorqueDrive":
        limit = t.number("torque_limit", "N m", positive=True) if t.has("torque_limit") else math.inf
        return cls(**law_from_table(joint, t), kp=t.number("kp", "N m/rad", 0.0, nonnegative=True),
                   kd=t.number("kd", "N m s/rad", 0.0, nonnegative=True),
                   motor=DCMotor.from_table(t.table("motor"), f"{t.path}.motor") if t.has("motor") else None,
                   flywheel=t.number("flywheel", "kg m^2", 0.0, nonnegative=True),
                   torque_limit=limit, feedforward=t.boolean("feedforward", True))

    def to_table(self) -> dict[str, Any]:
        entry = {**_law_table(self), "kp": self.kp, "kd": self.kd, "flywheel": self.flywheel,
                 "feedforward": self.feedforward}
        if math.isfinite(self.torque_limit):
            entry["torque_limit"] = self.torque_limit
        if self.motor is not None:
            entry["motor"] = self.motor.to_table()
        return entry

    @staticmethod
    def table_without_feedback(table: dict[str, Any]) -> dict[str, Any]:
        return {**table, "kp": 0.0, "kd": 0.0}

    def kinematic(self) -> PrescribedDrive:
        """The prescribed drive of its nominal law (its rotor and flywheel kept): the nominal motion's."""
        return PrescribedDrive(self.joint, self.rate, self.offset, self.harmonics, inertia=self.inertia)

    def without_feedback(self) -> "TorqueDrive":
        return dataclasses.replace(self, kp=0.0, kd=0.0)

    def law_derivative(self, key: str):
        """d(its PD law)/d ``key``: the ``ControllerLaw`` of unit ``kp`` or ``kd`` (the law is linear in
        them; the sensitivities' closed form, as a controller's); None for its other keys."""
        from .controllers import ControllerLaw

        return {"kp": ControllerLaw(kp=1.0), "kd": ControllerLaw(kd=1.0)}.get(key)

    @property
    def inertia(self) -> float:
        """Inertia (kg m^2) turning with ``link_b`` about the joint: the motor's rotor through its
        gear and the flywheel."""
        return self.flywheel + (self.motor.reflected_inertia if self.motor is not None else 0.0)

    angle = _drive_angle


Drive = Union[PrescribedDrive, TorqueDrive]

