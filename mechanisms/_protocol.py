"""The contract between an assembled mechanism and everything that uses it.

``mechanisms.assemble(mechanism)`` returns a ``Model`` that satisfies this protocol. The nonlinear
integrator (``mechanisms.simulate``), the nominal motion (``mechanisms.nominal_motion``) and
``linearize.linear_coefficients`` only ever talk to a model through these methods (and the batched
evaluations below), so a hand-written model (a pendulum in redundant coordinates, say) works with
them too. ``linearize.about`` and its geometric stiffness need an assembled ``Model``.

Equations of motion (Lagrange with multipliers, seed eq. 2.10), n coordinates ``s``, r constraints:

    M(s) s'' = Q(s, s', t) - Phi_s(s, t)^T lam          (n equations)
    Phi(s, t) = 0                                         (r equations)

so that ``Q`` collects everything but the inertia of ``s''`` and the constraint forces: applied forces
and torques, gravity, minus the quadratic-velocity (Coriolis, centrifugal) terms, minus the elastic
forces dPi/ds, minus the damping forces. Differentiating the constraints twice,

    Phi_s s'' = gamma(s, s', t) = -(Phi_s s')_s s' - 2 Phi_st s' - Phi_tt.

Shapes: ``s, sdot, sddot`` (n,), ``lam`` (r,), matrices (n, n) or (r, n). Units SI.

Batched evaluations along a sampled motion (times ``t`` (N,), ``s, sdot, sddot`` (N, n), ``lam``
(N, r)): ``mechanisms.linear_terms_along(model, t, s, sdot, sddot, lam)`` (``LinearTerms``: M,
``-dQ/ds'``, the stiffness ``d(M s'')/ds - dQ/ds + d(Phi_s^T lam)/ds``, the residual
``M s'' - Q + Phi_s^T lam`` and Phi_s), ``mechanisms.inertia_residual_along(model, t, s, sdot,
sddot)`` (``M s'' - Q``) and ``mechanisms.constraint_terms_along(model, t, s, sdot=None, *,
values=False)`` (``ConstraintTerms``: Phi_s, Phi_t, gamma, Phi). A model that has methods of these
names (``Model`` does: one numba call each) is evaluated by them; any other through the per-sample
methods of this protocol, with the same results.

``mechanisms.Model`` (the assembler's implementation) adds, beyond this protocol: ``mechanism``,
``period`` (s), ``layouts`` (link name -> ``LinkLayout`` with ``coords``/``elastic`` slices and
``shapes``), ``drive_rows`` (constraint rows of prescribed drives), ``joint_rows(name)`` (a
``JointRows``: the joint's constraint rows, its kind ``"revolute"`` or ``"slider"`` and where it
attaches to its links), ``link_coordinates(name)``, ``observable(spec)``, ``drive_torques(s, sdot,
t, lam=None)`` (N m per drive; a prescribed drive's torque is ``-lam[row]``), ``drive_power(s,
sdot, t, lam=None)`` (W) and ``damping_power(sdot, s=None)`` (W; ``s`` needed when a stiffened link
has Kelvin-Voigt damping), so that ``d(T + V)/dt = drive_power - damping_power`` can be checked
along a solution.

Reading the multipliers of ``mechanisms.Model`` (the generalized constraint force is
``-Phi_s^T lam``): a revolute joint's rows ``"J.x", "J.y"`` (``Phi = r_a - r_b``) are the force that
``link_a`` exerts on ``link_b`` at the pin (N, global axes); a slider's row ``"S.n"``
(``Phi = n . (r - origin)``) gives the force ``-lam n`` of the guide on the link; a prescribed drive's
row ``"drive:J"`` is minus the torque the drive applies to ``link_b`` (N m). Find a joint's rows with
``model.joint_rows(name).rows``, not by parsing the labels.
"""

from __future__ import annotations

from typing import Protocol, Sequence

import numpy as np


class ConstrainedModel(Protocol):
    n_coords: int
    n_constraints: int
    coord_labels: Sequence[str]        # e.g. "crank.x", "coupler.theta", "coupler.q3"
    constraint_labels: Sequence[str]   # e.g. "O.x", "A.y", "drive:O"
    rigid_index: np.ndarray            # int (n_rigid,): indices of the frame coordinates x, y, theta
    elastic_index: np.ndarray          # int (n_elastic,): indices of the elastic coordinates

    # --- equations of motion -----------------------------------------------------------------------
    def mass_matrix(self, s: np.ndarray) -> np.ndarray: ...                       # (n, n)
    def forces(self, s: np.ndarray, sdot: np.ndarray, t: float) -> np.ndarray: ...  # Q, (n,)
    def constraints(self, s: np.ndarray, t: float) -> np.ndarray: ...            # Phi, (r,)
    def constraint_jacobian(self, s: np.ndarray, t: float) -> np.ndarray: ...    # Phi_s, (r, n)
    def constraint_rate(self, s: np.ndarray, t: float) -> np.ndarray: ...        # Phi_t, (r,)
    def constraint_gamma(self, s: np.ndarray, sdot: np.ndarray, t: float) -> np.ndarray: ...  # (r,)

    # --- analytic derivatives (for implicit integrators and for linearize) ---------------------------
    def mass_matrix_jacobian(self, s: np.ndarray, sddot: np.ndarray) -> np.ndarray: ...
    """d(M(s) sddot)/ds with sddot held fixed, (n, n)."""
    def force_jacobians(self, s: np.ndarray, sdot: np.ndarray, t: float
                        ) -> tuple[np.ndarray, np.ndarray]: ...
    """(dQ/ds, dQ/dsdot), each (n, n)."""
    def constraint_force_jacobian(self, s: np.ndarray, lam: np.ndarray, t: float) -> np.ndarray: ...
    """d(Phi_s(s, t)^T lam)/ds with lam held fixed, (n, n)."""

    # --- energies (for tests and diagnostics) ------------------------------------------------------
    def kinetic_energy(self, s: np.ndarray, sdot: np.ndarray) -> float: ...
    def potential_energy(self, s: np.ndarray) -> float: ...   # strain + gravity, J


class Observable(Protocol):
    """A scalar quantity of the mechanism that users ask about, with its gradient for linear maps.

    Made by ``model.observable(spec)``; specs are strings such as ``"coupler.deflection@0.5"``
    (transverse deflection relative to the chord at half the length, m), ``"arm.transverse@1.0"``
    (transverse displacement in the link frame, m), ``"coupler.strain@0.5"`` (membrane strain, 1),
    ``"coupler.moment@0.5"`` (bending moment, N m) and ``"rocker.angle"`` (frame angle, rad); see
    ``mechanisms._observables``. ``mechanisms.default_observables(mechanism)`` names the ones
    reported when none are asked for. Joint reactions are not observables of ``s``: they are the
    multipliers of the joint's rows (``model.joint_rows``).
    """

    spec: str
    unit: str
    def value(self, s: np.ndarray) -> float: ...
    def gradient(self, s: np.ndarray) -> np.ndarray: ...  # d value / ds, (n,)
