"""Maps from the independent coordinates ``z`` of a linearised mechanism to its observables.

Each observable builds its map from the primitives of ``_Route`` (its ``linear_map``; the protocol is
``mechanisms`` ``LinearRoute``). An observable of the coordinates changes by
``g(s0) . x`` with ``x = V z``: its *deviation* from the nominal value (zero for the elastic
quantities; for a point's position, the point's displacement from its rigid nominal position). The
force-like observables are reported as *totals*, nominal plus linearised change:

* a joint force or a prescribed drive's torque, ``w . lam`` (``MultiplierObservable``):
  ``w . lam0 + w . (A_x z + A_v z' + A_a z'')`` with the multiplier maps of ``linearize._core``;
* a torque drive's torque: the nominal (inverse-dynamics) torque plus ``dtau/ds x + dtau/ds' x'``
  (``Model.drive_torque_terms``: PD gains, motor back EMF, controller feedback);
* the fibre stress ``N / A -+ M c / I``: the bending part is elastic (``M = EI w''``, zero along the
  rigid nominal motion); ``N`` is ``EA eps`` (the axial coordinates' response, which carries the
  axial load of the rigid motion: the total) or, for a link without axial coordinates, the nominal
  axial force of the rigid inverse dynamics (``linearize._geometric``) with no elastic change;
* a magnitude (``joint.J.force``, ``link.point_error@p``): ``hypot`` of its two components' values
  along the response (nonlinear in ``z``; each component is linear).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._core import spectral_derivatives
from ._geometric import axial_forces

__all__ = ["ObservableMap", "observable_maps"]


@dataclass(frozen=True)
class ObservableMap:
    """An observable on the grid of N+1 samples: ``o = nominal + position z + rate z' +
    acceleration z''`` (``nominal`` (N+1,) or None for a deviation; ``position``, ``rate``,
    ``acceleration`` (N+1, m) or None where zero), or, with ``components`` (two maps), the
    magnitude ``hypot`` of their values. ``unit`` its SI unit; ``total`` True when ``o`` is the
    total value (nominal plus change), False when it is the deviation from the nominal value."""

    unit: str
    nominal: np.ndarray | None = None
    position: np.ndarray | None = None
    rate: np.ndarray | None = None
    acceleration: np.ndarray | None = None
    components: tuple = ()

    @property
    def total(self) -> bool:
        return (self.nominal is not None) or any(c.total for c in self.components)

    @property
    def needs_derivatives(self) -> bool:
        """Whether ``z'`` or ``z''`` enter."""
        return (self.rate is not None or self.acceleration is not None
                or any(c.needs_derivatives for c in self.components))

    def evaluate(self, z: np.ndarray, zdot: np.ndarray | None = None,
                 zddot: np.ndarray | None = None, *, stride: int = 1) -> np.ndarray:
        """The observable (N/stride + 1,) along ``z``, ``zdot``, ``zddot`` (N/stride + 1, m)
        sampled every ``stride`` samples of the grid."""
        if self.components:
            a, b = (c.evaluate(z, zdot, zddot, stride=stride) for c in self.components)
            return np.hypot(a, b)
        out = np.zeros(z.shape[0])
        for gains, values in ((self.position, z), (self.rate, zdot), (self.acceleration, zddot)):
            if gains is not None:
                out += np.einsum("ki,ki->k", gains[::stride], values)
        if self.nominal is not None:
            out += self.nominal[::stride]
        return out

    def arrays(self) -> dict[str, np.ndarray]:
        """The non-None arrays by field name (components' arrays as ``"<k>.<field>"``)."""
        named = {name: getattr(self, name) for name in ("nominal", "position", "rate",
                                                        "acceleration")
                 if getattr(self, name) is not None}
        for k, component in enumerate(self.components):
            named.update({f"{k}.{name}": array for name, array in component.arrays().items()})
        return named

    def with_arrays(self, arrays: dict[str, np.ndarray]) -> "ObservableMap":
        """The same map with the arrays of ``arrays()`` replaced."""
        own = {name: arrays[name] for name in ("nominal", "position", "rate", "acceleration")
               if name in arrays}
        components = tuple(
            component.with_arrays({key.split(".", 1)[1]: value for key, value in arrays.items()
                                   if key.startswith(f"{k}.")})
            for k, component in enumerate(self.components))
        return ObservableMap(self.unit, **{**{name: getattr(self, name) for name in
                                              ("nominal", "position", "rate", "acceleration")},
                                           **own}, components=components)


def evaluate_maps(maps: dict[str, ObservableMap], z: np.ndarray, period: float, *,
                  zdot: np.ndarray | None = None, zddot: np.ndarray | None = None,
                  stride: int = 1) -> dict[str, np.ndarray]:
    """Every map along ``z`` (samples, m); ``zdot``, ``zddot`` default to the spectral derivatives
    of ``z`` as a periodic history over ``period`` (s) (a steady state)."""
    if (zdot is None or zddot is None) and any(m.needs_derivatives for m in maps.values()):
        d1, d2, _ = spectral_derivatives(z, period)
        zdot = d1 if zdot is None else zdot
        zddot = d2 if zddot is None else zddot
    return {spec: m.evaluate(z, zdot, zddot, stride=stride) for spec, m in maps.items()}


def torque_law_map(model, joint, t, s, sdot, coefficients, *, saturate=True):
    """The torque law of the torque drive at ``joint`` along the nominal motion ``t, s, sdot`` and
    its linear change in ``z``: ``(tau (N+1,), position (N+1, m), rate (N+1, m))`` with
    ``tau + position . z + rate . z'`` the torque (``saturate=False``: the demanded torque of the
    unsaturated law), from ``x = V z``, ``x' = V z' + V' z``."""
    tau, dtau_ds, dtau_dv = model.drive_torque_terms(joint, t, s, sdot, saturate=saturate)
    position = (np.einsum("kn,kni->ki", dtau_ds, coefficients.V)
                + np.einsum("kn,kni->ki", dtau_dv, coefficients.Vdot))
    # the lagged controllers at this joint add their states, the last entries of z (linearize._lag)
    lag_joints = getattr(model, "lag_joints", ())
    first_lag = position.shape[1] - len(lag_joints)
    for i, lag_at in enumerate(lag_joints):
        if lag_at == joint:
            position[:, first_lag + i] += 1.0
    return tau, position, np.einsum("kn,kni->ki", dtau_dv, coefficients.V)


def needs_multiplier_maps(model, specs) -> bool:
    """Whether any spec's linear map reads the multipliers' change (its observable declares
    ``needs_multipliers``): only those need ``linear_coefficients(..., multipliers=True)``."""
    return any(model.observable(spec).needs_multipliers for spec in specs)


def observable_maps(model, specs, *, t, s, sdot, sddot, lam, coefficients, drive_torque
                    ) -> dict[str, ObservableMap]:
    """The ``ObservableMap`` of each spec of ``model.observable`` along the nominal motion ``s,
    sdot, sddot`` (N+1, n) at times ``t`` (N+1,), with the model's multipliers ``lam`` (N+1, r),
    the nominal drive torques ``drive_torque`` (N+1, n_drives) and the ``LinearCoefficients``
    ``coefficients`` (basis ``V``, ``Vdot``, multiplier maps). Each observable builds its own map
    from the primitives of ``_Route`` (``mechanisms`` ``LinearRoute``)."""
    route = _Route(model, t, s, sdot, sddot, lam, coefficients, drive_torque)
    return {spec: model.observable(spec).linear_map(route) for spec in specs}


class _Route:
    """The ``LinearRoute`` an observable's ``linear_map`` reads (``mechanisms/_protocol.py``):
    the pieces of linear maps along one nominal motion."""

    def __init__(self, model, t, s, sdot, sddot, lam, coefficients, drive_torque):
        self.model, self.t, self.s, self.sdot, self.sddot, self.lam = model, t, s, sdot, sddot, lam
        self.c = coefficients
        self.drive_torque = drive_torque
        self.rigid_nominal = not np.any(s[:, np.asarray(model.elastic_index, dtype=np.int64)])

    def coordinates(self, observable, nominal=None) -> ObservableMap:
        """A function of ``s``: its change ``g(s0) . V z``; with ``nominal`` (N+1,) a part that is
        not a function of ``s`` (the map is then the total)."""
        return ObservableMap(observable.unit, nominal=nominal, position=self._gradient_map(observable))

    def multipliers(self, weights, unit) -> ObservableMap:
        """``weights . lam`` (weights (r,)): nominal plus the multipliers' linear change."""
        a_x, a_v, a_a = self.c.multiplier_maps
        return ObservableMap(unit, nominal=self.lam @ weights,
                             position=np.einsum("r,kri->ki", weights, a_x),
                             rate=np.einsum("r,kri->ki", weights, a_v),
                             acceleration=np.einsum("r,kri->ki", weights, a_a))

    def torque_law(self, drive_index, joint, unit) -> ObservableMap:
        """The torque law of the torque drive ``drive_index`` (at ``joint``): its change
        dtau/ds x + dtau/ds' x', x = V z, x' = V z' + V' z (the law's derivatives along the
        nominal motion: gains, motor back EMF, controller feedback)."""
        law, position, rate = torque_law_map(self.model, joint, self.t, self.s, self.sdot, self.c)
        # on the nominal motion the feedback vanishes: the torque is the feedforward, the
        # inverse-dynamics torque, or the law's own value (zero) when it is switched off
        feedforward = self.model.mechanism.drives[drive_index].feedforward
        nominal = self.drive_torque[:, drive_index].copy() if feedforward else law
        return ObservableMap(unit, nominal=nominal, position=position, rate=rate)

    def magnitude(self, unit, components) -> ObservableMap:
        """``hypot`` of the two maps ``components`` along the response."""
        return ObservableMap(unit, components=tuple(components))

    def axial_force(self, link, x) -> np.ndarray:
        """The nominal axial force (N+1,) N of the rigid inverse dynamics in ``link`` at abscissa
        ``x`` (m); NaN where the link is loaded by a joint that is not a point force."""
        axial = axial_forces(self.model, self.t, self.s, self.sdot, self.sddot, self.lam,
                             {link: np.array([x])})[link]
        return np.full(len(self.t), np.nan) if axial is None else axial[:, 0]

    def _gradient_map(self, observable) -> np.ndarray:
        """``g(s0(t)) . V(t)`` (N+1, m). An observable of the elastic coordinates alone has the same
        gradient at every sample of a rigid nominal motion (its elastic coordinates are zero)."""
        if self.rigid_nominal and getattr(observable, "depends_on_elastic_only", False):
            gradients = np.broadcast_to(observable.gradient(self.s[0]), self.s.shape)
        else:
            gradients = np.stack([observable.gradient(sk) for sk in self.s])
        return np.einsum("kn,kni->ki", gradients, self.c.V)


class _ChangeRoute:
    """The ``LinearRoute`` (``mechanisms/_protocol.py``) of a map's derivative with respect to a parameter
    that leaves the nominal motion and the multipliers' maps alone (``linearize.map_derivatives``):
    ``torque`` (joint, position, rate) the torque law's change at that joint per unit p, ``coordinates``
    (the routes at p + step and at p, step) where the observables' gradients change (their difference over
    the step: exact where the gradients are linear in p), ``axial(link, x)`` (N+1,) what an axially rigid
    link's nominal axial force contributes to the change (divided by the observable's area, as the
    observable divides the force; None: nothing, the nominal part does not move)."""

    def __init__(self, n_samples, *, torque=None, coordinates=None, axial=None):
        self.n_samples, self.torque, self.pair, self.axial = n_samples, torque, coordinates, axial

    def coordinates(self, observable, nominal=None) -> ObservableMap:
        nominal = nominal if self.axial is not None else None
        if self.pair is None:
            return ObservableMap(observable.unit, nominal=nominal)
        plus, point, step = self.pair
        change = (plus._gradient_map(observable) - point._gradient_map(point.model.observable(observable.spec))) / step
        return ObservableMap(observable.unit, nominal=nominal, position=change)

    def multipliers(self, weights, unit) -> ObservableMap:
        return ObservableMap(unit)

    def torque_law(self, drive_index, joint, unit) -> ObservableMap:
        if self.torque is None or self.torque[0] != joint:
            return ObservableMap(unit)
        return ObservableMap(unit, position=self.torque[1], rate=self.torque[2])

    def magnitude(self, unit, components) -> ObservableMap:
        return ObservableMap(unit, components=tuple(components))

    def axial_force(self, link, x) -> np.ndarray:
        return np.zeros(self.n_samples) if self.axial is None else self.axial(link, x)
