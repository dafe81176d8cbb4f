"""Controllers: what they add to the torque of the ``TorqueDrive`` at their joint."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, Union

from .checks import MechanismError, _check_name, _check_number, register_class

#: The controller classes by their scene-file ``type``, filled by ``register_controller``.
CONTROLLER_TYPES: dict[str, type] = {}

_INTERFACE = ("TYPE", "KEYS", "from_table", "to_table", "law")


def register_controller(cls: type) -> type:
    """Enter the controller class ``cls`` in ``CONTROLLER_TYPES`` under its ``TYPE`` and return it
    (a class decorator). A controller is a frozen class with ``name``, ``joint`` (the torque drive
    it adds to) and ``lag`` (s, 0 for none), its scene ``TYPE``, ``KEYS``, ``from_table(name,
    table)``, ``to_table()`` and ``law()`` (its ``ControllerLaw``); optionally ``law_derivative(key)``,
    the ``ControllerLaw`` per unit of its scalar scene key ``key`` (a gain: the law is linear in its
    gains) or None where the law is not linear in that key, which the sensitivities read for their
    closed-form derivatives (a controller without it is differenced)."""
    return register_class(CONTROLLER_TYPES, cls, _INTERFACE, "controller", "mechanisms.PDController")


@dataclass(frozen=True)
class ControllerLaw:
    """What a controller adds to its torque drive's law (``Model.drive_torque_terms``):
    ``kp (angle_nominal - angle) + kd (rate_nominal - rate)`` on the driven angle (N m/rad,
    N m s/rad) and, with ``observable`` (a spec), ``-(gain o + rate_gain o')``. Each controller
    class returns its own from ``law()``; the model never asks which class it holds."""

    kp: float = 0.0
    kd: float = 0.0
    observable: str | None = None
    gain: float = 0.0
    rate_gain: float = 0.0


@dataclass(frozen=True)
class _Controller:
    """What every controller has: its ``name`` and the ``joint`` of the torque drive it adds to."""

    name: str
    joint: str


@register_controller
@dataclass(frozen=True)
class PDController(_Controller):
    """PD on the driven angle of the torque drive at ``joint`` (the thesis's case): adds
    ``kp (angle_nominal - angle) + kd (rate_nominal - rate)`` (N m) to its torque."""

    TYPE: ClassVar[str] = "pd"
    KEYS: ClassVar[tuple[str, ...]] = ("type", "joint", "kp", "kd", "lag")

    kp: float = 0.0
    kd: float = 0.0
    lag: float = 0.0

    def __post_init__(self) -> None:
        owner = _checked_owner(self)
        _check_number(owner, "kp", self.kp, "N m/rad", nonnegative=True)
        _check_number(owner, "kd", self.kd, "N m s/rad", nonnegative=True)

    @classmethod
    def from_table(cls, name: str, table) -> "PDController":
        return cls(name, table.string("joint"), table.number("kp", "N m/rad", 0.0, nonnegative=True),
                   table.number("kd", "N m s/rad", 0.0, nonnegative=True), _lag_of(table))

    def to_table(self) -> dict[str, Any]:
        return {"type": self.TYPE, "joint": self.joint, "kp": self.kp, "kd": self.kd,
                **_lag_entry(self.lag)}

    def law(self) -> ControllerLaw:
        return ControllerLaw(kp=float(self.kp), kd=float(self.kd))

    def law_derivative(self, key: str) -> ControllerLaw | None:
        """d law / d ``key``: the law of unit ``kp`` or ``kd`` (it is linear in them); None for
        ``lag`` (the lag is not a gain)."""
        return {"kp": ControllerLaw(kp=1.0), "kd": ControllerLaw(kd=1.0)}.get(key)


@register_controller
@dataclass(frozen=True)
class ObservableFeedback(_Controller):
    """Feedback of a measured elastic quantity to the torque drive at ``joint``: adds
    ``-(gain o + rate_gain o')`` (N m) to its torque, ``o`` the observable ``observable`` (e.g.
    ``"coupler.strain@0.5"``, the strain a gauge at midspan reads; its unit sets those of the
    gains) and ``o'`` its time derivative. The observable must be a linear function of the elastic
    coordinates alone (deflection, slope, curvature, strain of a link), so that it is zero on the
    rigid nominal motion and the feedback vanishes there."""

    TYPE: ClassVar[str] = "feedback"
    KEYS: ClassVar[tuple[str, ...]] = ("type", "joint", "observable", "gain", "rate_gain", "lag")

    observable: str
    gain: float = 0.0
    rate_gain: float = 0.0
    lag: float = 0.0

    def __post_init__(self) -> None:
        owner = _checked_owner(self)
        if not isinstance(self.observable, str) or not self.observable:
            raise MechanismError(f"{owner}: observable must be an observable spec such as "
                                 f"'coupler.strain@0.5', got {self.observable!r}")
        _check_number(owner, "gain", self.gain, "N m per unit of the observable")
        _check_number(owner, "rate_gain", self.rate_gain, "N m s per unit of the observable")

    @classmethod
    def from_table(cls, name: str, table) -> "ObservableFeedback":
        return cls(name, table.string("joint"), table.string("observable"),
                   table.number("gain", "N m per unit of the observable", 0.0),
                   table.number("rate_gain", "N m s per unit of the observable", 0.0), _lag_of(table))

    def to_table(self) -> dict[str, Any]:
        return {"type": self.TYPE, "joint": self.joint, "observable": self.observable,
                "gain": self.gain, "rate_gain": self.rate_gain, **_lag_entry(self.lag)}

    def law(self) -> ControllerLaw:
        return ControllerLaw(observable=self.observable, gain=float(self.gain),
                             rate_gain=float(self.rate_gain))

    def law_derivative(self, key: str) -> ControllerLaw | None:
        """d law / d ``key``: the feedback of unit ``gain`` or ``rate_gain`` (it is linear in them);
        None for ``lag``."""
        if key not in ("gain", "rate_gain"):
            return None
        return ControllerLaw(observable=self.observable, **{key: 1.0})


# A controller's ``lag`` (s): the time constant of a first-order lag ``lag y' + y = u`` between its
# law ``u`` and the torque ``y`` it adds (0: none).  For these linear laws a sensor lag (the measured
# signal filtered, its rate taken from the filtered signal) is the same transfer function, so one
# key serves both.
def _checked_owner(controller) -> str:
    """Check a controller's name and ``lag`` (what every controller has); its name for messages."""
    _check_name("controller", controller.name)
    owner = f"controller {controller.name!r}"
    _check_number(owner, "lag", controller.lag, "s", nonnegative=True)
    return owner


def _lag_of(table) -> float:
    return table.number("lag", "s", 0.0, nonnegative=True)


def _lag_entry(lag: float) -> dict[str, float]:
    """The ``lag`` key of a controller's table: written only when there is a lag (older tables stay
    as they were)."""
    return {"lag": lag} if lag else {}


Controller = Union[PDController, ObservableFeedback]
