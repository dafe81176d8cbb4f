"""Tests of mechanisms.simulate (generalized-alpha on the index-3 equations).

The models here are written by hand, independently of the assembler: planar bodies in redundant
coordinates (x, y, theta of each frame origin, plus an axial "elastic" coordinate u carrying a point
mass on a spring, which mimics a stiff axial mode), with pins to the ground and between bodies. Their
mass matrix, forces, constraints and all derivatives are derived symbolically with sympy (Lagrange's
equations for point masses and rotary inertias) and lambdified. References are solve_ivp solutions of
the same systems in minimal coordinates (angles), energies, and the drive's work.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg
import sympy as sp
from scipy.integrate import solve_ivp

import mechanisms
from mechanisms import SimulationError

G = 9.81


# ---------------------------------------------------------------------------------------------------
# Hand-written models (sympy)
# ---------------------------------------------------------------------------------------------------
class _Observable:
    def __init__(self, spec, index):
        self.spec, self.unit, self._index = spec, "rad", index

    def value(self, s):
        return float(s[self._index])

    def gradient(self, s):
        g = np.zeros(len(s))
        g[self._index] = 1.0
        return g


def _lagrange_terms(points, rotors, qv, qd):
    """Mass matrix ``sum m J^T J`` of point masses ``(m, r(q))`` and rotary inertias
    ``(J, angle(q))``, and the quadratic-velocity term ``sum m J^T (dJ/dt) qd`` of Lagrange's
    equations, ``M q'' + quad = generalized forces``."""
    n = len(qv)
    Mmat, quad = sp.zeros(n, n), sp.zeros(n, 1)
    for inertia, position in [(m, sp.Matrix(r)) for m, r in points] + [
            (J, sp.Matrix([angle])) for J, angle in rotors]:
        Jac = position.jacobian(qv)
        Mmat += inertia * Jac.T * Jac
        quad += inertia * Jac.T * ((Jac * qd).jacobian(qv) * qd)
    return Mmat, quad


class SympyModel:
    """A ConstrainedModel from point masses ``(m, r(q))``, rotary inertias ``(J, angle(q))``, a
    potential ``V(q)``, a constant damping matrix and constraints ``Phi(q, t)``."""

    def __init__(self, q, points, rotors, potential, constraints, labels, *, damping=None,
                 elastic=()):
        t = sp.Symbol("t")
        n = len(q)
        qd = sp.Matrix(sp.symbols(f"qd0:{n}"))
        acc = sp.Matrix(sp.symbols(f"acc0:{len(q)}"))
        qv = sp.Matrix(q)
        Mmat, quad = _lagrange_terms(points, rotors, qv, qd)
        C = sp.zeros(n, n) if damping is None else sp.Matrix(damping)
        Q = -quad - sp.Matrix([potential]).jacobian(qv).T - C * qd
        Phi = sp.Matrix(constraints)
        r_ = len(constraints)
        lam = sp.Matrix(sp.symbols(f"lam0:{r_}"))
        Phi_q = Phi.jacobian(qv)
        Phi_t = Phi.diff(t)
        gamma = -((Phi_q * qd).jacobian(qv) * qd) - 2 * Phi_t.jacobian(qv) * qd - Phi_t.diff(t)
        T = (qd.T * Mmat * qd)[0] / 2
        args = (list(q), list(qd), t)
        f = lambda expr, *a: sp.lambdify(a, expr, modules="numpy", cse=True)  # noqa: E731
        self._M = f(Mmat, list(q))
        self._Q = f(Q, *args)
        self._Phi = f(Phi, list(q), t)
        self._Phi_q = f(Phi_q, list(q), t)
        self._Phi_t = f(Phi_t, list(q), t)
        self._gamma = f(gamma, *args)
        self._dMa = f((Mmat * acc).jacobian(qv), list(q), list(acc))
        self._dQ = f(Q.jacobian(qv), *args)
        self._dQv = f(Q.jacobian(qd), *args)
        self._dPl = f((Phi_q.T * lam).jacobian(qv), list(q), list(lam), t)
        self._T = f(T, list(q), list(qd))
        self._V = f(potential, list(q))
        self.n_coords, self.n_constraints = n, r_
        self.coord_labels = [str(s) for s in q]
        self.constraint_labels = labels
        self.elastic_index = np.array(elastic, dtype=np.int64)
        self.rigid_index = np.array([i for i in range(n) if i not in elastic], dtype=np.int64)

    @staticmethod
    def _mat(x, shape):
        return np.array(np.broadcast_to(np.asarray(x, dtype=float), shape), dtype=float)

    def mass_matrix(self, s):
        return self._mat(self._M(s), (self.n_coords, self.n_coords))

    def forces(self, s, sdot, t):
        return self._mat(self._Q(s, sdot, t), (self.n_coords, 1)).ravel()

    def constraints(self, s, t):
        return self._mat(self._Phi(s, t), (self.n_constraints, 1)).ravel()

    def constraint_jacobian(self, s, t):
        return self._mat(self._Phi_q(s, t), (self.n_constraints, self.n_coords))

    def constraint_rate(self, s, t):
        return self._mat(self._Phi_t(s, t), (self.n_constraints, 1)).ravel()

    def constraint_gamma(self, s, sdot, t):
        return self._mat(self._gamma(s, sdot, t), (self.n_constraints, 1)).ravel()

    def mass_matrix_jacobian(self, s, sddot):
        return self._mat(self._dMa(s, sddot), (self.n_coords, self.n_coords))

    def force_jacobians(self, s, sdot, t):
        shape = (self.n_coords, self.n_coords)
        return self._mat(self._dQ(s, sdot, t), shape), self._mat(self._dQv(s, sdot, t), shape)

    def constraint_force_jacobian(self, s, lam, t):
        return self._mat(self._dPl(s, lam, t), (self.n_coords, self.n_coords))

    def kinetic_energy(self, s, sdot):
        return float(self._T(s, sdot))

    def potential_energy(self, s):
        return float(self._V(s))

    def observable(self, spec):
        name = spec.removesuffix(".angle")
        return _Observable(spec, self.coord_labels.index(name))


def _rot(theta, x, y):
    return sp.Matrix([x * sp.cos(theta) - y * sp.sin(theta), x * sp.sin(theta) + y * sp.cos(theta)])


# a uniform bar pendulum: mass 0.8 kg, length 0.4 m, frame origin at the pin
PEND = dict(m=0.8, L=0.4)


def pendulum_model():
    """One bar on a ground pin in redundant coordinates (x, y, theta), gravity -y."""
    x, y, th = sp.symbols("x y theta")
    m, L = PEND["m"], PEND["L"]
    rc = sp.Matrix([x, y]) + _rot(th, L / 2, 0)
    return SympyModel([x, y, th], [(m, rc)], [(m * L**2 / 12, th)], m * G * rc[1],
                      [x, y], ["O.x", "O.y"])


def pendulum_minimal_rhs(t, z):
    """theta'' = -m g (L/2) cos(theta) / (m L^2 / 3), written by hand."""
    m, L = PEND["m"], PEND["L"]
    return [z[1], -m * G * (L / 2) * math.cos(z[0]) / (m * L**2 / 3)]


# double pendulum with axial springs: bar i (mass m_i, length L_i) plus an end mass mp_i at
# (L_i + u_i, 0) in its frame
DBL = dict(m1=0.6, L1=0.3, mp1=0.2, m2=0.4, L2=0.25, mp2=0.1)


def double_pendulum_parts(q, k1, k2):
    """Point masses, rotors and potential of the spring double pendulum for coordinates
    ``q = (x1, y1, th1, u1, x2, y2, th2, u2)`` (redundant) ."""
    x1, y1, th1, u1, x2, y2, th2, u2 = q
    d = DBL
    o1, o2 = sp.Matrix([x1, y1]), sp.Matrix([x2, y2])
    c1 = o1 + _rot(th1, d["L1"] / 2, 0)
    e1 = o1 + _rot(th1, d["L1"] + u1, 0)
    c2 = o2 + _rot(th2, d["L2"] / 2, 0)
    e2 = o2 + _rot(th2, d["L2"] + u2, 0)
    points = [(d["m1"], c1), (d["mp1"], e1), (d["m2"], c2), (d["mp2"], e2)]
    rotors = [(d["m1"] * d["L1"] ** 2 / 12, th1), (d["m2"] * d["L2"] ** 2 / 12, th2)]
    V = G * (d["m1"] * c1[1] + d["mp1"] * e1[1] + d["m2"] * c2[1] + d["mp2"] * e2[1])
    V += k1 * u1**2 / 2 + k2 * u2**2 / 2
    return points, rotors, V, e1


def double_pendulum_model(k1, k2, *, drive=None, damping=None):
    """Redundant coordinates; pins O (ground, origin) and A (bar 1's end mass = bar 2's origin);
    ``drive(t)`` (a sympy expression in t) prescribes theta1."""
    q = sp.symbols("x1 y1 theta1 u1 x2 y2 theta2 u2")
    points, rotors, V, e1 = double_pendulum_parts(q, k1, k2)
    x1, y1, th1, u1, x2, y2, th2, u2 = q
    cons = [x1, y1, x2 - e1[0], y2 - e1[1]]
    labels = ["O.x", "O.y", "A.x", "A.y"]
    if drive is not None:
        cons.append(th1 - drive(sp.Symbol("t")))
        labels.append("drive:O")
    return SympyModel(list(q), points, rotors, V, cons, labels, damping=damping, elastic=(3, 7))


def double_pendulum_minimal(k1, k2, *, rigid=False):
    """The same double pendulum in minimal coordinates (th1, u1, th2, u2), or (th1, th2) with the
    end masses rigidly at the bar ends; returns the first-order ODE right-hand side."""
    if rigid:
        th1, th2 = sp.symbols("theta1 theta2")
        qmin = [th1, th2]
        u1 = u2 = sp.Integer(0)
    else:
        th1, u1, th2, u2 = sp.symbols("theta1 u1 theta2 u2")
        qmin = [th1, u1, th2, u2]
    e1 = _rot(th1, DBL["L1"] + u1, 0)
    full = (0, 0, th1, u1, e1[0], e1[1], th2, u2)
    points, rotors, V, _ = double_pendulum_parts(full, k1, k2)
    n = len(qmin)
    qv = sp.Matrix(qmin)
    qd = sp.Matrix(sp.symbols(f"w0:{n}"))
    Mmat, quad = _lagrange_terms(points, rotors, qv, qd)
    rhs = -quad - sp.Matrix([V]).jacobian(qv).T
    Mf = sp.lambdify([qmin], Mmat, cse=True)
    Rf = sp.lambdify([qmin, list(qd)], rhs, cse=True)

    def f(t, z):
        qq, ww = z[:n], z[n:]
        return np.concatenate([ww, np.linalg.solve(Mf(qq), np.ravel(Rf(qq, ww)))])
    return f


def double_pendulum_initial(th1, th2, w1, w2):
    """A consistent redundant state (u = 0, udot = 0)."""
    L1 = DBL["L1"]
    s = np.array([0, 0, th1, 0, L1 * math.cos(th1), L1 * math.sin(th1), th2, 0.0])
    sd = np.array([0, 0, w1, 0, -L1 * math.sin(th1) * w1, L1 * math.cos(th1) * w1, w2, 0.0])
    return s, sd


@pytest.fixture(scope="module")
def pendulum():
    return pendulum_model()


@pytest.fixture(scope="module")
def soft_double():
    """Springs resolved by the steps used below: omega ~ sqrt(k / mp) ~ 70 and 100 rad/s."""
    return double_pendulum_model(1000.0, 1000.0)


# ---------------------------------------------------------------------------------------------------
# The hand-written models themselves (a test of the test inputs)
# ---------------------------------------------------------------------------------------------------
def test_hand_model_derivatives_match_finite_differences(soft_double):
    rng = np.random.default_rng(1)
    m = soft_double
    s, sd, acc = rng.normal(size=8), rng.normal(size=8), rng.normal(size=8)
    lam, t, eps = rng.normal(size=4), 0.3, 1e-6
    dQ, dQv = m.force_jacobians(s, sd, t)
    for j in range(8):
        e = np.zeros(8)
        e[j] = eps
        # central differences: error O(eps^2) ~ 1e-12 times third derivatives of order 1-100
        fd = (m.forces(s + e, sd, t) - m.forces(s - e, sd, t)) / (2 * eps)
        np.testing.assert_allclose(dQ[:, j], fd, atol=1e-7)
        fd = (m.forces(s, sd + e, t) - m.forces(s, sd - e, t)) / (2 * eps)
        np.testing.assert_allclose(dQv[:, j], fd, atol=1e-7)
        fd = (m.mass_matrix(s + e) @ acc - m.mass_matrix(s - e) @ acc) / (2 * eps)
        np.testing.assert_allclose(m.mass_matrix_jacobian(s, acc)[:, j], fd, atol=1e-7)
        fd = (m.constraint_jacobian(s + e, t).T @ lam
              - m.constraint_jacobian(s - e, t).T @ lam) / (2 * eps)
        np.testing.assert_allclose(m.constraint_force_jacobian(s, lam, t)[:, j], fd, atol=1e-7)


# ---------------------------------------------------------------------------------------------------
# Kernels (the LU routines themselves: tests/test_lapack.py)
# ---------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("n", [1, 2, 13, 60])
def test_the_newton_factorisation_reports_the_pivot_ratio_of_the_iteration_matrix(n):
    """``min_pivot_ratio`` is that of P G = L U (partial pivoting by rows of G, the matrix built transposed),
    and 0 for an exactly singular G, which the Newton iteration reports as a singular iteration matrix."""
    from mechanisms._alpha_step import _lu_factor  # internal kernel: no public face

    rng = np.random.default_rng(n)
    G = rng.normal(size=(n, n)) + np.sqrt(n) * np.eye(n)
    pivots = np.abs(np.diag(scipy.linalg.lu(G)[2]))
    assert _lu_factor(G.T.copy(), np.empty(n, dtype=np.int32)) == pytest.approx(pivots.min() / pivots.max(),
                                                                             rel=1e-12)
    singular = np.array([[2.0, 1.0, 3.0], [4.0, 2.0, 6.0], [1.0, 3.0, 0.5]])
    assert _lu_factor(singular.T.copy(), np.empty(3, dtype=np.int32)) == 0.0


# ---------------------------------------------------------------------------------------------------
# Accuracy: observed order against minimal-coordinate references
# ---------------------------------------------------------------------------------------------------
def _observed_orders(errors):
    e = np.asarray(errors)
    return np.log2(e[:-1] / e[1:])


@pytest.mark.parametrize("rho_inf", [0.8, 0.5])
def test_pendulum_order_two_against_minimal_coordinates(pendulum, rho_inf):
    th0, t_end = 0.3, 1.0
    ref = solve_ivp(pendulum_minimal_rhs, (0, t_end), [th0, 0.0], method="DOP853", rtol=1e-13,
                    atol=1e-13)
    th_ref, w_ref = ref.y[:, -1]
    s0 = [0.0, 0.0, th0]
    errors, lam_errors = [], []
    for n_steps in (50, 100, 200, 400):
        res = mechanisms.simulate(pendulum, t_end=t_end, dt=t_end / n_steps, s0=s0, rho_inf=rho_inf,
                                  tol=1e-13)
        assert res.success and res.n_steps == n_steps and res.n_rejected == 0
        errors.append(max(abs(res.s[-1, 2] - th_ref), abs(res.sdot[-1, 2] - w_ref)))
        # pin reaction from the minimal solution: lam = -(m a_c - m g) with the centroid's
        # acceleration (the constraint force on (x, y) is -lam)
        m, c = PEND["m"], PEND["L"] / 2
        alpha = pendulum_minimal_rhs(t_end, [th_ref, w_ref])[1]
        acc_c = c * np.array([-math.sin(th_ref) * alpha - math.cos(th_ref) * w_ref**2,
                              math.cos(th_ref) * alpha - math.sin(th_ref) * w_ref**2])
        lam_ref = -(m * acc_c + np.array([0.0, m * G]))
        lam_errors.append(np.max(np.abs(res.lam[-1] - lam_ref)))
    # second order (Chung & Hulbert; Arnold & Bruls 2007 for q, v and, after the O(h) start-up
    # transient has decayed like (alpha_m / alpha_f)^n, for lam): slopes 2 up to higher-order terms
    assert np.all(np.abs(_observed_orders(errors) - 2.0) < 0.15), errors
    assert np.all(np.abs(_observed_orders(lam_errors) - 2.0) < 0.2), lam_errors


def _pendulum_reference_lam(t_end, th0, w0, t_eval):
    """Pin reactions (n_t, 2) of the minimal-coordinate solution (see the test above)."""
    ref = solve_ivp(pendulum_minimal_rhs, (0, t_end), [th0, w0], t_eval=t_eval, method="DOP853",
                    rtol=1e-13, atol=1e-14)
    th, w = ref.y
    alpha = np.array([pendulum_minimal_rhs(0.0, z)[1] for z in ref.y.T])
    m, c = PEND["m"], PEND["L"] / 2
    acc_c = c * np.array([-np.sin(th) * alpha - np.cos(th) * w**2,
                          np.cos(th) * alpha - np.sin(th) * w**2])
    return (-(m * acc_c + np.array([[0.0], [m * G]]))).T


def test_multipliers_converge_at_order_two_from_the_start(pendulum):
    # Arnold & Bruls' perturbed start (perturbed_start=True) a_0 = sddot(t0 + (alpha_m - alpha_f) h): the multipliers
    # after the first step carry only the local error, O(h^3) (with a_0 = sddot_0 it was O(h^2),
    # the global order lost in the very first step), and their maximum error over a window
    # that starts at t0 falls at order 2. The plain start loses one order in the first step.
    # The swinging start (theta' = 3 rad/s) has a nonzero
    # jerk, so the perturbation matters.
    th0, w0, t_end = 0.3, 3.0, 0.05
    first, window, first_plain = [], [], []
    for n_steps in (10, 20, 40, 80):
        kw = dict(t_end=t_end, dt=t_end / n_steps, s0=[0, 0, th0], sdot0=[0, 0, w0], rho_inf=0.5,
                  tol=1e-14, estimate_error=False)
        res = mechanisms.simulate(pendulum, perturbed_start=True, **kw)
        plain = mechanisms.simulate(pendulum, **kw)
        lam_ref = _pendulum_reference_lam(t_end, th0, w0, res.t)
        first.append(np.max(np.abs(res.lam[1] - lam_ref[1])))
        window.append(np.max(np.abs(res.lam - lam_ref)))
        first_plain.append(np.max(np.abs(plain.lam[1] - lam_ref[1])))
    assert np.all(np.abs(_observed_orders(first) - 3.0) < 0.15), first
    assert np.all(np.abs(_observed_orders(window) - 2.0) < 0.1), window
    assert np.all(np.abs(_observed_orders(first_plain) - 2.0) < 0.15), first_plain


def test_double_pendulum_with_springs_converges_to_minimal_solution(soft_double):
    k = 1000.0
    f = double_pendulum_minimal(k, k)
    s0, sd0 = double_pendulum_initial(0.4, -0.3, 1.0, 0.0)
    t_end = 0.5
    ref = solve_ivp(f, (0, t_end), [0.4, 0.0, -0.3, 0.0, 1.0, 0.0, 0.0, 0.0], method="DOP853",
                    rtol=1e-12, atol=1e-13)
    z = ref.y[:, -1]
    idx = [2, 3, 6, 7]
    errors = []
    for n_steps in (200, 400, 800):
        res = mechanisms.simulate(soft_double, t_end=t_end, dt=t_end / n_steps, s0=s0, sdot0=sd0,
                                  tol=1e-13)
        errors.append(max(np.max(np.abs(res.s[-1, idx] - z[:4])),
                          np.max(np.abs(res.sdot[-1, idx] - z[4:])) / 100.0))
    # the spring modes (~70-100 rad/s, h omega <= 0.25) are resolved: asymptotic order 2
    assert np.all(np.abs(_observed_orders(errors) - 2.0) < 0.2), errors


# ---------------------------------------------------------------------------------------------------
# Constraints and stiffness
# ---------------------------------------------------------------------------------------------------
def test_constraint_residual_stays_at_newton_tolerance(soft_double):
    s0, sd0 = double_pendulum_initial(1.0, 2.0, 3.0, -5.0)
    tol = 1e-12
    res = mechanisms.simulate(soft_double, t_end=2.0, dt=2e-3, s0=s0, sdot0=sd0, tol=tol)
    assert res.success
    # index 3: Phi = 0 is solved at every step, so the residual is bounded by the last Newton
    # increment (<= tol * max(1, |s0|) = 2 tol) times the row sums of Phi_s (<= 2 + L1 + |u1| + 1
    # < 3.4 here), at every step: no drift
    bound = 3.4 * 2.0 * tol
    assert np.max(res.constraint_residual) <= bound
    assert np.max(res.constraint_residual[-100:]) <= bound


@pytest.mark.slow
@pytest.mark.parametrize("rho_inf", [0.8, 0.0])
def test_stiff_springs_stable_at_large_steps_and_rigid_limit(rho_inf):
    # springs with omega = sqrt(k / mp) ~ 7e4-1e5 rad/s; steps of 2e-3 s give h omega ~ 150-200,
    # steps of 8e-3 s up to ~800
    k = 1e9
    stiff = double_pendulum_model(k, k)
    rigid = double_pendulum_minimal(k, k, rigid=True)
    s0, sd0 = double_pendulum_initial(0.4, -0.3, 1.0, 0.0)
    t_end = 1.0
    ref = solve_ivp(rigid, (0, t_end), [0.4, -0.3, 1.0, 0.0], method="DOP853", rtol=1e-12,
                    atol=1e-13).y[:, -1]
    errors = []
    for n_steps in (125, 250, 500):
        res = mechanisms.simulate(stiff, t_end=t_end, dt=t_end / n_steps, s0=s0, sdot0=sd0,
                                  rho_inf=rho_inf)
        assert res.success
        assert np.max(np.abs(res.s[:, [3, 7]])) < 1e-6   # stretch stays ~ static, m w^2 L / k
        errors.append(max(abs(res.s[-1, 2] - ref[0]), abs(res.s[-1, 6] - ref[1])))
    # no order reduction from the unresolved stiff modes: the error against the rigid limit
    # (whose own distance is O(1/k) ~ 1e-9) falls like h^2
    assert np.all(np.abs(_observed_orders(errors) - 2.0) < 0.25), errors


def test_full_newton_and_modified_newton_agree(soft_double):
    s0, sd0 = double_pendulum_initial(0.4, -0.3, 1.0, 0.0)
    kw = dict(t_end=0.2, dt=1e-3, s0=s0, sdot0=sd0, tol=1e-12)
    modified = mechanisms.simulate(soft_double, **kw)
    full = mechanisms.simulate(soft_double, jacobian_reuse=False, **kw)
    assert full.n_jacobian == full.n_newton
    assert modified.n_jacobian < modified.n_steps
    # both solve the same step equations to the Newton tolerance (1e-12 x scale 1); the
    # per-step differences add up over the 200 steps, amplified by the flow's sensitivity over
    # 0.2 s (a factor ~ exp(0.2 * 3), rounded up to 2)
    np.testing.assert_allclose(modified.s, full.s, rtol=0, atol=2 * 200 * 1e-12)


# ---------------------------------------------------------------------------------------------------
# Energy
# ---------------------------------------------------------------------------------------------------
def _energy(model, res):
    return np.array([model.kinetic_energy(s, v) + model.potential_energy(s)
                     for s, v in zip(res.s, res.sdot)])


@pytest.mark.slow
def test_undriven_energy_conserved_to_second_order(soft_double):
    s0, sd0 = double_pendulum_initial(1.2, 0.5, 2.0, -1.0)
    t_end = 1.0
    drifts = []
    for n_steps in (250, 500, 1000):
        res = mechanisms.simulate(soft_double, t_end=t_end, dt=t_end / n_steps, s0=s0, sdot0=sd0,
                                  tol=1e-13)
        E = _energy(soft_double, res)
        drifts.append(np.max(np.abs(E - E[0])))
    # the exact flow conserves E; a second-order method changes it by O(h^2) over a fixed time
    assert np.all(np.abs(_observed_orders(drifts) - 2.0) < 0.25), drifts
    assert drifts[-1] < 1e-3 * abs(_energy(soft_double, res)[0])


@pytest.mark.slow
def test_drive_work_equals_energy_change():
    omega = 2 * math.pi
    model = double_pendulum_model(1000.0, 1000.0,
                                  drive=lambda t: 0.3 + 4.0 * t + 0.5 * sp.sin(omega * t))
    s0, _ = double_pendulum_initial(0.3, 0.0, 0.0, 0.0)
    w1 = 4.0 + 0.5 * omega
    _, sd0 = double_pendulum_initial(0.3, 0.0, w1, 0.0)
    t_end = 1.0
    mismatch, gains = [], []
    for n_steps in (250, 500, 1000):
        res = mechanisms.simulate(model, t_end=t_end, dt=t_end / n_steps, s0=s0, sdot0=sd0,
                                  tol=1e-13)
        E = _energy(model, res)
        # power of the constraint forces -Phi_s^T lam on sdot, = lam . Phi_t on the constraint
        # manifold: only the rheonomic drive row contributes
        power = np.array([lam @ model.constraint_rate(s, t)
                          for lam, s, t in zip(res.lam, res.s, res.t)])
        work = np.concatenate([[0.0], np.cumsum(0.5 * (power[1:] + power[:-1]) * np.diff(res.t))])
        mismatch.append(np.max(np.abs(E - E[0] - work)))
        gains.append(np.max(np.abs(E - E[0])))
    # both the integrator and the trapezoidal quadrature are second order
    assert np.all(np.abs(_observed_orders(mismatch) - 2.0) < 0.3), mismatch
    assert mismatch[-1] < 1e-3 * gains[-1]


# ---------------------------------------------------------------------------------------------------
# Results, observables, failures and bad input
# ---------------------------------------------------------------------------------------------------
def test_result_shapes_observables_and_error_estimate(pendulum):
    res = mechanisms.simulate(pendulum, t_end=0.5, dt=0.005, s0=[0, 0, 0.3],
                              observables=["theta.angle"], estimate_error=True)
    n_t = 101
    assert res.t.shape == (n_t,) and res.s.shape == (n_t, 3) and res.lam.shape == (n_t, 2)
    assert res.sdot.shape == res.sddot.shape == (n_t, 3)
    assert res.constraint_residual.shape == (n_t,)
    np.testing.assert_array_equal(res.observables["theta.angle"], res.s[:, 2])
    assert res.observable_units["theta.angle"] == "rad"
    assert res.run_time > 0 and res.n_newton >= res.n_steps == 100
    # the Richardson estimate against the true error (from the minimal-coordinate reference)
    ref = solve_ivp(pendulum_minimal_rhs, (0, 0.5), [0.3, 0.0], t_eval=res.t, method="DOP853",
                    rtol=1e-13, atol=1e-13).y[0]
    true_error = np.max(np.abs(res.s[:, 2] - ref))
    # asymptotically exact for an order-2 method; allow the O(h^3) remainder (a factor of 1.5)
    assert true_error / 1.5 <= res.observable_error["theta.angle"] <= 1.5 * true_error
    with pytest.raises(dataclasses_frozen_error()):
        res.status = 1


def dataclasses_frozen_error():
    import dataclasses
    return dataclasses.FrozenInstanceError


class _FailsLater:
    """The pendulum whose forces turn to NaN after t = 0.25 s."""

    def __init__(self, model):
        self._m = model

    def __getattr__(self, name):
        return getattr(self._m, name)

    def forces(self, s, sdot, t):
        return self._m.forces(s, sdot, t) * (np.nan if t > 0.25 else 1.0)


def test_failure_reports_time_and_partial_result(pendulum):
    bad = _FailsLater(pendulum)
    res = mechanisms.simulate(bad, t_end=0.5, dt=0.01, s0=[0, 0, 0.3], throw=False)
    assert res.status == -1 and not res.success
    assert "t = 0.26" in res.message and "non-finite" in res.message
    assert res.t[-1] == pytest.approx(0.25) and np.all(np.isfinite(res.s))
    with pytest.raises(SimulationError, match="t = 0.26") as info:
        mechanisms.simulate(bad, t_end=0.5, dt=0.01, s0=[0, 0, 0.3])
    assert info.value.result.status == -1
    res = mechanisms.simulate(pendulum, t_end=0.5, dt=0.01, s0=[0, 0, 0.3], throw=False,
                              max_iterations=1, tol=1e-15)
    assert res.status == -1 and "did not converge in 1 iterations" in res.message


def test_bad_input(pendulum):
    ok = dict(t_end=0.1, dt=0.01, s0=[0, 0, 0.3])
    with pytest.raises(TypeError, match="exactly one of `t_end`"):
        mechanisms.simulate(pendulum, **ok, n_periods=2)
    with pytest.raises(TypeError, match="exactly one of `dt`"):
        mechanisms.simulate(pendulum, t_end=0.1, s0=[0, 0, 0.3])
    with pytest.raises(ValueError, match=r"`s0` must have shape \(3,\)"):
        mechanisms.simulate(pendulum, t_end=0.1, dt=0.01, s0=[0, 0.3])
    with pytest.raises(ValueError, match="violates the constraints"):
        mechanisms.simulate(pendulum, t_end=0.1, dt=0.01, s0=[0.1, 0, 0.3])
    with pytest.raises(ValueError, match="violates the velocity constraints"):
        mechanisms.simulate(pendulum, **ok, sdot0=[1.0, 0, 0])
    with pytest.raises(ValueError, match="rho_inf"):
        mechanisms.simulate(pendulum, **ok, rho_inf=1.5)
    with pytest.raises(ValueError, match="method"):
        mechanisms.simulate(pendulum, **ok, method="euler")
    with pytest.raises(ValueError, match="needs the period|need the period"):
        mechanisms.simulate(pendulum, n_periods=2, dt=0.01, s0=[0, 0, 0.3])
    with pytest.raises(ValueError, match="`s0` is required"):
        mechanisms.simulate(pendulum, t_end=0.1, dt=0.01)
    with pytest.raises(TypeError, match="ConstrainedModel"):
        mechanisms.simulate(object(), t_end=0.1, dt=0.01)
    with pytest.raises(ValueError, match="`dt` must be positive"):
        mechanisms.simulate(pendulum, t_end=0.1, dt=-0.01, s0=[0, 0, 0.3])


# ---------------------------------------------------------------------------------------------------
# The assembled thesis four-bar
# ---------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def resolved_four_bar():
    """The thesis four-bar, undamped, coupler with two Ritz bending modes and no axial mode
    (296 and 1184 rad/s, resolved by the steps below: h omega <= 0.19), so that the energy the
    elastic modes carry converges at the method's order instead of being damped numerically."""
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # no axial coordinate: no geometric stiffening (announced)
        mech = mechanisms.four_bar(discretisation="ritz", n_bending=2, axial=False,
                                   damping_ratio=0.0)
    return mech, mechanisms.assemble(mech), mechanisms.nominal_motion(mech)


def _work_and_energy(model, res):
    E = _energy(model, res)
    power = np.array([lam @ model.constraint_rate(s, t) for lam, s, t in zip(res.lam, res.s, res.t)])
    work = np.concatenate([[0.0], np.cumsum(0.5 * (power[1:] + power[:-1]) * np.diff(res.t))])
    return E - E[0], work


def test_four_bar_drive_work_equals_energy_change(resolved_four_bar):
    mech, model, _ = resolved_four_bar
    mismatch = []
    for spp in (200, 400, 800):
        res = mechanisms.simulate(mech, n_periods=1, steps_per_period=spp, tol=1e-12)
        assert res.success
        assert np.max(res.constraint_residual) < 1e-12 * 3.0 * 3.0   # tol x max|s0| x row sums
        gain, work = _work_and_energy(model, res)
        mismatch.append(np.max(np.abs(gain - work)))
    # the drive's work integral (trapezoid) and the integrator are both second order
    assert np.all(np.abs(_observed_orders(mismatch) - 2.0) < 0.25), mismatch
    assert mismatch[-1] < 1e-3 * np.max(np.abs(gain))


def test_four_bar_undriven_conserves_energy_to_second_order(resolved_four_bar):
    import dataclasses
    mech, _, nominal = resolved_four_bar
    # a torque drive with no feedforward and no gains: the crank turns freely from 100 rad/s
    free = mechanisms.assemble(dataclasses.replace(
        mech, drives=(mechanisms.TorqueDrive(joint="O", rate=100.0),)))
    drifts = []
    for spp in (200, 400, 800):
        res = mechanisms.simulate(free, n_periods=1, steps_per_period=spp, s0=nominal.s[0],
                                  sdot0=nominal.sdot[0], tol=1e-12)
        E = _energy(free, res)
        drifts.append(np.max(np.abs(E - E[0])))
    assert np.all(np.abs(_observed_orders(drifts) - 2.0) < 0.25), drifts
    assert drifts[-1] < 5e-3 * E[0]


def test_four_bar_fem_with_axial_modes_converges_at_order_two():
    # FEM coupler with axial deformation: axial modes up to ~1e5 rad/s are far from resolved
    # (h omega ~ 10-40) and damped by rho_inf = 0.8; the midspan deflection still converges at
    # order 2. Successive differences d_k = max |o_{h_k} - o_{h_k/2}| on the common grid fall
    # by 2^p.
    mech = mechanisms.four_bar(discretisation="fem", n_elements=2)
    spec = "coupler.deflection@0.5"
    runs = [mechanisms.simulate(mech, n_periods=1, steps_per_period=spp, observables=[spec])
            for spp in (200, 400, 800, 1600)]
    diffs = [np.max(np.abs(a.observables[spec] - b.observables[spec][::2]))
             for a, b in zip(runs[:-1], runs[1:])]
    assert np.all(np.abs(_observed_orders(diffs) - 2.0) < 0.25), diffs
    assert all(r.constraint_residual.max() < 1e-10 * 3.0 * 3.0 for r in runs)


def test_torque_drive_with_nominal_feedforward_follows_the_nominal_law():
    # A nearly rigid coupler (E x 1e4: elastic deflections ~1e-4 of the real ones) driven by a
    # TorqueDrive with no feedback: simulate() feeds the nominal inverse-dynamics torque forward,
    # which reproduces the nominal motion crank = 100 t up to the integrator's O(h^2) error (and
    # O(1/E), O(spline^4) terms far below it), so the deviation falls 4x per halving of h.
    import dataclasses
    mech = mechanisms.four_bar(discretisation="ritz", n_bending=1, youngs_modulus=2.0e15)
    torque = dataclasses.replace(mech, drives=(mechanisms.TorqueDrive(joint="O", rate=100.0),))
    deviations = []
    for spp in (100, 200, 400):
        res = mechanisms.simulate(torque, n_periods=1, steps_per_period=spp)
        assert res.lam.shape[1] == 8   # no drive row: the crank is free
        deviations.append(np.max(np.abs(res.s[:, 2] - 100.0 * res.t)))
    assert np.all(np.abs(_observed_orders(deviations) - 2.0) < 0.25), deviations


def test_error_estimate_on_odd_grids_and_without_observables(pendulum):
    # 101 steps: the 2 h run covers 50 steps; the estimate uses the common points
    res = mechanisms.simulate(pendulum, t_end=0.505, dt=0.005, s0=[0, 0, 0.3])
    assert res.n_steps == 101 and set(res.observable_error) == {"s"}
    ref = solve_ivp(pendulum_minimal_rhs, (0, 0.505), [0.3, 0.0], t_eval=res.t, method="DOP853",
                    rtol=1e-13, atol=1e-13).y[0]
    # the coordinates' estimate bounds theta's true error within the O(h^3) remainder
    assert np.max(np.abs(res.s[:, 2] - ref)) <= 1.5 * res.observable_error["s"]
    single = mechanisms.simulate(pendulum, t_end=0.005, dt=0.005, s0=[0, 0, 0.3])
    assert single.observable_error == {} and "No error estimate" in single.message


def test_observables_without_an_observable_method(pendulum):
    with pytest.raises(TypeError, match="no `observable"):
        mechanisms.simulate(_NoObservables(pendulum), t_end=0.1, dt=0.01, s0=[0, 0, 0.3],
                            observables=["theta.angle"])


class _NoObservables:
    """A protocol model without the optional ``observable`` method."""

    def __init__(self, model):
        self._m = model

    def __getattr__(self, name):
        if name == "observable":
            raise AttributeError(name)
        return getattr(self._m, name)


class _RedundantPin:
    """The pendulum with its x pin row repeated: a singular augmented matrix."""

    def __init__(self, model):
        self._m = model
        self.n_constraints = model.n_constraints + 1

    def __getattr__(self, name):
        return getattr(self._m, name)

    def _rows(self, a):
        return np.concatenate([a, a[:1]])

    def constraints(self, s, t):
        return self._rows(self._m.constraints(s, t))

    def constraint_jacobian(self, s, t):
        return self._rows(self._m.constraint_jacobian(s, t))

    def constraint_rate(self, s, t):
        return self._rows(self._m.constraint_rate(s, t))

    def constraint_gamma(self, s, sdot, t):
        return self._rows(self._m.constraint_gamma(s, sdot, t))

    def constraint_force_jacobian(self, s, lam, t):
        return self._m.constraint_force_jacobian(s, lam[:-1] + np.r_[lam[-1], 0.0], t)


def test_redundant_constraints_are_reported_before_the_run(pendulum):
    with pytest.raises(ValueError, match="singular.*redundant constraints"):
        mechanisms.simulate(_RedundantPin(pendulum), t_end=0.1, dt=0.01, s0=[0, 0, 0.3])


# ---------------------------------------------------------------------------------------------------
# Step halving where Newton fails
# ---------------------------------------------------------------------------------------------------
def test_failed_steps_are_retried_in_substeps_on_the_user_grid(pendulum):
    # Newton needs 4-5 iterations per step of 0.1 s at tol 1e-12 (swing of +-0.3 rad); capped at 3
    # it fails there, and the step is retried as 2, 4, ... substeps, whose better predictors need
    # fewer iterations. The output stays on the uniform grid and the substeps only shrink local
    # errors: the error against the minimal-coordinate reference is at most that of the uncapped
    # run up to the O(h^3) terms that the substeps change (a factor 1.5).
    th0, t_end, h = 0.3, 1.0, 0.1
    kw = dict(t_end=t_end, dt=h, s0=[0.0, 0.0, th0], tol=1e-12, estimate_error=False)
    capped = mechanisms.simulate(pendulum, max_iterations=3, **kw)
    plain = mechanisms.simulate(pendulum, **kw)
    assert capped.success and plain.n_rejected == 0
    assert capped.n_rejected > 0 and capped.n_substeps >= 2 * capped.n_rejected // 2
    assert "rejected" in capped.message
    np.testing.assert_allclose(capped.t, np.linspace(0.0, t_end, 11), rtol=0, atol=1e-14)
    ref = solve_ivp(pendulum_minimal_rhs, (0, t_end), [th0, 0.0], t_eval=capped.t,
                    method="DOP853", rtol=1e-13, atol=1e-13).y[0]
    err_capped = np.max(np.abs(capped.s[:, 2] - ref))
    err_plain = np.max(np.abs(plain.s[:, 2] - ref))
    assert err_capped <= 1.5 * err_plain, (err_capped, err_plain)
    # every accepted grid state is on the constraints to the Newton tolerance (row sums 1)
    assert np.max(capped.constraint_residual) <= 1e-12
    # without halving the first failure ends the run
    failed = mechanisms.simulate(pendulum, max_iterations=3, max_step_halvings=0, throw=False, **kw)
    assert failed.status == -1 and "did not converge in 3 iterations" in failed.message
    with pytest.raises(ValueError, match="max_step_halvings"):
        mechanisms.simulate(pendulum, max_step_halvings=-1, **kw)


def test_rho_inf_one_warns(pendulum, caplog):
    with caplog.at_level("WARNING", logger="mechanisms._simulate"):
        mechanisms.simulate(pendulum, t_end=0.05, dt=0.01, s0=[0, 0, 0.3], rho_inf=1.0)
    assert "rho_inf = 1" in caplog.text


# ---------------------------------------------------------------------------------------------------
# The shipped scenes against their linear periodic solutions
# ---------------------------------------------------------------------------------------------------
def _against_linear(mech, spec, steps_per_period, n_lin=256):
    """Nonlinear runs over 2 periods from the nominal motion and from the linear periodic state,
    and the largest difference of the second one from the linear solution (on the common grid)."""
    import linearize
    import periodic
    lin = linearize.about(mech, n_steps=n_lin)
    ss = periodic.steady_state(lin.system)
    s, sd = lin.full_state(ss.x, ss.v)
    obs = mechanisms.assemble(mech).observable(spec)
    o_lin = np.array([obs.value(q) for q in s])[::n_lin // steps_per_period]
    o_lin = np.concatenate([o_lin[:-1], o_lin])    # two periods
    nominal = mechanisms.simulate(mech, n_periods=2, steps_per_period=steps_per_period,
                                  observables=[spec])
    linear = mechanisms.simulate(mech, n_periods=2, steps_per_period=steps_per_period,
                                 observables=[spec], s0=s[0], sdot0=sd[0])
    assert nominal.success and linear.success
    deviation = np.max(np.abs(linear.observables[spec] - o_lin))
    return deviation, np.max(np.abs(o_lin)), linear.observable_error[spec], nominal


@pytest.fixture(scope="module")
def linear_starts():
    """The linear periodic state at t = 0 of the shipped four-bar and six-bar."""
    import linearize
    import periodic
    starts = {}
    for name in ("four_bar_fem4", "six_bar"):
        lin = linearize.about(mechanisms.load(name), n_steps=256)
        ss = periodic.steady_state(lin.system)
        s, sd = lin.full_state(ss.x, ss.v)
        starts[name] = (s[0], sd[0])
    return starts


@pytest.mark.parametrize("spp", [16, 64])
def test_shipped_scenes_run_at_coarse_steps(spp, linear_starts):
    # the studies' nonlinear check ran these at coarse grids, from the nominal motion and from
    # the linear periodic state, and failed in Newton (modified Newton found spurious roots on
    # the four-bar); with the divergence guards and step halving all complete on the user's grid
    runs = [(name, {}) for name in ("two_link_arm", "six_bar", "four_bar_fem4")]
    runs += [(name, dict(s0=s0, sdot0=sd0)) for name, (s0, sd0) in linear_starts.items()]
    for name, start in runs:
        res = mechanisms.simulate(mechanisms.load(name), n_periods=1, steps_per_period=spp,
                                  estimate_error=False, **start)
        assert res.success and res.n_steps == spp, (name, res.message)


def test_two_link_arm_approaches_the_linear_solution_quadratically():
    # The former shipped arm at 1 % and 3 % of its joint amplitudes: from the linear periodic state the
    # nonlinear run differs from the linear solution by the neglected terms, quadratic in the
    # deflections, so the difference grows 9x when the amplitudes triple (+-25 % for the cubic
    # terms and the integration errors, each below a tenth of its deviation), and stays a small
    # fraction of the amplitude
    spec = "forearm.transverse@1"
    results = []
    for scale in (0.01, 0.03):
        # the former shipped arm (2 mm links, period 0.5 s, amplitudes 0.5 and 0.4 rad), scaled
        mech = mechanisms.two_link_arm(thickness=0.002, period=0.5,
                                       shoulder_amplitude=0.5 * scale,
                                       elbow_amplitude=0.4 * scale)
        results.append(_against_linear(mech, spec, 128))
    (dev1, amp1, err1, _), (dev3, _, err3, _) = results
    assert err1 < 0.1 * dev1 and err3 < 0.1 * dev3   # the ratio measures the model, not the steps
    assert 9.0 * 0.75 <= dev3 / dev1 <= 9.0 * 1.25, (dev1, dev3)
    assert dev1 < 0.1 * amp1


def test_six_bar_stays_close_to_the_linear_solution():
    # the six-bar at 60 rad/s (deflection amplitude ~1.5 mm on the 0.28 m link 2): from the
    # linear periodic state the nonlinear run differs from the linear solution by terms of
    # relative size deflection / length ~ 0.5 %; allowed: 2 % of the amplitude plus three times
    # the run's own error estimate
    spec = "link2.deflection@0.5"
    dev, amp, err, nominal = _against_linear(mechanisms.six_bar(crank_speed=60.0), spec, 256)
    assert dev <= 0.02 * amp + 3.0 * err, (dev, amp, err)
    assert np.max(nominal.constraint_residual) < 1e-10 * 3.0 * 3.0


def test_a_link_observable_s_values_along_a_run_are_its_value_at_each_sample():
    """``values_along`` (simulate's evaluation of a run's observables at once) against ``value`` sample by
    sample, for every kind of a link's quantity, with and without the stiffened link's membrane strain."""
    for scene, stiffened in (("four_bar_fem4", True), ("four_bar_fem1", False)):
        mechanism = mechanisms.load(scene)
        if not stiffened:
            mechanism = mechanism.with_parameter("links.coupler.geometric_stiffening", False)
        model = mechanisms.integrated_model(mechanism)
        run = mechanisms.simulate(model, t_end=0.01, dt=2e-4, estimate_error=False)
        for kind in ("deflection@0.5", "transverse@0.3", "strain@0.25", "moment@0.5", "angle"):
            observable = model.observable(f"coupler.{kind}")
            expected = np.array([observable.value(s) for s in run.s])
            along = observable.values_along(run.s)
            assert along.shape == expected.shape and np.ptp(expected) > 0.0
            np.testing.assert_allclose(along, expected, rtol=1e-12, atol=1e-15 * np.abs(expected).max())
        with pytest.raises(mechanisms.ArgumentError, match=r"s must have shape \(K, "):
            observable.values_along(run.s[0])
