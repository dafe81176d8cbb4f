"""Derivatives of a linearisation's coefficients with respect to a scene parameter, for
``periodic.response_derivative``: differences of the coefficients of linearisations at nearby
parameter values (not of whole steady states), on the same phase grid ``t_k / T = k / N``.

Two linearisations differ by the parameter's effect on the mass, damping, stiffness, forcing and
period, and, where the parameter moves the kinematics (a link length, a joint position), by the
nominal motion's change: a central difference takes both.  Where the nominal configuration is the
same at both values (section properties, densities, damping, gains: the kinematics do not move) and
no exact route applies (below), the coefficients are smooth closed-form functions of the parameter
evaluated on the same nominal motion and one forward difference of step ``FORWARD_STEP`` is accurate to
about that step (measured: 5e-7 of the damping's derivative for the coupler's thickness of the thesis
four-bar, I = b h^3 / 12); a parameter that moves the kinematics
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
to the response's derivative.  A link's Young's modulus (``links.<link>.youngs_modulus``) is pure
stiffness: ``K_ee`` is ``E`` times the shapes' integrals and the geometric stiffness and the load are
the rigid inverse dynamics', so ``dK_ee = K_ee / E`` and ``dD_ee`` is the damping kind's
``modulus_derivative``, projected as above.  A controller's gain (``controllers.<name>.<key>``, and a
torque drive's own ``kp``, ``kd``: ``drive.<key>``, ``drives.<joint>.<key>``) enters
its law linearly: ``law_derivative(key)`` is the law per unit gain, ``du = dP . x + dD . x'`` with
``dP = -kp' h - gain' g`` (``h`` the driven angle's gradient, ``g`` the fed-back observable's), and

    no lag:  dK = -(V^T h) (dP V + dD V'),  dC = -(V^T h) (dD V)     (the torque u h in Q)
    a lag:   only the lag state's row, dK_row = -(dP V + dD V'), dC_row = -(dD V)   (linearize._lag)

with ``dM = df = 0`` (the law vanishes on the nominal motion, whose model drops the controllers); where
``h`` reaches a dependent coordinate the multipliers' maps would move too, and the closed form declines.
The observable maps these two move (stresses and moments for ``E``, drive torques for a gain) are
differentiated on the point's motion (``map_derivatives``: the torque law's change per unit gain, the
gradients' change for ``E``; the multipliers' and the nominal parts do not move).

An elastic link's section (``links.<link>.density``, ``width``, ``thickness``, ``area``,
``second_moment``) moves the mass, hence the multipliers, the geometric stiffness, the load and the
multipliers' maps: on the fixed kinematics of prescribed drives all of them are affine in the link's
``rho A``, and ``K_ee`` and the observables' gradients are linear in ``A``, ``I`` and the fibre distance
``c``; moved along the parameter's tangent (each of these linear in one offset ``t``, at the rates the
link's ``section_rates(key)`` gives) with its damping removed, the link's linearisation on the point's
kinematics differenced with the point's own (its damping's projection removed) is the derivative
exactly, to rounding, for the coefficients and the maps alike; the damping kind's ``section_derivative``
adds the damping's (``linearize._section``, whose docstring has the formulas and the cases that keep the
forward difference: a torque drive, a reduced link, rotary inertia under a key that moves ``rho I`` apart
from ``rho A``, modal damping).
"""

from __future__ import annotations

import numpy as np

import mechanisms
import periodic

from ._observe import _ChangeRoute, _Route  # the maps' primitives, for E's gradients
from ._section import section_derivative, section_map_derivatives, section_route

__all__ = ["CENTRAL_STEP", "FORWARD_STEP", "analytic_derivative", "map_derivatives", "coefficient_derivative",
           "keeps_configuration", "moves_maps", "parameter_step"]

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
    differences linearisations): a link's damping ``links.<link>.damping.<key>`` (its kind's
    ``matrix_derivative``), its Young's modulus ``links.<link>.youngs_modulus`` (``K_ee / E`` and the
    damping kind's ``modulus_derivative``), an elastic link's section ``links.<link>.density`` / ``width`` /
    ``thickness`` / ``area`` / ``second_moment`` on prescribed drives (exact by the coefficients' affinity in
    its mass: one linearisation on the point's kinematics, ``linearize._section``), a controller's gain
    ``controllers.<name>.<key>`` and a torque drive's own ``drive.kp`` / ``drives.<joint>.kd`` (their
    ``law_derivative``); module docstring.  The observables' maps of the last three move with the parameter
    too: ``map_derivatives``."""
    mechanism = getattr(linearized, "mechanism", None)
    if mechanism is None:
        return None
    parts = path.split(".")
    if parts[0] == "links" and len(parts) == 3 and parts[2] != "youngs_modulus":
        route = section_route(linearized, parts)
        return None if route is None else section_derivative(linearized, route)
    if parts[0] == "links" and len(parts) in (3, 4):
        return _link_derivative(linearized, mechanism, parts)
    if (parts[0] == "controllers" and len(parts) == 3) or _drive_of(mechanism, parts) is not None:
        return _gain_derivative(linearized, mechanism, _gain_owner(mechanism, parts), parts[-1])
    return None


def _drive_of(mechanism, parts):
    """The drive of a scene path ``drive.<key>`` (a scene's one ``[drive]`` table) or
    ``drives.<joint>.<key>``, else None."""
    if parts[0] == "drive" and len(parts) == 2 and len(mechanism.drives) == 1:
        return mechanism.drives[0]
    if parts[0] == "drives" and len(parts) == 3:
        return next((item for item in mechanism.drives if item.joint == parts[1]), None)
    return None


def _moved_specs(linearized, path: str) -> list[str]:
    """The observables whose maps the parameter ``path`` of ``analytic_derivative`` moves: for a
    Young's modulus every one (a stress or moment is ``E`` times a curvature or an axial strain, with no
    nominal part where the link has axial coordinates), for a controller's gain the totals (forces and
    torques: ``ObservableMap.total``; a deviation of the coordinates is the gain's through ``z`` alone),
    for a link's damping none."""
    parts = path.split(".")
    if parts[0] == "links" and len(parts) == 3 and parts[2] == "youngs_modulus":
        return list(linearized.observable_maps)
    if parts[0] == "links" and len(parts) == 3 and section_route(linearized, parts) is not None:
        return list(linearized.observable_maps)
    if (parts[0] == "controllers" and len(parts) == 3) or _drive_of(linearized.mechanism, parts) is not None:
        return [spec for spec, found in linearized.observable_maps.items() if found.total]
    return []


def moves_maps(linearized, path: str) -> bool:
    """Whether the parameter ``path`` of ``analytic_derivative`` moves some of ``linearized``'s
    observable maps (``map_derivatives``): a Young's modulus (stresses, moments) or a controller's gain
    where a force or torque is observed; a link's damping moves none."""
    return bool(_moved_specs(linearized, path))


def map_derivatives(linearized, path: str, mechanism=None, step: float = 0.0) -> dict:
    """d(map)/dp {spec: ``ObservableMap`` of derivatives, per unit of p} of ``linearized``'s observable
    maps that the parameter ``path`` of ``analytic_derivative`` moves (``moves_maps``); {} where none
    move.  A gain moves its drive's torque law only, by the law per unit gain along ``x = V z``; ``E``
    moves the gradients of the coordinates' observables (a stress or moment is ``E`` times a curvature
    or strain): their change to ``mechanism``, ``linearized``'s with ``E`` at ``p + step``, over ``step``.
    Neither moves the nominal motion, the multipliers' maps or the nominal axial forces
    (``analytic_derivative`` declines where a gain would reach the multipliers), and each map is affine in
    them, so ``point + h * derivative`` is the map at ``p + h`` exactly."""
    if not moves_maps(linearized, path):
        return {}
    nominal, c = linearized.nominal, linearized.coefficients
    parts = path.split(".")
    if parts[0] == "links" and parts[2] != "youngs_modulus":
        return section_map_derivatives(linearized, section_route(linearized, parts))
    if parts[0] == "links":
        def route(model):
            return _Route(model, nominal.t, nominal.s, nominal.sdot, nominal.sddot, None, c, None)

        model = mechanisms.assemble(mechanism)
        change = _ChangeRoute(len(nominal.t), coordinates=(route(model), route(mechanisms.assemble(
            linearized.mechanism)), step))
    else:
        law = _gain_law(linearized, linearized.mechanism, _gain_owner(linearized.mechanism, parts), parts[-1])
        model = mechanisms.assemble(linearized.mechanism)   # its torque drives' own observables
        change = _ChangeRoute(len(nominal.t), torque=None if law is None or law[3] else law[:3])
    return {spec: model.observable(spec).linear_map(change) for spec in _moved_specs(linearized, path)}


def _elastic_projection(linearized, layout, d_damping, d_stiffness) -> periodic.SystemDerivative:
    """``dC = V^T dD V``, ``dK = V^T (dD V' + dK V)`` of changes ``d_damping``, ``d_stiffness``
    (n_e, n_e or None) of one link's elastic block: independent coordinates, so ``V`` is a selection
    there and the multipliers' maps (dependent rows) do not move."""
    c = linearized.coefficients
    basis, rate = c.V[:, layout.elastic, :], c.Vdot[:, layout.elastic, :]   # (N+1, n_e, m)
    transposed = np.swapaxes(basis, 1, 2)
    damping = stiffness = None
    if d_damping is not None:
        projected = transposed @ np.asarray(d_damping, dtype=float)         # V^T dD on the link's rows
        damping, stiffness = projected @ basis, projected @ rate
    if d_stiffness is not None:
        block = transposed @ np.asarray(d_stiffness, dtype=float) @ basis
        stiffness = block if stiffness is None else stiffness + block
    return periodic.SystemDerivative(C=damping, K=stiffness, log_period=0.0)


def _link_derivative(linearized, mechanism, parts) -> periodic.SystemDerivative | None:
    """``links.<link>.damping.<key>`` and ``links.<link>.youngs_modulus`` of an elastic link."""
    link = next((item for item in mechanism.links if item.name == parts[1]), None)
    layout = linearized.nominal.model.layouts.get(parts[1]) if link is not None else None
    if layout is None or layout.shapes is None:
        return None
    m_ee, k_ee = mechanisms.beam_matrices(layout.shapes)
    damping = getattr(link, "damping", None)
    if len(parts) == 4:
        if parts[2] != "damping" or damping is None:
            return None
        block = damping.matrix_derivative(parts[3], link, m_ee, k_ee)
        return None if block is None else _elastic_projection(linearized, layout, block, None)
    if parts[2] != "youngs_modulus":
        return None
    # K_ee = E (A int Su'^T Su' + I int Sw''^T Sw'') (mechanisms.beam_matrices); the geometric stiffness
    # and the load are the rigid inverse dynamics', which E does not enter
    rule = getattr(damping, "modulus_derivative", None)
    if damping is not None and rule is None:
        return None
    block = None if damping is None else rule(link, m_ee, k_ee)
    return _elastic_projection(linearized, layout, block, k_ee / link.youngs_modulus)


def _gain_owner(mechanism, parts):
    """The controller of ``controllers.<name>.<key>`` or the drive of ``drive.<key>`` /
    ``drives.<joint>.<key>`` (None if there is none)."""
    if parts[0] == "controllers":
        return next((item for item in mechanism.controllers if item.name == parts[1]), None)
    return _drive_of(mechanism, parts)


def _gain_law(linearized, mechanism, owner, key):
    """``(joint, position, rate, lagged)`` of a gain ``key`` of ``owner`` (a controller, or a torque
    drive's own PD): its law's change per unit gain ``du = position . z + rate . z'`` (N+1, m) from its
    ``law_derivative(key)``, or None where it has none."""
    rule = getattr(owner, "law_derivative", None)
    law = None if rule is None else rule(key)
    if law is None:
        return None
    model = mechanisms.assemble(mechanism)
    h = model.drive_gradient(owner.joint)                          # (n,) the driven angle's gradient
    c = linearized.coefficients
    du_ds, du_dv = -law.kp * h, -law.kd * h                        # the law's dP, dD per unit gain
    if law.observable is not None:
        # an observable of the elastic coordinates alone: its gradient is the same at every sample of
        # the rigid nominal motion, and its Hessian meets only elastic rates (zero there)
        gradient = model.observable(law.observable).gradient(linearized.nominal.s[0])
        du_ds, du_dv = du_ds - law.gain * gradient, du_dv - law.rate_gain * gradient
    # du = position . z + rate . z' per unit gain, from x = V z, x' = V z' + V' z
    position = np.einsum("n,kni->ki", du_ds, c.V) + np.einsum("n,kni->ki", du_dv, c.Vdot)
    return owner.joint, position, np.einsum("n,kni->ki", du_dv, c.V), bool(getattr(owner, "lag", 0.0))


def _gain_derivative(linearized, mechanism, owner, key) -> periodic.SystemDerivative | None:
    """A gain ``key`` of ``owner`` (``_gain_law``) folded in as ``linearize._core`` and
    ``linearize._lag`` fold the law itself (module docstring)."""
    found = _gain_law(linearized, mechanism, owner, key)
    if found is None:
        return None
    joint, position, rate, lagged = found
    c = linearized.coefficients
    n_samples, m = position.shape
    damping, stiffness = np.zeros((n_samples, m, m)), np.zeros((n_samples, m, m))
    if lagged:
        lag = f"lag.{owner.name}"
        if lag not in linearized.labels:
            return None
        # the lag's own row [-du/ds, 1], [-du/ds', tau] (linearize._lag): only -du moves
        row = linearized.labels.index(lag)
        stiffness[:, row, :], damping[:, row, :] = -position, -rate
        return periodic.SystemDerivative(C=damping, K=stiffness, log_period=0.0)
    h = mechanisms.assemble(mechanism).drive_gradient(joint)
    dependent = np.setdiff1d(np.arange(h.size), c.independent)
    if np.any(h[dependent]):
        return None     # the torque would reach the dependent rows, hence the multipliers' maps
    # the torque u h in Q: K = -dQ/ds gains -h du/ds, D = -dQ/ds' gains -h du/ds'
    lever = np.einsum("n,kni->ki", h, c.V)                         # V^T h (N+1, m)
    stiffness, damping = -lever[:, :, None] * position[:, None, :], -lever[:, :, None] * rate[:, None, :]
    return periodic.SystemDerivative(C=damping, K=stiffness, log_period=0.0)
