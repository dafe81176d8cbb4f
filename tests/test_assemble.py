"""The generic assembler against independent derivations.

* sympy: the thesis four-bar OABC (rigid crank and rocker, elastic coupler with 2 Ritz bending and
  1 axial mode, seed eq. 2.2/2.4) derived by Lagrange's equations (seed eq. 2.10) from the kinetic
  and strain energies written out symbolically (seed eq. 2.12/2.13, with and without geometric
  stiffening), integrals along the links done exactly, in the assembler's coordinates.
* central finite differences for the analytic derivatives of the protocol.
* the exact second time derivative of the constraints along a quadratic path for ``gamma``.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest
import sympy as sp

import mechanisms as mk
from mechanisms import (GROUND, ElasticLink, Fem, Mechanism, PointMass, PrescribedDrive, Rayleigh,
                        Revolute, RigidLink, Ritz, Slider, TorqueDrive, assemble)

L0, L1, L2, L3 = 0.254, 0.0508, 0.2794, 0.2794
STEEL = dict(width=0.02, thickness=0.0016, density=7800.0)
E = 2.0e11
AREA = 0.02 * 0.0016
SECOND_MOMENT = 0.02 * 0.0016**3 / 12.0
MU = 7800.0 * AREA
GRAVITY = (0.7, -9.81)                      # tilted so that both components are exercised
POINT_MASS = dict(x=0.1, mass=0.01, inertia=2e-6)
ALPHA, BETA = 0.7, 2.0e-5                   # Rayleigh damping on the coupler
DRIVE = dict(rate=100.0, offset=0.3, harmonics=((1, 0.01, 0.02), (3, 0.0, 0.005)))


def fourbar(discretisation=Ritz(2, 1), *, stiffening=True, rotary=False, torque=False,
            young=E, gravity=GRAVITY):
    """The thesis four-bar OABC with an elastic coupler, a point mass on it, gravity and damping."""
    crank = RigidLink.uniform("crank", L1, **STEEL)
    coupler = ElasticLink.rectangular("coupler", L2, youngs_modulus=young,
                                      discretisation=discretisation,
                                      geometric_stiffening=stiffening, rotary_inertia=rotary,
                                      damping=Rayleigh(ALPHA, BETA), **STEEL)
    rocker = RigidLink.uniform("rocker", L3, **STEEL)
    joints = (Revolute("O", GROUND, (0.0, 0.0), "crank", "start"),
              Revolute("A", "crank", "end", "coupler", "start"),
              Revolute("B", "coupler", "end", "rocker", "end"),
              Revolute("C", GROUND, (L0, 0.0), "rocker", "start"))
    drive = (TorqueDrive("O", kp=3.0, kd=0.2, **DRIVE) if torque else PrescribedDrive("O", **DRIVE))
    return Mechanism("fourbar", (crank, coupler, rocker), joints, (drive,),
                     point_masses=(PointMass("coupler", POINT_MASS["x"], POINT_MASS["mass"],
                                             POINT_MASS["inertia"]),),
                     gravity=gravity)


def random_state(model, rng, *, q_scale=1e-3):
    """A random state (not on the constraint manifold: M, Q and Phi_s are defined everywhere)."""
    n = model.n_coords
    s = rng.uniform(-1.0, 1.0, n)
    s[model.rigid_index] *= 0.3
    s[[2, 5, 11]] = rng.uniform(-math.pi, math.pi, 3)
    s[model.elastic_index] *= q_scale
    sdot = rng.uniform(-1.0, 1.0, n) * 20.0
    sdot[[2, 5, 11]] *= 10.0               # angular rates ~ 100 rad/s as in the thesis
    sdot[model.elastic_index] *= q_scale * 100.0
    return s, sdot


# ---------------------------------------------------------------------------------------------------
# sympy derivation
# ---------------------------------------------------------------------------------------------------
XI = sp.Symbol("xi", real=True)


@functools.lru_cache(maxsize=None)
def _integral_01(factor):
    """int_0^1 factor(xi) dxi exactly (returned to 30 digits): factor is a product of powers of xi
    and of sines and cosines of multiples of pi xi. Written in exponentials every term is
    xi^n e^{b xi}, integrated by parts: J(n, b) = e^b / b - n / b J(n - 1, b), J(n, 0) = 1 / (n + 1)."""
    total = sp.Integer(0)
    for term in sp.Add.make_args(sp.expand(sp.sympify(factor).rewrite(sp.exp))):
        coeff, rest = term.as_independent(XI)
        n, b = 0, sp.Integer(0)
        for part in sp.Mul.make_args(rest):
            if part == 1:
                continue
            if part == XI:
                n += 1
            elif part.is_Pow and part.base == XI:
                n += int(part.exp)
            elif isinstance(part, sp.exp):
                b += sp.expand(part.args[0] / XI)
            else:
                raise AssertionError(f"unexpected factor {part} in {factor}")
        total += coeff * _moment(n, b)
    value = sp.N(total, 30)
    assert abs(sp.im(value)) < 1e-25
    return sp.re(value)


@functools.lru_cache(maxsize=None)
def _moment(n, b):
    if b == 0:
        return sp.Rational(1, n + 1)
    if n == 0:
        return (sp.exp(b) - 1) / b
    return sp.exp(b) / b - n / b * _moment(n - 1, b)


def _integrate(expr, length):
    """int_0^length expr dx with x = length xi; expr is polynomial in the coordinates."""
    total = 0
    for term in sp.Add.make_args(sp.expand(expr)):
        coeff, factor = term.as_independent(XI)
        total += coeff * _integral_01(factor)
    return length * total


def _rot(theta):
    return sp.Matrix([[sp.cos(theta), -sp.sin(theta)], [sp.sin(theta), sp.cos(theta)]])


def _derive_fourbar(stiffening, rotary):
    """M, Q, Phi_s of the four-bar (coordinates as the assembler orders them), lambdified."""
    s = sp.symbols("x1 y1 t1 x2 y2 t2 q1 q2 p1 x3 y3 t3", real=True)
    v = sp.symbols("x1d y1d t1d x2d y2d t2d q1d q2d p1d x3d y3d t3d", real=True)
    time = sp.Symbol("t", real=True)
    x1, y1, t1, x2, y2, t2, q1, q2, p1, x3, y3, t3 = s
    x1d, y1d, t1d, x2d, y2d, t2d, q1d, q2d, p1d, x3d, y3d, t3d = v
    gvec = sp.Matrix(GRAVITY)

    def bar(r_origin, v_origin, theta, omega, length):
        """Uniform rigid bar: kinetic and gravity energy integrated along it (x = length xi)."""
        local = sp.Matrix([length * XI, 0])
        position = r_origin + _rot(theta) * local
        velocity = v_origin + omega * _rot(theta).diff(theta) * local
        kinetic = _integrate(sp.Rational(1, 2) * MU * velocity.dot(velocity), length)
        gravity = _integrate(-MU * gvec.dot(position), length)
        return kinetic, gravity

    t_crank, v_crank = bar(sp.Matrix([x1, y1]), sp.Matrix([x1d, y1d]), t1, t1d, L1)
    t_rocker, v_rocker = bar(sp.Matrix([x3, y3]), sp.Matrix([x3d, y3d]), t3, t3d, L3)

    # coupler: seed eq. 2.14 with the modes of eq. 2.2 and 2.4, in xi = x / L2
    def fields(xi):
        w = q1 * sp.sin(sp.pi * xi) + q2 * sp.sin(2 * sp.pi * xi)
        u = p1 * sp.sin(sp.pi * xi / 2)
        return u, w

    u, w = fields(XI)
    ud = u.subs(p1, p1d)
    wd = w.subs({q1: q1d, q2: q2d}, simultaneous=True)
    w_x, u_x = w.diff(XI) / L2, u.diff(XI) / L2
    w_xx = w.diff(XI, 2) / L2**2
    rot2 = _rot(t2)
    local = sp.Matrix([L2 * XI + u, w])
    position = sp.Matrix([x2, y2]) + rot2 * local
    velocity = (sp.Matrix([x2d, y2d]) + t2d * rot2.diff(t2) * local
                + rot2 * sp.Matrix([ud, wd]))
    t_coupler = _integrate(sp.Rational(1, 2) * MU * velocity.dot(velocity), L2)
    if rotary:
        omega = t2d + wd.diff(XI) / L2
        t_coupler += _integrate(sp.Rational(1, 2) * 7800.0 * SECOND_MOMENT * omega**2, L2)
    v_coupler = _integrate(-MU * gvec.dot(position), L2)
    strain = u_x + (w_x**2 / 2 if stiffening else 0)
    v_strain = _integrate(sp.Rational(1, 2) * (E * AREA * strain**2
                                               + E * SECOND_MOMENT * w_xx**2), L2)

    # point mass on the coupler
    xi_m = sp.Float(POINT_MASS["x"] / L2, 30)
    u_m, w_m = fields(xi_m)
    local_m = sp.Matrix([POINT_MASS["x"] + u_m, w_m])
    position_m = sp.Matrix([x2, y2]) + rot2 * local_m
    velocity_m = position_m.jacobian(s) * sp.Matrix(v)
    omega_m = t2d + (wd.diff(XI) / L2).subs(XI, xi_m)
    t_mass = (sp.Rational(1, 2) * POINT_MASS["mass"] * velocity_m.dot(velocity_m)
              + sp.Rational(1, 2) * POINT_MASS["inertia"] * omega_m**2)
    v_mass = -POINT_MASS["mass"] * gvec.dot(position_m)

    kinetic = t_crank + t_rocker + t_coupler + t_mass
    potential = v_crank + v_rocker + v_coupler + v_strain + v_mass

    # Rayleigh damping C = alpha M_ee + beta K_ee of the coupler's elastic coordinates
    q, qd = sp.Matrix([q1, q2, p1]), sp.Matrix([q1d, q2d, p1d])
    m_ee = sp.hessian(t_coupler, qd)
    linear_strain = _integrate(sp.Rational(1, 2) * (E * AREA * u_x**2
                                                    + E * SECOND_MOMENT * w_xx**2), L2)
    k_ee = sp.hessian(linear_strain, q)
    dissipation = (ALPHA * m_ee + BETA * k_ee) * qd

    # Lagrange (seed eq. 2.10): M s'' = dT/ds - (d2T/ds'ds) s' - dV/ds - C s' - Phi_s^T lam
    s_vec, v_vec = sp.Matrix(s), sp.Matrix(v)
    p = sp.Matrix([kinetic]).jacobian(v_vec).T
    mass = p.jacobian(v_vec)
    forces = (sp.Matrix([kinetic]).jacobian(s_vec).T - p.jacobian(s_vec) * v_vec
              - sp.Matrix([potential]).jacobian(s_vec).T)
    forces[6:9, 0] -= dissipation

    # constraints (seed eq. 2.11, written for the frame coordinates)
    w_period = DRIVE["rate"]  # period 2 pi / rate: the harmonics' base frequency is the rate
    angle = DRIVE["offset"] + DRIVE["rate"] * time + sum(
        c * sp.cos(k * w_period * time) + d * sp.sin(k * w_period * time)
        for k, c, d in DRIVE["harmonics"])
    u_l, w_l = fields(1)
    a_point = sp.Matrix([x1, y1]) + _rot(t1) * sp.Matrix([L1, 0])
    b_coupler = sp.Matrix([x2, y2]) + rot2 * sp.Matrix([L2 + u_l, w_l])
    b_rocker = sp.Matrix([x3, y3]) + _rot(t3) * sp.Matrix([L3, 0])
    phi = sp.Matrix([
        -x1, -y1,
        a_point[0] - x2, a_point[1] - y2,
        b_coupler[0] - b_rocker[0], b_coupler[1] - b_rocker[1],
        L0 - x3, -y3,
        t1 - angle])
    jac = phi.jacobian(s_vec)
    args = (s, v, time)
    return (sp.lambdify(args, mass, cse=True), sp.lambdify(args, forces, cse=True),
            sp.lambdify(args, jac, cse=True), sp.lambdify(args, phi, cse=True))


@pytest.fixture(scope="module", params=[(False, False), (True, True)],
                ids=["seed-eq-2.13", "stiffening+rotary"])
def derived(request):
    stiffening, rotary = request.param
    model = assemble(fourbar(Ritz(2, 1), stiffening=stiffening, rotary=rotary))
    return model, _derive_fourbar(stiffening, rotary)


def test_assembler_matches_sympy_lagrange(derived):
    """Mass matrix, force vector and constraint Jacobian of the thesis four-bar against the sympy
    derivation, to 1e-10 relative. The Ritz integrals are exact in sympy and converged to ~1e-14 by
    the assembler's Gauss rule; the sympy side evaluates with float64 after lambdify, so agreement is
    limited by round-off (~1e-14 times the condition of the sums), far below 1e-10. Each block is
    compared on its own scale: the velocity part of Q (Q(s, s') - Q(s, 0)) is ~1e4 times smaller than
    the elastic part, and the gravity part (q = 0, s' = 0) smaller still."""
    model, (mass_f, forces_f, jac_f, phi_f) = derived
    assert model.coord_labels == ("crank.x", "crank.y", "crank.theta", "coupler.x", "coupler.y",
                                  "coupler.theta", "coupler.b1", "coupler.b2", "coupler.a1",
                                  "rocker.x", "rocker.y", "rocker.theta")
    rng = np.random.default_rng(20181)
    zero = np.zeros(model.n_coords)

    def rel(a, b):
        return np.linalg.norm(a - b) / np.linalg.norm(b)

    for _ in range(5):
        s, sdot = random_state(model, rng)
        t = rng.uniform(0.0, 0.1)
        assert rel(model.mass_matrix(s), mass_f(s, sdot, t)) < 1e-10
        q_static = np.asarray(forces_f(s, zero, t), dtype=float).ravel()
        q_full = np.asarray(forces_f(s, sdot, t), dtype=float).ravel()
        assert rel(model.forces(s, zero, t), q_static) < 1e-10
        assert rel(model.forces(s, sdot, t) - model.forces(s, zero, t), q_full - q_static) < 1e-10
        s_rigid = s.copy()
        s_rigid[model.elastic_index] = 0.0
        gravity_only = np.asarray(forces_f(s_rigid, zero, t), dtype=float).ravel()
        assert rel(model.forces(s_rigid, zero, t), gravity_only) < 1e-10
        assert rel(model.constraint_jacobian(s, t), jac_f(s, sdot, t)) < 1e-10
        assert rel(model.constraints(s, t), np.asarray(phi_f(s, sdot, t), float).ravel()) < 1e-10
