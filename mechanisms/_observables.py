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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._parts import ArgumentError, ElasticLink

_KINDS = {"deflection": "m", "transverse": "m", "strain": "1", "moment": "N m", "angle": "rad"}


@dataclass(frozen=True)
class LinkObservable:
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


def make_observable(model, spec: str) -> LinkObservable:
    """Parse ``spec`` against ``model`` (a ``mechanisms.Model``)."""
    if not isinstance(spec, str):
        raise TypeError(f"spec must be a string such as 'coupler.deflection@0.5'; received "
                        f"{type(spec).__name__}")
    head, _, where = spec.partition("@")
    name, _, kind = head.rpartition(".")
    if name not in model.layouts:
        raise ArgumentError(f"observable {spec!r}: unknown link {name!r}; links are "
                         f"{list(model.layouts)}")
    if kind not in _KINDS:
        raise ArgumentError(f"observable {spec!r}: unknown quantity {kind!r}; expected one of "
                         f"{sorted(_KINDS)}")
    lay = model.layouts[name]
    common = dict(spec=spec, unit=_KINDS[kind], kind=kind, n_coords=model.n_coords,
                  coords=lay.coords, theta_index=lay.offset + 2, length=lay.link.length)
    if kind == "angle":
        if where:
            raise ArgumentError(f"observable {spec!r}: 'angle' takes no '@fraction'")
        return LinkObservable(**common, x=0.0, rows=(), flexural_rigidity=0.0, membrane=())
    if lay.shapes is None:
        raise ArgumentError(f"observable {spec!r}: {kind} needs an elastic link; {name!r} is rigid")
    try:
        fraction = float(where) if where else 0.5
    except ValueError:
        raise ArgumentError(f"observable {spec!r}: the part after '@' must be a fraction of the "
                         f"length in [0, 1]; received {where!r}") from None
    if not 0.0 <= fraction <= 1.0:
        raise ArgumentError(f"observable {spec!r}: fraction must be in [0, 1]; received {fraction}")
    x = fraction * lay.link.length
    v = lay.shapes.evaluate([x, lay.link.length])
    rows = (v.u[0], v.w[0], v.du[0], v.dw[0], v.ddw[0], v.u[1], v.w[1])
    membrane = ()
    if lay.stiffening:
        membrane = (v.du[0] @ lay.membrane, lay.shapes.evaluate(lay.shapes.quadrature[0]).dw)
    return LinkObservable(**common, x=x, rows=rows, membrane=membrane,
                          flexural_rigidity=lay.link.youngs_modulus * lay.link.second_moment)
