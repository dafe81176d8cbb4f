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
names (``Model`` does: one kernel call per quantity, numpy summing the terms) is evaluated by them;
any other through the per-sample methods of this protocol, with the same results.

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

from typing import Any, Callable, Protocol, Sequence

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
    """A scalar quantity of the mechanism that users ask about, and how it is evaluated.

    Made by ``model.observable(spec)``; specs are strings such as ``"coupler.deflection@0.5"``
    (transverse deflection relative to the chord at half the length, m), ``"arm.transverse@1.0"``
    (transverse displacement in the link frame, m), ``"coupler.strain@0.5"`` (membrane strain, 1),
    ``"coupler.moment@0.5"`` (bending moment, N m), ``"rocker.angle"`` (frame angle, rad), joint
    forces, drive torques and stresses; see ``mechanisms._observables``, and
    ``mechanisms.register_observable`` for a new quantity of a link.
    ``mechanisms.default_observables(mechanism)`` names the ones reported when none are asked for.

    An observable carries its evaluation route (no caller asks for its class):

    * ``of_coordinates``: True when ``value(s)`` and ``gradient(s)`` are the whole quantity
      (``mechanisms.simulate`` evaluates it, a controller may feed it back); False for joint forces,
      drive torques, magnitudes and the stress of an axially rigid link (``value`` raises).
    * ``needs_multipliers``: whether its linear map reads the multipliers' change (``linearize``
      then computes the multiplier maps).
    * ``depends_on_elastic_only`` (optional, default False): value and gradient read only the
      elastic coordinates, so the gradient is the same at every sample of a rigid nominal motion.
    * ``linear_map(route)``: its linear map about the nominal motion, built from the primitives of
      ``route`` (a ``LinearRoute``, which ``linearize`` passes in); returns what the route returns
      (a ``linearize.ObservableMap``).
    * ``along_run(run, linear_map)``: its values (K,) along a full nonlinear run as the linear route
      reports them, from the primitives of ``run`` (a ``RunRoute``, which ``studies`` passes in) and
      its own ``linear_map`` (the object ``linear_map(route)`` returned).
    """

    spec: str
    unit: str
    of_coordinates: bool
    needs_multipliers: bool
    def value(self, s: np.ndarray) -> float: ...
    def gradient(self, s: np.ndarray) -> np.ndarray: ...  # d value / ds, (n,)
    def linear_map(self, route: "LinearRoute") -> Any: ...
    def along_run(self, run: "RunRoute", linear_map: Any) -> np.ndarray: ...


class LinearRoute(Protocol):
    """What ``linearize`` hands an observable's ``linear_map``: maps along the nominal motion on the
    grid of N+1 samples, each a ``linearize.ObservableMap`` (``nominal`` part plus gains on the
    independent coordinates z, z', z''). Duck-typed: ``mechanisms`` imports no ``linearize``."""

    def coordinates(self, observable: Observable, nominal: np.ndarray | None = None) -> Any:
        """A function of ``s``: the change ``gradient(s0) . V z`` (a deviation); with ``nominal``
        (N+1,) a part that is not a function of ``s``, the map is then the total."""
    def multipliers(self, weights: np.ndarray, unit: str) -> Any:
        """``weights . lam`` (weights (r,)): the nominal multipliers plus their linear change."""
    def torque_law(self, drive_index: int, joint: str, unit: str) -> Any:
        """The torque law of the torque drive ``mechanism.drives[drive_index]`` at ``joint``."""
    def magnitude(self, unit: str, components: tuple) -> Any:
        """``hypot`` of two maps (the components' ``linear_map``) along the response."""
    def axial_force(self, link: str, x: float) -> np.ndarray:
        """The nominal axial force (N+1,) N of the rigid inverse dynamics in ``link`` at abscissa
        ``x`` (m); NaN where it is unknown (a joint that is not a point force)."""


class RunRoute(Protocol):
    """What ``studies`` hands an observable's ``along_run``: a full nonlinear run of K samples (from
    a whole period's start, on the linear grid or every stride-th sample of it). Duck-typed."""

    def coordinates(self, observable: Observable, linear_map: Any,
                    value: Callable[[np.ndarray], float] | None = None) -> np.ndarray:
        """``value`` (default ``observable.value``) along the run less its values along the
        nominal motion (angles, unit ``"rad"``, modulo 2 pi), plus ``linear_map.nominal`` when it
        has one: (K,)."""
    def multipliers(self, weights: np.ndarray) -> np.ndarray:
        """``lam @ weights`` along the run, (K,)."""
    def drive_torque(self, drive_index: int) -> np.ndarray:
        """The torque the run's drive ``drive_index`` applied (feedforward plus feedback within its
        limits, plus lagged controllers' states), (K,) N m."""
