"""Derivatives of a linearisation's coefficients with respect to a scene parameter, for
``periodic.response_derivative``: differences of the coefficients of linearisations at nearby
parameter values (not of whole steady states), on the same phase grid ``t_k / T = k / N``.

Two linearisations differ by the parameter's effect on the mass, damping, stiffness, forcing and
period, and, where the parameter moves the kinematics (a link length, a joint position), by the
nominal motion's change: a central difference takes both.  Where the nominal configuration is the
same at both values (section properties, densities, damping, gains: the kinematics do not move), the
coefficients are smooth closed-form functions of the parameter evaluated on the same nominal motion and
one forward difference of step ``FORWARD_STEP`` is accurate to about that step (measured: 2e-9 of the
derivative for the coupler's thickness of the thesis four-bar); a parameter that moves the kinematics
carries the nominal motion's Newton tolerance into the difference (3e-5 of the derivative at that step
for the crank's length), so it takes a central difference of step ``CENTRAL_STEP`` (2e-9 truncation,
the residual's 1e-12 over the step).

Where a part carries its own derivative the coefficients need no second linearisation at all
(``analytic_derivative``): a link's damping (``links.<link>.damping.<key>``, the damping kind's
``matrix_derivative``) changes only the damping ``D`` of the link's elastic coordinates, by ``dD``, and
with the nominal motion and the basis ``V`` unchanged the projection of ``linearize._core`` gives

    dM = 0,   dC = V^T dD V,   dK = V^T dD V',   df = 0,   d ln T = 0;

the elastic coordinates are independent ones, so ``dD V`` has no dependent rows and the multipliers'
maps (joint forces, drive torques) do not change either: an observable's derivative is its map applied
to the response's derivative.
"""

from __future__ import annotations

import numpy as np

import periodic

__all__ = ["CENTRAL_STEP", "FORWARD_STEP", "analytic_derivative", "coefficient_derivative", "keeps_configuration",
           "parameter_step"]

#: Relative step of a forward difference (parameters that leave the kinematics alone).
FORWARD_STEP = 1e-6
#: Relative step of a central difference (parameters that move the kinematics, and the speed).
CENTRAL_STEP = 1e-4


def parameter_step(value: float, relative: float) -> float:
    """The absolute step for a parameter of nominal ``value``: ``relative * |value|`` (``relative`` for a
    parameter whose nominal value is 0, in its SI unit)."""
    return relative * abs(value) if value != 0.0 else relative


def keeps_configuration(mechanism, nominal, *, n_samples: int = 4) -> bool:
    """Whether the nominal motion ``nominal`` (of a nearby mechanism) still meets ``mechanism``'s
    constraints, at ``n_samples`` samples over the period, to ten times its own residual (and 1e-11): the
    kinematics have not moved, without computing ``mechanism``'s nominal motion (a parameter change that
    moves a pin by 1e-6 of a link's length leaves a residual of that size)."""
    import mechanisms

    model = mechanisms.assemble(mechanism)
    if model.n_coords != nominal.s.shape[1]:
        return False
    tol = 10.0 * float(nominal.constraint_residual) + 1e-11
    picks = np.linspace(0, len(nominal.t) - 1, n_samples, endpoint=False).astype(int)
    return all(float(np.abs(model.constraints(nominal.s[k], nominal.t[k])).max(initial=0.0)) <= tol for k in picks)


def coefficient_derivative(plus: periodic.PeriodicSystem, minus: periodic.PeriodicSystem,
                           step: float) -> periodic.SystemDerivative:
    """``periodic.SystemDerivative`` of the systems at ``p + step`` (``plus``) and ``p - step``
    (``minus``, central, divided by ``2 step``) or, with ``minus`` at ``p`` itself and a forward
    difference, by ``step``: pass the divisor as ``step`` (``2 h`` or ``h``).  Both systems must share
    their phase grid (the same N); ``log_period`` is ``ln(T+ / T-) / step``."""
    if plus.M.shape != minus.M.shape:
        raise periodic.PeriodicError(f"plus, minus: expected systems on the same grid, got {plus!r} and {minus!r}")

    def difference(name):
        change = (getattr(plus, name) - getattr(minus, name)) / step
        return None if not np.any(change) else change

    return periodic.SystemDerivative(M=difference("M"), C=difference("C"), K=difference("K"),
                                     f=difference("f"), log_period=float(np.log(plus.period / minus.period) / step))


def analytic_derivative(linearized, path: str) -> periodic.SystemDerivative | None:
    """The coefficients' derivative of the ``linearize.LinearizedMechanism`` ``linearized`` with respect
    to the scene parameter ``path`` in closed form, or None where no part carries it (the caller then
    differences linearisations): ``links.<link>.damping.<key>`` through the link's damping kind's
    ``matrix_derivative(key, link, M_ee, K_ee)`` (module docstring)."""
    parts = path.split(".")
    mechanism = getattr(linearized, "mechanism", None)
    if len(parts) != 4 or parts[0] != "links" or parts[2] != "damping" or mechanism is None:
        return None
    link = next((item for item in mechanism.links if item.name == parts[1]), None)
    layout = linearized.nominal.model.layouts.get(parts[1]) if link is not None else None
    if layout is None or layout.shapes is None or getattr(link, "damping", None) is None:
        return None
    import mechanisms

    m_ee, k_ee = mechanisms.beam_matrices(layout.shapes)
    block = link.damping.matrix_derivative(parts[3], link, m_ee, k_ee)
    if block is None:
        return None
    c = linearized.coefficients
    basis, rate = c.V[:, layout.elastic, :], c.Vdot[:, layout.elastic, :]   # (N+1, n_e, m)
    projected = np.swapaxes(basis, 1, 2) @ np.asarray(block, dtype=float)   # V^T dD on the link's rows
    return periodic.SystemDerivative(C=projected @ basis, K=projected @ rate, log_period=0.0)
