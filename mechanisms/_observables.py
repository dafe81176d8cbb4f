"""Observables of an assembled model: scalars of ``s`` with their gradients (``Observable`` protocol).

Specs (``link`` a link name, ``f`` a fraction of the link length in [0, 1], default 0.5):

* ``"link.deflection@f"``: distance (m) of the material point at ``x = f L`` from the chord through
  the link's start and tip, positive on the frame's +y side. For a pinned-pinned link the frame is
  the chord frame and this is ``w(x)``; for a clamped-free link it is measured from the deformed chord.
* ``"link.transverse@f"``: transverse displacement ``w(x)`` (m) in the link's frame: for a
  pinned-pinned link the same as ``deflection``; for a clamped-free link (robot arms) the deflection
  from the root tangent, so ``@1.0`` is the tip deflection.
* ``"link.strain@f"``: membrane (neutral-axis) strain, 1: ``u'(x)``, or with geometric stiffening
  the projected membrane strain the strain energy uses, ``u'(x) + P[w'^2/2](x)`` (``_assemble``);
  for Hermite elements it is constant on an element, and at a node the element to the right is used.
* ``"link.moment@f"``: bending moment ``EI w''(x)``, N m (for Hermite elements, at a node the element
  to the right is used).
* ``"link.angle"``: the frame angle ``theta``, rad (for an elastic link: the chord or root tangent).
* ``"link.point_error_x@p"``, ``"link.point_error_y@p"``: the global x, y position (m) of a point of
  any link (``p`` a fraction of the length, or a named point of a rigid link's ``points``,
  ``"start"``, ``"end"``). Its value is the position; its change from the rigid nominal motion is
  the displacement of the point from its rigid nominal position (the output precision).
  ``"link.point_error@p"``: the magnitude of that displacement (``PairMagnitude``).

The quantities of a link (the part after ``link.``) are looked up in one registry
(``mechanisms._quantities``) that the built-in ones above join at import and
``mechanisms.register_observable(name, function, unit=...)`` extends with a user's function of the
coordinates; an unknown name is refused with the nearest one suggested.

Quantities that are not functions of ``s`` alone (``linearize`` supplies the nominal motion):

* ``"joint.J.<component>"``: a component of joint ``J``'s force, a weighted sum of its multipliers
  (``MultiplierObservable``) with the weights its class declares (``force_components()``): for a
  revolute joint and a slider ``fx``, ``fy``, the force (N, global axes) on its ``link_b`` from its
  ``link_a`` (a slider: on its link from the ground), and ``force`` their magnitude.
* ``"drive.J.torque"``: the torque (N m) of the drive at joint ``J`` on its ``link_b``:
  ``-lam`` of a prescribed drive's row (``MultiplierObservable``), the torque law of a torque drive
  (``TorqueLawObservable``).
* ``"link.stress_top@f"``, ``"link.stress_bottom@f"``: normal stress (Pa) at the extreme fibres
  ``y = +c`` (the frame's +y side, where positive deflection points) and ``y = -c`` of an elastic
  link: ``N / A -+ M c / I`` with ``M = EI w''`` the ``moment`` observable (``StressObservable``).
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass

import numpy as np

from ._parts import ArgumentError, ElasticLink
from ._quantities import OfCoordinates, add_quantity, fraction_of, quantity

_KINDS = {"deflection": "m", "transverse": "m", "strain": "1", "moment": "N m", "angle": "rad"}
_POINT_KINDS = {"point_error_x": 0, "point_error_y": 1}
_STRESS_KINDS = {"stress_top": 1.0, "stress_bottom": -1.0}  # sign of the fibre's y


# How an observable is evaluated is its own business: each class below says it in two methods,
# ``linear_map(route)`` (the linearisation: ``route`` is what ``linearize`` hands over) and
# ``along_run(run, linear_map)`` (a full nonlinear run: ``run`` is what ``studies`` hands over),
# both duck-typed and documented in ``_protocol.py`` (``LinearRoute``, ``RunRoute``); functions of
# the coordinates share them (``OfCoordinates``). A route offers a few primitives (a gradient map, a
# sum of multipliers, a drive's torque law, a magnitude, the nominal axial force) and the observable
# composes them. We prefer this to a declared category read through a table in ``linearize`` and
# ``studies``: a new kind of observable built from the same primitives (a new joint's force map, a
# new stress) then needs no edit of either table, and mechanisms still imports neither package.


@dataclass(frozen=True)
class LinkObservable(OfCoordinates):
    """One observable (see the module docstring). ``value(s)`` -> float, ``gradient(s)`` -> (n,)."""

    spec: str
    unit: str
    kind: str
    n_coords: int
    coords: slice          # the link's coordinates in s
    theta_index: int
    x: float               # abscissa (m); 0 for "angle"
    rows: tuple            # shape rows at x and at the tip, each (n_elastic,)
    length: float
    flexural_rigidity: float
    membrane: tuple        # with stiffening: (a (n_gauss,), w' at the Gauss points (n_gauss, n_e))
                           # so that P[w'^2/2](x) = a . (w'_g q)^2 / 2; else ()

    # The value and gradient read only the link's elastic coordinates (and, for "angle", its frame
    # angle, whose gradient is constant): linearize relies on this to evaluate the gradient once
    # along a rigid motion.
    depends_on_elastic_only = True

    def _q(self, s):
        s = np.asarray(s, dtype=float)
        if s.shape != (self.n_coords,):
            raise ArgumentError(f"s must have shape ({self.n_coords},); received shape {s.shape}")
        return s, s[self.coords][3:]

    def value(self, s) -> float:
        s, q = self._q(s)
        if self.kind == "angle":
            return float(s[self.theta_index])
        u, w, du, dw, ddw, u_tip, w_tip = self.rows
        if self.kind == "deflection":
            cx, cy = self.length + u_tip @ q, w_tip @ q
            px, py = self.x + u @ q, w @ q
            return float((cx * py - cy * px) / np.hypot(cx, cy))
        if self.kind == "transverse":
            return float(w @ q)
        if self.kind == "strain":
            if not self.membrane:
                return float(du @ q)
            weights, slopes = self.membrane
            return float(du @ q + 0.5 * weights @ (slopes @ q) ** 2)
        return float(self.flexural_rigidity * (ddw @ q))

    def values_along(self, s) -> np.ndarray:
        """``value`` at each row of ``s`` (K, n) at once: (K,) (a nonlinear run's samples; the same
        formulas, to round-off)."""
        s = np.asarray(s, dtype=float)
        if s.ndim != 2 or s.shape[1] != self.n_coords:
            raise ArgumentError(f"s must have shape (K, {self.n_coords}); received shape {s.shape}")
        if self.kind == "angle":
            return s[:, self.theta_index].copy()
        q = s[:, self.coords][:, 3:]
        u, w, du, dw, ddw, u_tip, w_tip = self.rows
        if self.kind == "deflection":
            cx, cy = self.length + q @ u_tip, q @ w_tip
            px, py = self.x + q @ u, q @ w
            return (cx * py - cy * px) / np.hypot(cx, cy)
        if self.kind == "transverse":
            return q @ w
        if self.kind == "strain":
            if not self.membrane:
                return q @ du
            weights, slopes = self.membrane
            return q @ du + 0.5 * ((q @ slopes.T) ** 2) @ weights
        return self.flexural_rigidity * (q @ ddw)

    def gradient(self, s) -> np.ndarray:
        s, q = self._q(s)
        out = np.zeros(self.n_coords)
        if self.kind == "angle":
            out[self.theta_index] = 1.0
            return out
        u, w, du, dw, ddw, u_tip, w_tip = self.rows
        if self.kind == "deflection":
            cx, cy = self.length + u_tip @ q, w_tip @ q
            px, py = self.x + u @ q, w @ q
            norm = np.hypot(cx, cy)
            cross = cx * py - cy * px
            d_cross = u_tip * py + cx * w - w_tip * px - cy * u
            d_norm = (cx * u_tip + cy * w_tip) / norm
            grad = d_cross / norm - cross * d_norm / norm**2
        elif self.kind == "transverse":
            grad = w.copy()
        elif self.kind == "strain":
            grad = du.copy()
            if self.membrane:
                weights, slopes = self.membrane
                grad += (weights * (slopes @ q)) @ slopes
        else:
            grad = self.flexural_rigidity * ddw
        out[self.coords][3:] = grad
        return out


def default_observables(mechanism) -> tuple[str, ...]:
    """The observables reported when none are asked for (by ``simulate`` and ``linearize``): the
    midspan deflection from the chord (``"link.deflection@0.5"``) of each pinned-pinned elastic
    link, the tip deflection from the root tangent (``"link.transverse@1.0"``) of each
    clamped-free one, in the order of ``mechanism.links``."""
    return tuple(f"{link.name}.deflection@0.5" if link.boundary == "pinned-pinned"
                 else f"{link.name}.transverse@1.0"
                 for link in mechanism.links if isinstance(link, ElasticLink))


@dataclass(frozen=True)
class PointObservable(OfCoordinates):
    """Global x or y position (m) of a material point of a link (module docstring):
    ``r = R + A(theta) (p + S q)``, ``p = (px, py)`` its undeformed local position, ``S = [Su; Sw]``
    the link's shape rows there (empty for a rigid link). ``value(s)`` -> float, ``gradient(s)``
    -> (n,); the gradient depends on the frame angle, so it is evaluated at each sample."""

    spec: str
    unit: str
    kind: str
    n_coords: int
    coords: slice          # the link's coordinates in s
    axis: int              # 0: x, 1: y
    local: tuple           # (px, py) m
    su: np.ndarray         # (n_elastic,)
    sw: np.ndarray         # (n_elastic,)

    depends_on_elastic_only = False

    def _parts(self, s):
        s = np.asarray(s, dtype=float)
        if s.shape != (self.n_coords,):
            raise ArgumentError(f"s must have shape ({self.n_coords},); received shape {s.shape}")
        link = s[self.coords]
        q = link[3:]
        lx = self.local[0] + (self.su @ q if q.size else 0.0)
        ly = self.local[1] + (self.sw @ q if q.size else 0.0)
        return link, lx, ly, np.cos(link[2]), np.sin(link[2])

    def value(self, s) -> float:
        link, lx, ly, c, sn = self._parts(s)
        if self.axis == 0:
            return float(link[0] + c * lx - sn * ly)
        return float(link[1] + sn * lx + c * ly)

    def gradient(self, s) -> np.ndarray:
        _, lx, ly, c, sn = self._parts(s)
        out = np.zeros(self.n_coords)
        start = self.coords.start
        out[start + self.axis] = 1.0
        if self.axis == 0:
            out[start + 2] = -sn * lx - c * ly
            out[start + 3:self.coords.stop] = c * self.su - sn * self.sw
        else:
            out[start + 2] = c * lx - sn * ly
            out[start + 3:self.coords.stop] = sn * self.su + c * self.sw
        return out


@dataclass(frozen=True)
class MultiplierObservable:
    """A weighted sum of the constraint multipliers, ``weights @ lam``: a joint's force component
    (N) or a prescribed drive's torque (N m). Not a function of ``s``: ``linearize`` evaluates it
    from the nominal multipliers and their linearised change."""

    spec: str
    unit: str
    kind: str
    weights: np.ndarray    # (r,)

    of_coordinates = False
    needs_multipliers = True

    def linear_map(self, route):
        return route.multipliers(self.weights, self.unit)

    def along_run(self, run, linear_map) -> np.ndarray:
        return run.multipliers(self.weights)

    def value_from(self, lam) -> float:
        return float(self.weights @ np.asarray(lam, dtype=float))

    def value(self, s) -> float:
        raise _not_of_coordinates(self.spec, "a sum of multipliers: MultiplierObservable."
                                             "value_from(lam) (SimulationResult.lam)")


@dataclass(frozen=True)
class TorqueLawObservable:
    """The torque (N m) a torque drive applies: its feedforward, PD, motor and controller law
    (``Model.drive_torque_terms(joint, ...)``, which also gives its derivatives in ``s`` and
    ``s'``: the change with ``x = s - s0``)."""

    spec: str
    unit: str
    kind: str
    drive_index: int       # position in mechanism.drives (and in NominalMotion.drive_torque)
    gradient: np.ndarray   # h (n,)
    joint: str

    of_coordinates = False
    needs_multipliers = False

    def linear_map(self, route):
        return route.torque_law(self.drive_index, self.joint, self.unit)

    def along_run(self, run, linear_map) -> np.ndarray:
        # what the run applied: feedforward and feedback summed before the drive's limits, which
        # the linear route's nominal + change cannot show
        return run.drive_torque(self.drive_index)

    def value(self, s) -> float:
        raise _not_of_coordinates(self.spec, "the drive's torque law: Model.drive_torques(s, "
                                             "sdot, t, lam)")


@dataclass(frozen=True)
class PairMagnitude:
    """The magnitude ``hypot(a, b)`` of a vector given by two observables: for joint forces the
    total force's magnitude, for point errors the magnitude of the displacement."""

    spec: str
    unit: str
    kind: str
    components: tuple      # (observable a, observable b)

    of_coordinates = False   # the magnitude of a change is not a function of s (value raises)

    @property
    def needs_multipliers(self) -> bool:
        return any(component.needs_multipliers for component in self.components)

    def linear_map(self, route):
        return route.magnitude(self.unit, tuple(c.linear_map(route) for c in self.components))

    def along_run(self, run, linear_map) -> np.ndarray:
        return np.hypot(*(component.along_run(run, component_map) for component, component_map
                          in zip(self.components, linear_map.components)))

    def value(self, s) -> float:
        raise _not_of_coordinates(self.spec, "the magnitude of a change or of a force: "
                                             "linearize.about(...).observe")


@dataclass(frozen=True)
class StressObservable:
    """Normal stress (Pa) at an extreme fibre ``y = fibre`` (signed, m) of an elastic link at
    abscissa ``x``: ``sigma = N / A - M fibre / I`` with ``M = EI w''`` (``moment``). ``N`` is
    ``EA`` times the membrane strain (``strain``) when the link has axial coordinates: they carry
    the axial load of the motion, so this is the total axial force. A link without axial
    coordinates is axially rigid: its ``N`` is the nominal axial force of the rigid inverse dynamics
    (``needs_axial_force``; ``linearize`` supplies it) and has no elastic change."""

    spec: str
    unit: str
    kind: str
    link: str
    x: float
    fibre: float
    area: float
    second_moment: float
    axial_stiffness: float
    moment: LinkObservable
    strain: LinkObservable | None

    @property
    def needs_axial_force(self) -> bool:
        return self.strain is None

    @property
    def of_coordinates(self) -> bool:
        return not self.needs_axial_force

    depends_on_elastic_only = True
    needs_multipliers = False

    def linear_map(self, route):
        # the nominal axial stress of an axially rigid link (not a function of s) plus the elastic
        # change; with axial coordinates the strain's response carries the whole axial force
        nominal = (route.axial_force(self.link, self.x) / self.area if self.needs_axial_force
                   else None)
        return route.coordinates(self, nominal=nominal)

    def along_run(self, run, linear_map) -> np.ndarray:
        # the elastic part along the run; the run adds the map's nominal axial stress
        return run.coordinates(self, linear_map, value=lambda s: self.value(s, axial_force=0.0))

    def value(self, s, axial_force: float | None = None) -> float:
        """The stress at ``s``; ``axial_force`` (N) is required without axial coordinates (and
        used only then)."""
        if self.strain is None and axial_force is None:
            raise _not_of_coordinates(self.spec, "the nominal axial force of an axially rigid "
                                                 "link: pass axial_force, or linearize.about")
        normal = (self.axial_stiffness * self.strain.value(s) if self.strain is not None
                  else axial_force)
        return float(normal / self.area - self.moment.value(s) * self.fibre / self.second_moment)

    def gradient(self, s) -> np.ndarray:
        """Gradient of the elastic part (the nominal axial force of an axially rigid link is not a
        function of ``s``)."""
        grad = -self.moment.gradient(s) * self.fibre / self.second_moment
        if self.strain is not None:
            grad = grad + self.axial_stiffness * self.strain.gradient(s) / self.area
        return grad


def _not_of_coordinates(spec: str, where: str) -> ArgumentError:
    return ArgumentError(f"observable {spec!r} is not a function of the coordinates s alone (it "
                         f"is {where}); mechanisms.simulate reports only such observables")


def make_observable(model, spec: str):
    """Parse ``spec`` against ``model`` (a ``mechanisms.Model``)."""
    if not isinstance(spec, str):
        raise TypeError(f"spec must be a string such as 'coupler.deflection@0.5'; received "
                        f"{type(spec).__name__}")
    head, _, where = spec.partition("@")
    parts = head.split(".")
    if len(parts) == 3 and parts[0] in ("joint", "drive") and parts[0] not in model.layouts:
        if where:
            raise ArgumentError(f"observable {spec!r}: a {parts[0]} quantity takes no '@'")
        if parts[0] == "joint":
            return _joint_observable(model, spec, parts[1], parts[2])
        return _drive_observable(model, spec, parts[1], parts[2])
    name, _, kind = head.rpartition(".")
    if name not in model.layouts:
        close = difflib.get_close_matches(name, list(model.layouts), n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise ArgumentError(f"observable {spec!r}: unknown link {name!r}{hint}; links are "
                            f"{list(model.layouts)} (or 'joint.<name>.fx|fy|force', "
                            f"'drive.<joint>.torque')")
    return quantity(spec, kind)(model, spec, model.layouts[name], kind, where)


def _link_observable(model, spec, lay, kind, where) -> LinkObservable:
    name = lay.link.name
    common = dict(spec=spec, unit=_KINDS[kind], kind=kind, n_coords=model.n_coords,
                  coords=lay.coords, theta_index=lay.offset + 2, length=lay.link.length)
    if kind == "angle":
        if where:
            raise ArgumentError(f"observable {spec!r}: 'angle' takes no '@fraction'")
        return LinkObservable(**common, x=0.0, rows=(), flexural_rigidity=0.0, membrane=())
    if lay.shapes is None:
        raise ArgumentError(f"observable {spec!r}: {kind} needs an elastic link; {name!r} is rigid")
    x = fraction_of(spec, where) * lay.link.length
    v = lay.shapes.evaluate([x, lay.link.length])
    rows = (v.u[0], v.w[0], v.du[0], v.dw[0], v.ddw[0], v.u[1], v.w[1])
    membrane = ()
    if lay.stiffening:
        membrane = (v.du[0] @ lay.membrane, lay.shapes.evaluate(lay.shapes.quadrature[0]).dw)
    return LinkObservable(**common, x=x, rows=rows, membrane=membrane,
                          flexural_rigidity=lay.link.youngs_modulus * lay.link.second_moment)


def _point_observable(model, spec, lay, kind, where):
    """A point's x or y position, or (``point_error``) the magnitude of its displacement."""
    if kind == "point_error":
        return PairMagnitude(spec, "m", kind, tuple(
            _point_observable(model, f"{spec.partition('@')[0]}_{axis}@{where}", lay,
                              f"point_error_{axis}", where) for axis in "xy"))
    link = lay.link
    try:
        float(where or 0.5)                    # a fraction of the length (checked below) ...
    except ValueError:
        try:                                   # ... or a named point ("start", "end", a key of points)
            px, py = link.point_position(where)
        except ValueError as error:
            raise ArgumentError(f"observable {spec!r}: {error}") from None
    else:
        px, py = fraction_of(spec, where) * link.length, 0.0
    if lay.shapes is None:
        su = sw = np.zeros(0)
    else:
        v = lay.shapes.evaluate([px])
        su, sw = v.u[0], v.w[0]
    return PointObservable(spec, "m", kind, model.n_coords, lay.coords, _POINT_KINDS[kind],
                           (float(px), float(py)), su, sw)


def _stress_observable(model, spec, lay, kind, where) -> StressObservable:
    name = lay.link.name
    if lay.shapes is None:
        raise ArgumentError(f"observable {spec!r}: stress needs an elastic link; {name!r} is rigid")
    fraction = fraction_of(spec, where)
    link = lay.link
    moment = _link_observable(model, f"{name}.moment@{fraction!r}", lay, "moment", repr(fraction))
    strain = None
    quadrature = lay.shapes.quadrature[0]
    if np.any(lay.shapes.evaluate(quadrature).du):   # the link has axial coordinates
        strain = _link_observable(model, f"{name}.strain@{fraction!r}", lay, "strain",
                                  repr(fraction))
    return StressObservable(spec, "Pa", kind, name, fraction * link.length,
                            _STRESS_KINDS[kind] * link.fibre_distance, link.area,
                            link.second_moment, link.youngs_modulus * link.area, moment, strain)


# the built-in quantities of a link, in the one registry (``_quantities``) that user ones join
for _kind in _KINDS:
    add_quantity(_kind, _link_observable, position=_kind == "angle")   # the frame angle is a position
for _kind in (*_POINT_KINDS, "point_error"):
    add_quantity(_kind, _point_observable, position=True)
for _kind in _STRESS_KINDS:
    add_quantity(_kind, _stress_observable)


def _joint_observable(model, spec, joint_name, kind):
    """``joint.J.<component>``: a weighted sum of joint J's multipliers, the weights its force map
    (``force_components()`` of the joint's class); ``force`` the magnitude of ``fx`` and ``fy``."""
    try:
        rows = model.joint_rows(joint_name)
    except ArgumentError as error:
        raise ArgumentError(f"observable {spec!r}: {error}") from None
    joint = model.mechanism.joint(joint_name)
    components = dict(joint.force_components())
    known = list(components) + (["force"] if {"fx", "fy"} <= set(components) else [])
    if kind not in known:
        raise ArgumentError(f"observable {spec!r}: unknown quantity {kind!r} of joint "
                            f"{joint_name!r} (a {joint.TYPE} joint); expected one of {known}")
    if kind == "force" and kind not in components:
        return PairMagnitude(spec, joint.force_unit, kind, tuple(
            _joint_observable(model, f"joint.{joint_name}.{axis}", joint_name, axis)
            for axis in ("fx", "fy")))
    weights_on_rows = tuple(float(w) for w in components[kind])
    if len(weights_on_rows) != len(rows.rows):
        raise ArgumentError(f"observable {spec!r}: the force map of joint {joint_name!r} gives "
                            f"{len(weights_on_rows)} weights for its {len(rows.rows)} rows")
    weights = np.zeros(model.n_constraints)
    weights[list(rows.rows)] = weights_on_rows
    return MultiplierObservable(spec, joint.force_unit, kind, weights)


def _drive_observable(model, spec, joint_name, kind):
    if kind != "torque":
        raise ArgumentError(f"observable {spec!r}: unknown drive quantity {kind!r}; expected "
                            f"'torque'")
    drives = [info for info in model._drives if info.drive.joint == joint_name]
    if not drives:
        raise ArgumentError(f"observable {spec!r}: no drive at joint {joint_name!r}; drives act "
                            f"at {[info.drive.joint for info in model._drives]}")
    info = drives[0]
    if info.row >= 0:
        weights = np.zeros(model.n_constraints)
        weights[info.row] = -1.0          # Model.drive_torques: the torque is -lam of the row
        return MultiplierObservable(spec, "N m", kind, weights)
    return TorqueLawObservable(spec, "N m", kind, model._drives.index(info), info.gradient,
                               joint_name)
