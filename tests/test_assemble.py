"""The generic assembler against independent derivations.

* sympy: the thesis four-bar OABC (rigid crank and rocker, elastic coupler with 2 Ritz bending and
  1 axial mode, seed eq. 2.2/2.4) derived by Lagrange's equations (seed eq. 2.10) from the kinetic
  and strain energies written out symbolically (seed eq. 2.12/2.13, with and without geometric
  stiffening, whose membrane strain is projected onto the axial strain functions), integrals along
  the links done exactly, in the assembler's coordinates.
* central finite differences for the analytic derivatives of the protocol.
* the exact second time derivative of the constraints along a quadratic path for ``gamma``.
* the linear periodic steady state (``linearize``, ``periodic``) for a nonlinear run of the
  four-bar with geometric stiffening (the projected membrane strain does not lock).
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest
import sympy as sp
from scipy.integrate import quad

import linearize
import mechanisms as mk
import periodic
from mechanisms import (
    GROUND,
    ElasticLink,
    Fem,
    Mechanism,
    PointMass,
    PrescribedDrive,
    Rayleigh,
    Revolute,
    RigidLink,
    Ritz,
    Slider,
    TorqueDrive,
    assemble,
)

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


COUPLER_RITZ = Ritz(2, 1)


def fourbar(discretisation=COUPLER_RITZ, *, stiffening=True, rotary=False, torque=False,
            young=E, gravity=GRAVITY, slot=False):
    """The thesis four-bar OABC with an elastic coupler, a point mass on it, gravity and damping;
    with ``slot`` also an elastic follower pivoted on the ground with a coupler point in its slot
    (a point on a line of a moving link, both sides elastic)."""
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
    links = (crank, coupler, rocker)
    if slot:
        links += (ElasticLink.rectangular("follower", 0.3, youngs_modulus=young,
                                          discretisation=Fem(2), boundary="clamped-free",
                                          geometric_stiffening=False, **STEEL),)
        joints += (Revolute("F", GROUND, (0.1, -0.2), "follower", "start"),
                   mk.Slot("S", "coupler", 0.2, "follower", 0.05, angle=0.1))
    return Mechanism("fourbar", links, joints, (drive,),
                     point_masses=(PointMass("coupler", POINT_MASS["x"], POINT_MASS["mass"],
                                             POINT_MASS["inertia"]),),
                     gravity=gravity)


def random_state(model, rng, *, q_scale=1e-3):
    """A random state (not on the constraint manifold: M, Q and Phi_s are defined everywhere)."""
    n = model.n_coords
    s = rng.uniform(-1.0, 1.0, n)
    s[model.rigid_index] *= 0.3
    angles = model.rigid_index[2::3]
    s[angles] = rng.uniform(-math.pi, math.pi, len(angles))
    s[model.elastic_index] *= q_scale
    sdot = rng.uniform(-1.0, 1.0, n) * 20.0
    sdot[angles] *= 10.0               # angular rates ~ 100 rad/s as in the thesis
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


S_SYM = sp.symbols("x1 y1 t1 x2 y2 t2 q1 q2 p1 x3 y3 t3", real=True)
V_SYM = sp.symbols("x1d y1d t1d x2d y2d t2d q1d q2d p1d x3d y3d t3d", real=True)
T_SYM = sp.Symbol("t", real=True)


@functools.lru_cache(maxsize=None)
def _energy_pieces(kind):
    """The four-bar's energies, split into additive pieces so that the variants share the work:
    kinetic (seed eq. 2.12 plus the rigid bars and the point mass), rotary kinetic energy of the
    coupler's sections, potential (gravity + seed eq. 2.13), the extra strain energy of geometric
    stiffening EA/2 int (eps^2 - u'^2) with the projected membrane strain eps = u' + P[w'^2/2],
    P the L2 projection onto the axial strain function (``_assemble``), the Rayleigh damping (its
    mass-proportional matrix and the Kelvin-Voigt dissipation functions of the linear and of the
    projected strain) and the constraints.
    ``kind`` is the coupler's discretisation: "ritz" (2 bending modes, 1 axial mode; elastic
    coordinates q1, q2, p1) or "fem1" (one Hermite element, seed eq. 2.5-2.8, pinned ends: the
    coordinates r0, u1, r1 stand in the places of q1, q2, p1)."""
    x1, y1, t1, x2, y2, t2, q1, q2, p1, x3, y3, t3 = S_SYM
    x1d, y1d, t1d, x2d, y2d, t2d, q1d, q2d, p1d, x3d, y3d, t3d = V_SYM
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

    def fields(xi):
        if kind == "ritz":  # seed eq. 2.14 with the modes of eq. 2.2 and 2.4, xi = x / L2
            w = q1 * sp.sin(sp.pi * xi) + q2 * sp.sin(2 * sp.pi * xi)
            u = p1 * sp.sin(sp.pi * xi / 2)
        else:               # seed eq. 2.5-2.8 with q1 = u0 = 0, q2 = w0 = 0, q5 = w1 = 0
            w = q1 * L2 * (xi - 2 * xi**2 + xi**3) + p1 * L2 * (xi**3 - xi**2)
            u = q2 * xi
        return u, w

    u, w = fields(XI)
    rates = {q1: q1d, q2: q2d, p1: p1d}
    ud, wd = u.subs(rates, simultaneous=True), w.subs(rates, simultaneous=True)
    w_x, u_x = w.diff(XI) / L2, u.diff(XI) / L2
    w_xx = w.diff(XI, 2) / L2**2
    rot2 = _rot(t2)
    local = sp.Matrix([L2 * XI + u, w])
    position = sp.Matrix([x2, y2]) + rot2 * local
    velocity = (sp.Matrix([x2d, y2d]) + t2d * rot2.diff(t2) * local
                + rot2 * sp.Matrix([ud, wd]))
    t_coupler = _integrate(sp.Rational(1, 2) * MU * velocity.dot(velocity), L2)
    t_rotary = _integrate(sp.Rational(1, 2) * 7800.0 * SECOND_MOMENT * (t2d + wd.diff(XI) / L2)**2,
                          L2)
    v_coupler = _integrate(-MU * gvec.dot(position), L2)
    v_linear = _integrate(sp.Rational(1, 2) * (E * AREA * u_x**2 + E * SECOND_MOMENT * w_xx**2), L2)
    # projected membrane strain u' + P[w'^2/2]: with one axial coordinate a (p1 for Ritz, u1 for the
    # element) u' = a Y'(x), and P f = Y' int(Y' f) / int(Y'^2), so eps = Y' (a + c) with
    # c = int(Y' w'^2/2) / int(Y'^2), and EA/2 int (eps^2 - u'^2) = EA/2 int(Y'^2) ((a + c)^2 - a^2)
    axial = p1 if kind == "ritz" else q2
    slope_axial = u_x.diff(axial)
    gram = _integrate(slope_axial**2, L2)
    c = _integrate(slope_axial * w_x**2 / 2, L2) / gram
    v_stiffening = sp.Rational(1, 2) * E * AREA * gram * ((axial + c)**2 - axial**2)

    # point mass on the coupler
    xi_m = sp.Float(POINT_MASS["x"] / L2, 30)
    u_m, w_m = fields(xi_m)
    local_m = sp.Matrix([POINT_MASS["x"] + u_m, w_m])
    position_m = sp.Matrix([x2, y2]) + rot2 * local_m
    velocity_m = position_m.jacobian(S_SYM) * sp.Matrix(V_SYM)
    omega_m = t2d + (wd.diff(XI) / L2).subs(XI, xi_m)
    t_mass = (sp.Rational(1, 2) * POINT_MASS["mass"] * velocity_m.dot(velocity_m)
              + sp.Rational(1, 2) * POINT_MASS["inertia"] * omega_m**2)
    v_mass = -POINT_MASS["mass"] * gvec.dot(position_m)

    # Rayleigh damping of the coupler's elastic coordinates: alpha M_ee (the rotary inertia is
    # left out of M_ee here and added by the caller) and Kelvin-Voigt beta as the Rayleigh
    # dissipation function D = beta/2 int (EA eps'^2 + EI w''_t^2) dx, damping force -dD/dq'.
    # Seed eq. 2.13: eps = u', so D = beta/2 q'^T K_ee q'. Projected strain: eps = Y' (a + c), so
    # eps' = Y' (a' + c') with c' = dc/dq q', and int EA eps'^2 = EA gram (a' + c')^2.
    q, qd = sp.Matrix([q1, q2, p1]), sp.Matrix([q1d, q2d, p1d])
    damping_mass = ALPHA * sp.hessian(t_coupler, qd)
    dissipation_linear = BETA * v_linear.subs(rates, simultaneous=True)
    c_rate = sum(c.diff(qk) * qdk for qk, qdk in zip(q, qd))
    bending_rate = _integrate(
        sp.Rational(1, 2) * E * SECOND_MOMENT * w_xx.subs(rates, simultaneous=True)**2, L2)
    dissipation_stiffening = BETA * (sp.Rational(1, 2) * E * AREA * gram
                                     * (rates[axial] + c_rate)**2 + bending_rate)

    # constraints (seed eq. 2.11, written for the frame coordinates)
    w_period = DRIVE["rate"]  # period 2 pi / rate: the harmonics' base frequency is the rate
    angle = DRIVE["offset"] + DRIVE["rate"] * T_SYM + sum(
        c * sp.cos(k * w_period * T_SYM) + d * sp.sin(k * w_period * T_SYM)
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
    return dict(kinetic=t_crank + t_rocker + t_coupler + t_mass, rotary=t_rotary,
                potential=v_crank + v_rocker + v_coupler + v_linear + v_mass,
                stiffening=v_stiffening, damping_mass=damping_mass,
                dissipation_linear=dissipation_linear,
                dissipation_stiffening=dissipation_stiffening, qd=qd, phi=phi)


@functools.lru_cache(maxsize=None)
def _lagrange(kind, piece):
    """Lagrange's equations (seed eq. 2.10) of one energy piece, in the protocol's form
    M s'' = Q: a kinetic piece gives M = d2T/ds'2 and Q = dT/ds - (d2T/ds'ds) s'; a potential
    piece gives M = 0 and Q = -dV/ds."""
    energy = sp.Matrix([_energy_pieces(kind)[piece]])
    s_vec, v_vec = sp.Matrix(S_SYM), sp.Matrix(V_SYM)
    if piece in ("kinetic", "rotary"):
        p = energy.jacobian(v_vec).T
        return p.jacobian(v_vec), energy.jacobian(s_vec).T - p.jacobian(s_vec) * v_vec
    return sp.zeros(12, 12), -energy.jacobian(s_vec).T


def _derive_fourbar(stiffening, rotary, *, kind="ritz", cse=False):
    """M, Q, Phi_s and Phi of the four-bar (coordinates as the assembler orders them), lambdified
    with arguments (s, s', t)."""
    pieces = _energy_pieces(kind)
    names = ["kinetic", "potential"] + (["rotary"] if rotary else []) + (
        ["stiffening"] if stiffening else [])
    mass, forces = sp.zeros(12, 12), sp.zeros(12, 1)
    for name in names:
        m, f = _lagrange(kind, name)
        mass, forces = mass + m, forces + f
    damping = pieces["damping_mass"]
    if rotary:  # Rayleigh alpha acts on the full elastic mass block, rotary inertia included
        damping = damping + ALPHA * _lagrange(kind, "rotary")[0][6:9, 6:9]
    dissipation = pieces["dissipation_stiffening" if stiffening else "dissipation_linear"]
    forces[6:9, 0] -= (damping * pieces["qd"]
                       + sp.Matrix([dissipation]).jacobian(pieces["qd"]).T)
    jac = pieces["phi"].jacobian(sp.Matrix(S_SYM))
    args = (S_SYM, V_SYM, T_SYM)
    return tuple(sp.lambdify(args, expr, cse=cse) for expr in (mass, forces, jac, pieces["phi"]))


SYMPY_CASES = {"ritz-seed-eq-2.13": ("ritz", False, False),
               "ritz-stiffening+rotary": ("ritz", True, True),
               "fem1-stiffening": ("fem1", True, False)}


@pytest.fixture(scope="module", params=list(SYMPY_CASES), ids=list(SYMPY_CASES))
def derived(request):
    kind, stiffening, rotary = SYMPY_CASES[request.param]
    discretisation = Ritz(2, 1) if kind == "ritz" else Fem(1)
    model = assemble(fourbar(discretisation, stiffening=stiffening, rotary=rotary))
    return model, _derive_fourbar(stiffening, rotary, kind=kind)


@pytest.mark.slow
def test_assembler_matches_sympy_lagrange(derived):
    """Mass matrix, force vector and constraint Jacobian of the thesis four-bar against the sympy
    derivation, to 1e-10 relative. The integrals are exact in sympy; the assembler's Gauss rule is
    exact for the Hermite element and converged to ~1e-14 for the Ritz modes; the sympy side
    evaluates with float64 after lambdify, so agreement is limited by round-off (~1e-14 times the condition of
    the sums), far below 1e-10. Each block is compared on its own scale: the velocity part of Q
    (Q(s, s') - Q(s, 0)) is ~1e4 times smaller than the elastic part, and the gravity part (q = 0,
    s' = 0) smaller still."""
    model, (mass_f, forces_f, jac_f, phi_f) = derived
    elastic = ("b1", "b2", "a1") if isinstance(model.layouts["coupler"].link.discretisation,
                                               Ritz) else ("r0", "u1", "r1")
    assert model.coord_labels == ("crank.x", "crank.y", "crank.theta", "coupler.x", "coupler.y",
                                  "coupler.theta", *(f"coupler.{e}" for e in elastic),
                                  "rocker.x", "rocker.y", "rocker.theta")
    rng = np.random.default_rng(20181)
    zero = np.zeros(model.n_coords)

    def rel(a, b):
        return np.linalg.norm(a - b) / np.linalg.norm(b)

    # elastic coordinates of 1e-3 and of 3e-2: geometric stiffening contributes ~1e-5 and ~2e-4 of
    # the static force, so at 1e-10 an error of more than ~1e-6 of the stiffening terms shows
    for q_scale in (1e-3, 1e-3, 1e-3, 3e-2, 3e-2):
        s, sdot = random_state(model, rng, q_scale=q_scale)
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


# ---------------------------------------------------------------------------------------------------
# analytic derivatives against central differences
# ---------------------------------------------------------------------------------------------------
# Central differences with step h_k = 1e-5 * scale_k (scale 1 for frame coordinates, 1e-3 for the
# elastic ones, the size of the state): truncation ~ (h/scale)^2 * |f'''| / 6 ~ 1e-11 relative,
# round-off ~ eps |f| / h ~ 1e-11 relative, so agreement to 1e-7 leaves a margin of 1e3 for the
# spread of curvature scales, while a missing or wrong term is an O(1) relative error of its block.
FD_RTOL = 1e-7

CASES = {
    "ritz-stiffening": dict(discretisation=Ritz(2, 1)),
    "fem3-rotary-torque": dict(discretisation=Fem(3), rotary=True, torque=True),
    "fem2-seed-eq-2.13": dict(discretisation=Fem(2), stiffening=False),
    # a soft coupler so that the inertia and gravity terms are not hidden behind the elastic ones
    "fem2-soft": dict(discretisation=Fem(2), young=2.0e4),
    # a pin in a slot of a moving elastic link (the frame term of the constraint kernels)
    "fem2-slot": dict(discretisation=Fem(2), slot=True),
}


@pytest.fixture(scope="module", params=list(CASES), ids=list(CASES))
def case(request):
    model = assemble(fourbar(**CASES[request.param]))
    return model, np.random.default_rng(7)


def _central_jacobian(f, x, scales, rel_step=1e-5):
    """Central differences and their round-off bound, each (m, n): 10 eps max|f| / h_k per column
    (the cancellation in f(x + h) - f(x - h) of large entries limits small ones)."""
    columns, roundoff = [], []
    for k in range(len(x)):
        h = rel_step * scales[k]
        e = np.zeros(len(x))
        e[k] = h
        plus, minus = f(x + e), f(x - e)
        columns.append((plus - minus) / (2.0 * h))
        bound = 10.0 * np.finfo(float).eps * max(np.max(np.abs(plus)), np.max(np.abs(minus))) / h
        roundoff.append(np.full(len(plus), bound))
    return np.array(columns).T, np.array(roundoff).T


def _blockwise_close(analytic, numeric_and_roundoff, model, rtol, *, all_rows=False):
    """Compare the rigid-rigid, rigid-elastic, ... blocks each on its own norm, allowing the
    truncation (rtol) and the round-off bound of the differences. ``all_rows`` for (r, n)."""
    numeric, roundoff = numeric_and_roundoff
    groups = (model.rigid_index, model.elastic_index)
    row_groups = (np.arange(analytic.shape[0]),) if all_rows else groups
    for rows in row_groups:
        for cols in groups:
            block = np.ix_(rows, cols)
            error = np.linalg.norm(analytic[block] - numeric[block])
            allowed = rtol * np.linalg.norm(numeric[block]) + np.linalg.norm(roundoff[block])
            assert error <= allowed, (f"block rows {rows[:3]}..., cols {cols[:3]}...: error "
                                      f"{error:.3e} > allowed {allowed:.3e}")


def test_derivatives_match_central_differences(case):
    model, rng = case
    n, r = model.n_coords, model.n_constraints
    scales = np.ones(n)
    scales[model.elastic_index] = 1e-3
    for _ in range(2):
        s, sdot = random_state(model, rng)
        sddot = rng.normal(size=n) * 100.0
        lam = rng.normal(size=r) * 10.0
        t = rng.uniform(0.0, 0.06)
        _blockwise_close(model.mass_matrix_jacobian(s, sddot),
                         _central_jacobian(lambda x: model.mass_matrix(x) @ sddot, s, scales),
                         model, FD_RTOL)
        d_s, d_v = model.force_jacobians(s, sdot, t)
        _blockwise_close(d_s, _central_jacobian(lambda x: model.forces(x, sdot, t), s, scales),
                         model, FD_RTOL)
        v_scales = np.abs(sdot) + 1.0
        _blockwise_close(d_v, _central_jacobian(lambda x: model.forces(s, x, t), sdot, v_scales),
                         model, FD_RTOL)
        _blockwise_close(
            model.constraint_force_jacobian(s, lam, t),
            _central_jacobian(lambda x: model.constraint_jacobian(x, t).T @ lam, s, scales),
            model, FD_RTOL)
        _blockwise_close(model.constraint_jacobian(s, t),
                         _central_jacobian(lambda x: model.constraints(x, t), s, scales),
                         model, FD_RTOL, all_rows=True)


def test_gamma_and_rate_are_time_derivatives_of_the_constraints(case):
    """Along s(tau) = s + s' tau + a tau^2 / 2 at time t + tau: dPhi/dtau = Phi_s s' + Phi_t and
    d2Phi/dtau2 = Phi_s a - gamma (protocol). Five-point differences with h = 1e-5 s: with angular
    rates w up to ~200 rad/s, |Phi^(k)| ~ w^k * 0.3 m, the truncation relative to the derivative is
    ~ (w h)^4 / 30 ~ 1e-12; round-off eps |Phi| / h^2 ~ 3e-7 m/s^2 against |Phi''| ~ w^2 0.3 m ~ 1e4
    m/s^2 (and eps |Phi| / h ~ 3e-12 m/s against |Phi'| ~ 60 m/s): 1e-6 relative is safe."""
    model, rng = case
    s, sdot = random_state(model, rng)
    a = rng.normal(size=model.n_coords) * 100.0
    t = 0.01
    h = 1e-5
    def along(tau):
        return model.constraints(s + sdot * tau + 0.5 * a * tau**2, t + tau)
    f = [along(k * h) for k in (-2, -1, 0, 1, 2)]
    first = (f[0] - 8 * f[1] + 8 * f[3] - f[4]) / (12 * h)
    second = (-f[0] + 16 * f[1] - 30 * f[2] + 16 * f[3] - f[4]) / (12 * h * h)
    jac = model.constraint_jacobian(s, t)
    expected_first = jac @ sdot + model.constraint_rate(s, t)
    expected_second = jac @ a - model.constraint_gamma(s, sdot, t)
    assert np.linalg.norm(first - expected_first) <= 1e-6 * np.linalg.norm(expected_first)
    assert np.linalg.norm(second - expected_second) <= 1e-6 * np.linalg.norm(expected_second)


def test_energies_are_consistent_with_the_equations(case):
    """T = s'^T M s' / 2; with s' = 0 the forces are -dV/ds (plus the torque drive's PD law);
    the velocity forces do no work but the damping's: s'.(Q(s, s') - Q(s, 0)) =
    -1/2 s'^T (dM/ds s') s' - s'^T C s' (Lagrange: s'.k = 1/2 s'^T Mdot s')."""
    model, rng = case
    s, sdot = random_state(model, rng)
    t = 0.02
    zero = np.zeros(model.n_coords)
    kinetic = model.kinetic_energy(s, sdot)
    assert kinetic == pytest.approx(0.5 * sdot @ model.mass_matrix(s) @ sdot, rel=1e-12)
    scales = np.ones(model.n_coords)
    scales[model.elastic_index] = 1e-3
    grad_v = _central_jacobian(lambda x: np.array([model.potential_energy(x)]), s, scales)[0][0]
    drive_force = model.forces(s, zero, t) + grad_v
    torque_driven = any(isinstance(d, TorqueDrive) for d in model.mechanism.drives)
    crank_angle = np.zeros(model.n_coords)
    crank_angle[2] = 1.0          # gradient of the drive's relative angle (ground to rigid crank)
    if torque_driven:
        drive_force -= model.drive_torques(s, zero, t)[0] * crank_angle
    assert np.linalg.norm(drive_force) <= FD_RTOL * np.linalg.norm(grad_v)
    power = sdot @ (model.forces(s, sdot, t) - model.forces(s, zero, t))
    if torque_driven:
        power -= (model.drive_torques(s, sdot, t) - model.drive_torques(s, zero, t))[0] * sdot[2]
    mdot = model.mass_matrix_jacobian(s, sdot)
    expected = -0.5 * sdot @ mdot @ sdot - model.damping_power(sdot, s)
    # an exact identity evaluated twice in float64: the sides differ by the round-off of sums
    # whose terms reach ~ |s'| |Q| ~ 1e2 * (the kinetic energy times the angular rates)
    assert power == pytest.approx(expected, rel=1e-10, abs=1e-12 * kinetic * 100)


# ---------------------------------------------------------------------------------------------------
# constraint values on known configurations, observables, bad input
# ---------------------------------------------------------------------------------------------------
def test_slider_crank_constraints_vanish_on_the_closed_form_configuration():
    """Crank r at angle phi from O, rod l whose end slides on the x-axis: x_B = r cos phi +
    sqrt(l^2 - r^2 sin^2 phi), rod angle -asin(r sin phi / l). The rod is elastic (FEM) with zero
    deflection. Phi = 0 to round-off; the drive row is the crank angle minus the law."""
    r, l, phi = 0.15, 0.30, 0.7
    crank = RigidLink.uniform("crank", r, **STEEL)
    rod = ElasticLink.rectangular("rod", l, youngs_modulus=E, discretisation=Fem(2), **STEEL)
    mech = Mechanism("slider-crank", (crank, rod),
                     (Revolute("O", GROUND, (0.0, 0.0), "crank", "start"),
                      Revolute("A", "crank", "end", "rod", "start"),
                      Slider("S", "rod", "end", origin=(0.05, 0.0), angle=0.0)),
                     (PrescribedDrive("O", rate=150.0, offset=phi),))
    model = assemble(mech)
    assert model.constraint_labels == ("O.x", "O.y", "A.x", "A.y", "S.n", "drive:O")
    beta = -math.asin(r * math.sin(phi) / l)
    s = np.zeros(model.n_coords)
    s[model.link_coordinates("crank")][:3] = (0.0, 0.0, phi)
    s[model.link_coordinates("rod")][:3] = (r * math.cos(phi), r * math.sin(phi), beta)
    assert np.max(np.abs(model.constraints(s, 0.0))) < 1e-15
    assert model.constraints(s, 1e-3)[-1] == pytest.approx(-0.15, rel=1e-12)
    # lifting the slider's line by 1 mm shows up in its row only
    lifted = assemble(Mechanism("lifted", mech.links, mech.joints[:2] + (
        Slider("S", "rod", "end", origin=(0.05, 0.001), angle=0.0),), mech.drives))
    assert lifted.constraints(s, 0.0) == pytest.approx([0, 0, 0, 0, -0.001, 0], abs=1e-15)


def test_observables_values_and_gradients():
    """Pinned-pinned coupler: deflection@f is w(fL) (the frame is the chord), moment is EI w'',
    strain u' + the element average of w'^2/2 (the projected membrane strain of linear axial
    elements; the average by scipy's adaptive quad, not the Gauss rule); gradients against central differences
    (the values are at most quadratic in q and the step is 1e-9, so differences agree to ~1e-7
    relative)."""
    model = assemble(fourbar(Fem(4)))
    rng = np.random.default_rng(3)
    s, _ = random_state(model, rng)
    shapes = model.layouts["coupler"].shapes
    q = s[model.layouts["coupler"].elastic]
    values = shapes.evaluate([0.3 * L2])
    deflection = model.observable("coupler.deflection@0.3")
    assert deflection.unit == "m"
    assert deflection.value(s) == pytest.approx(values.w[0] @ q, rel=1e-12)
    moment = model.observable("coupler.moment@0.3")
    assert moment.value(s) == pytest.approx(E * SECOND_MOMENT * values.ddw[0] @ q, rel=1e-12)
    strain = model.observable("coupler.strain@0.3")
    h = L2 / 4
    element = (h, 2 * h)                               # 0.3 L lies on the second of 4 elements
    mean_square = quad(lambda x: (shapes.evaluate([x]).dw[0] @ q) ** 2, *element,
                       epsabs=0.0, epsrel=1e-13)[0] / h
    assert strain.value(s) == pytest.approx(values.du[0] @ q + 0.5 * mean_square, rel=1e-11)
    assert model.observable("rocker.angle").value(s) == s[model.link_coordinates("rocker")][2]
    for spec in ("coupler.deflection", "coupler.strain@0.8", "coupler.moment@0.3", "rocker.angle"):
        _assert_gradient_matches_differences(model, model.observable(spec), s)


def _assert_gradient_matches_differences(model, obs, s):
    scales = np.ones(model.n_coords)
    scales[model.elastic_index] = 1e-3
    numeric, roundoff = _central_jacobian(lambda x: np.array([obs.value(x)]), s, scales,
                                          rel_step=1e-6)
    assert np.all(np.abs(obs.gradient(s) - numeric[0])
                  <= 1e-7 * np.max(np.abs(numeric)) + roundoff[0])


def test_ritz_strain_observable_is_the_projection_onto_the_axial_mode():
    """With one axial Ritz mode Y = sin(pi x / 2L) the projected membrane strain is
    Y'(x) (a + int Y' w'^2/2 / int Y'^2), the integrals by scipy's adaptive quad (independent of the
    assembler's Gauss rule); its gradient against central differences as above."""
    model = assemble(fourbar(Ritz(2, 1)))
    s, _ = random_state(model, np.random.default_rng(5), q_scale=3e-2)
    shapes = model.layouts["coupler"].shapes
    q = s[model.layouts["coupler"].elastic]
    def axial_slope(x):
        return shapes.evaluate([x]).du[0, 2]
    def slope(x):
        return shapes.evaluate([x]).dw[0] @ q
    gram = quad(lambda x: axial_slope(x) ** 2, 0.0, L2, epsabs=0.0, epsrel=1e-13)[0]
    projected = quad(lambda x: axial_slope(x) * slope(x) ** 2 / 2, 0.0, L2, epsabs=0.0,
                     epsrel=1e-13)[0] / gram
    strain = model.observable("coupler.strain@0.7")
    assert strain.value(s) == pytest.approx(axial_slope(0.7 * L2) * (q[2] + projected), rel=1e-11)
    _assert_gradient_matches_differences(model, strain, s)


def test_clamped_free_deflection_is_measured_from_the_chord():
    """A clamped-free arm bent into its first mode: the tip lies on the chord (zero deflection),
    midspan lies off it by the closed-form distance from the chord."""
    arm = ElasticLink.rectangular("arm", 0.5, youngs_modulus=E, discretisation=Ritz(1, 0),
                                  boundary="clamped-free", axial=False,
                                  geometric_stiffening=False, **STEEL)
    mech = Mechanism("arm", (arm,), (Revolute("O", GROUND, (0.0, 0.0), "arm", "start"),),
                     (PrescribedDrive("O", rate=1.0),))
    model = assemble(mech)
    s = np.array([0.0, 0.0, 0.2, 0.01])
    v = model.layouts["arm"].shapes.evaluate([0.25, 0.5])
    chord = np.array([0.5, v.w[1, 0] * 0.01])
    point = np.array([0.25, v.w[0, 0] * 0.01])
    expected = (chord[0] * point[1] - chord[1] * point[0]) / np.linalg.norm(chord)
    assert model.observable("arm.deflection@0.5").value(s) == pytest.approx(expected, rel=1e-12)
    assert model.observable("arm.deflection@1").value(s) == pytest.approx(0.0, abs=1e-15)


def _replace(mechanism, **changes):
    return Mechanism(**{**{f: getattr(mechanism, f) for f in (
        "name", "links", "joints", "drives", "point_masses", "gravity")}, **changes})


@pytest.mark.parametrize("change, culprit", [
    (lambda m: _replace(m, joints=m.joints[:1] + (
        Revolute("A", "crank", "end", "coupling", "start"),) + m.joints[2:]), "coupling"),
    (lambda m: _replace(m, drives=(PrescribedDrive("Q", rate=1.0),)), "Q"),
    (lambda m: _replace(m, links=(RigidLink("crank", -0.05, mass=0.1, inertia=1e-5),)
                        + m.links[1:]), "length"),
    (lambda m: _replace(m, joints=m.joints[:1] + (
        Revolute("A", "crank", "middle", "coupler", "start"),) + m.joints[2:]), "middle"),
    (lambda m: _replace(m, joints=m.joints[:1] + (
        Revolute("A", "crank", "end", "coupler", 0.5),) + m.joints[2:]), "0.5"),
])
def test_bad_mechanisms_are_rejected_with_the_offending_part_named(change, culprit):
    """Whether ``Mechanism`` itself or ``assemble`` catches it, the message names the culprit."""
    with pytest.raises(ValueError, match=culprit):
        assemble(change(fourbar()))


def _joints(m, index, joint):
    return m.joints[:index] + (joint,) + m.joints[index + 1:]


def _coupler(**changes):
    return ElasticLink.rectangular("coupler", L2, youngs_modulus=E, **{**STEEL, **changes})


# Every check that assemble() made a second time before it was removed, and the constructor's
# message that now catches it (assemble trusts a Mechanism: it is validated when it is made).
CONSTRUCTOR_CHECKS = {
    "link type": (lambda m: _replace(m, links=m.links + ("rod",)),
                  "links must be RigidLink or ElasticLink"),
    "link name empty": (lambda m: RigidLink("", 0.1, mass=0.1, inertia=1e-5), "link name must be"),
    "link name ground": (lambda m: RigidLink(GROUND, 0.1, mass=0.1, inertia=1e-5), "reserved"),
    "link name twice": (lambda m: _replace(m, links=m.links + (m.links[0],)),
                        "duplicate link name 'crank'"),
    "elastic length": (lambda m: ElasticLink.rectangular("coupler", -0.2, youngs_modulus=E,
                                                         **STEEL), "length must be positive"),
    "rigid mass": (lambda m: RigidLink("crank", L1, mass=0.0, inertia=1e-5),
                   "mass must be positive"),
    "rigid inertia": (lambda m: RigidLink("crank", L1, mass=0.1, inertia=-1e-5),
                      "inertia must be zero or positive"),
    "point mass link": (lambda m: _replace(m, point_masses=(PointMass("cupler", 0.1, 0.01),)),
                        "names unknown link 'cupler'"),
    "point mass mass": (lambda m: PointMass("coupler", 0.1, 0.0), "mass must be positive"),
    "point mass inertia": (lambda m: PointMass("coupler", 0.1, 0.01, -1.0),
                           "inertia must be zero or positive"),
    "point mass point": (lambda m: _replace(m, point_masses=(PointMass("coupler", 0.5, 0.01),)),
                         "distance in \\[0, 0.2794\\] m, got 0.5"),
    "point mass named point on an elastic link": (
        lambda m: _replace(m, point_masses=(PointMass("coupler", "tip", 0.01),)),
        "has no point 'tip'"),
    "joint type": (lambda m: _replace(m, joints=m.joints + ("pin",)),
                   "joints must be Revolute or Slider"),
    "joint name twice": (lambda m: _replace(m, joints=_joints(m, 1, Revolute(
        "O", "crank", "end", "coupler", "start"))), "duplicate joint name 'O'"),
    "revolute ground point": (lambda m: Revolute("O", GROUND, (0.0, math.inf), "crank", "start"),
                              "point_a \\(a ground point\\) must be a pair of finite"),
    "revolute point": (lambda m: _replace(m, joints=_joints(m, 1, Revolute(
        "A", "crank", "end", "coupler", -0.1))), "got -0.1"),
    "slider link": (lambda m: _replace(m, joints=_joints(m, 3, Slider("C", "rockr", "end"))),
                    "names unknown link 'rockr'"),
    "slider angle": (lambda m: Slider("C", "rocker", "end", angle=math.nan),
                     "angle must be a finite number"),
    "slider origin": (lambda m: Slider("C", "rocker", "end", origin=(0.0,)),
                      "origin must be a pair"),
    "drive type": (lambda m: _replace(m, drives=("motor",)),
                   "drives must be drives of a registered kind"),
    "drive joint": (lambda m: _replace(m, drives=(PrescribedDrive("Q", rate=1.0),)),
                    "drive names joint 'Q', which is not a revolute joint"),
    "drive rate": (lambda m: PrescribedDrive("O", rate=math.inf), "rate must be a finite number"),
    "drive offset": (lambda m: TorqueDrive("O", rate=1.0, offset=math.nan),
                     "offset must be a finite number"),
    "drive kp": (lambda m: TorqueDrive("O", rate=1.0, kp=-1.0), "kp must be zero or positive"),
    "drive kd": (lambda m: TorqueDrive("O", rate=1.0, kd=math.nan), "kd must be a finite number"),
    "period": (lambda m: m.replace(period=-1.0), "period must be positive"),
    "period needed": (lambda m: _replace(m, drives=(PrescribedDrive(
        "O", harmonics=((1, 0.1, 0.0),)),)), "give the period"),
    "gravity": (lambda m: _replace(m, gravity=(0.0, math.nan)),
                "gravity must be a pair of finite numbers"),
    "rayleigh": (lambda m: Rayleigh(alpha=-1.0), "alpha must be zero or positive"),
    "modal ratios": (lambda m: mk.ModalDamping((0.01, -0.02)),
                     "ratios\\[1\\] must be zero or positive"),
    "damping matrix": (lambda m: mk.DampingMatrix(((1.0, math.nan), (0.0, 1.0))),
                       "matrix\\[0\\]\\[1\\] must be a finite number"),
    "damping type": (lambda m: _coupler(damping=0.02), "damping must be Rayleigh"),
}


@pytest.mark.parametrize("check", sorted(CONSTRUCTOR_CHECKS))
def test_the_constructors_reject_what_assemble_no_longer_checks(check):
    make, message = CONSTRUCTOR_CHECKS[check]
    with pytest.raises(mk.MechanismError, match=message):
        make(fourbar())


def test_damping_sized_by_the_discretisation_is_checked_by_assemble():
    """The only damping checks left in assemble: sizes that depend on the link's discretisation."""
    too_many = fourbar().replace(links=(fourbar().links[0], _coupler(
        discretisation=Ritz(1, 1), damping=mk.ModalDamping((0.01, 0.02, 0.03))),
        fourbar().links[2]))
    with pytest.raises(mk.MechanismError, match="damping.ratios must be at most 2"):
        assemble(too_many)
    wrong = too_many.replace(links=(too_many.links[0], _coupler(
        discretisation=Ritz(1, 1), damping=mk.DampingMatrix(((1.0,),))), too_many.links[2]))
    with pytest.raises(mk.MechanismError, match=r"damping.matrix must be a \(2, 2\) matrix"):
        assemble(wrong)


def test_joint_rows_name_the_rows_kind_and_attachments():
    mechanism = mk.slider_crank(n_elements=2)
    model = assemble(mechanism)
    seen = []
    for joint in mechanism.joints:
        rows = model.joint_rows(joint.name)
        seen += rows.rows
        if isinstance(joint, Revolute):
            assert rows.kind == "revolute"
            assert [model.constraint_labels[i] for i in rows.rows] == [f"{joint.name}.x",
                                                                       f"{joint.name}.y"]
            ends = [(link, point) for link, point in ((joint.link_a, joint.point_a),
                                                      (joint.link_b, joint.point_b))
                    if link != GROUND]
        else:
            assert rows.kind == "slider"
            assert [model.constraint_labels[i] for i in rows.rows] == [f"{joint.name}.n"]
            ends = [(joint.link, joint.point)]
        assert rows.ends == tuple((link, mechanism.link(link).point_position(point))
                                  for link, point in ends)
    # every row is a joint's or a drive's, once
    assert sorted(seen + list(model.drive_rows)) == list(range(model.n_constraints))
    with pytest.raises(ValueError, match="unknown joint 'Z'"):
        model.joint_rows("Z")


def test_point_position_is_the_one_point_lookup():
    crank = RigidLink("crank", 0.1, mass=0.1, inertia=1e-5, points={"cam": (0.02, 0.01)})
    assert crank.point_position("start") == (0.0, 0.0)
    assert crank.point_position("end") == (0.1, 0.0)
    assert crank.point_position("cam") == (0.02, 0.01)
    assert crank.point_position(0.04) == (0.04, 0.0)
    assert _coupler().point_position("end") == (L2, 0.0)
    with pytest.raises(mk.MechanismError, match="has no point 'cam'"):
        _coupler().point_position("cam")
    with pytest.raises(mk.MechanismError, match="got 0.2"):
        crank.point_position(0.2)


def test_bad_call_arguments_are_rejected():
    model = assemble(fourbar())
    with pytest.raises(ValueError, match=r"s must have shape \(12,\)"):
        model.mass_matrix(np.zeros(11))
    with pytest.raises(ValueError, match="sdot must be finite"):
        model.forces(np.zeros(12), np.full(12, np.nan), 0.0)
    with pytest.raises(ValueError, match="unknown quantity 'bend'"):
        model.observable("coupler.bend@0.5")
    with pytest.raises(ValueError, match="needs an elastic link"):
        model.observable("crank.deflection")


@pytest.mark.parametrize("options", [dict(discretisation=Ritz(2, 1)),
                                     dict(discretisation=Fem(2), torque=True, rotary=True)],
                         ids=["prescribed", "torque"])
def test_power_balance_along_the_equations_of_motion(options):
    """For s'' from M s'' = Q - Phi_s^T lam (any lam) and a velocity that satisfies the velocity
    constraints Phi_s s' + Phi_t = 0: d(T + V)/dt = drive_power - damping_power exactly (the joint
    forces do no work, the drive row's multiplier is minus the drive torque). d/dt by a five-point
    difference along s + s' tau + s'' tau^2 / 2 with h = 2e-7 s: the fastest time scale is the
    axial mode (w ~ 3e4 rad/s), truncation ~ (w h)^4 ~ 1e-9; round-off ~ eps |T + V| / h ~ 1e-6 W
    against powers of ~1e5 W; 1e-7 relative leaves a margin of 10-100."""
    model = assemble(fourbar(**options))
    rng = np.random.default_rng(11)
    s, sdot = random_state(model, rng)
    t = 0.013
    jac = model.constraint_jacobian(s, t)
    # least-squares projection of the velocity onto Phi_s s' = -Phi_t
    sdot -= np.linalg.lstsq(jac, jac @ sdot + model.constraint_rate(s, t), rcond=None)[0]
    lam = rng.normal(size=model.n_constraints) * 10.0
    sddot = np.linalg.solve(model.mass_matrix(s), model.forces(s, sdot, t) - jac.T @ lam)
    h = 2e-7
    def energy(tau):
        return (model.kinetic_energy(s + sdot * tau + 0.5 * sddot * tau**2,
                                                   sdot + sddot * tau)
                              + model.potential_energy(s + sdot * tau + 0.5 * sddot * tau**2))
    e = [energy(k * h) for k in (-2, -1, 1, 2)]
    rate = (e[0] - 8 * e[1] + 8 * e[2] - e[3]) / (12 * h)
    expected = model.drive_power(s, sdot, t, lam) - model.damping_power(sdot, s)
    assert model.damping_power(sdot, s) > 0.0
    assert rate == pytest.approx(expected, rel=1e-7)


def test_multipliers_are_the_documented_reactions():
    """A uniform bar pinned at O, held at rest by a prescribed drive 0.3 rad from hanging: the pin
    force on the bar is m g upwards (lam of "O.x", "O.y" = force of link_a = ground on link_b), and
    the drive torque -lam of "drive:O" balances gravity, m g (L/2) sin(0.3) (statics)."""
    bar = RigidLink.uniform("bar", 0.4, **STEEL)
    g = 9.81
    angle = -math.pi / 2 + 0.3
    mech = Mechanism("pendulum", (bar,), (Revolute("O", GROUND, (0.0, 0.0), "bar", "start"),),
                     (PrescribedDrive("O", rate=0.0, offset=angle),), gravity=(0.0, -g),
                     period=1.0)
    model = assemble(mech)
    s, zero = np.array([0.0, 0.0, angle]), np.zeros(3)
    jac = model.constraint_jacobian(s, 0.0)
    kkt = np.block([[model.mass_matrix(s), jac.T], [jac, np.zeros((3, 3))]])
    solution = np.linalg.solve(kkt, np.concatenate([model.forces(s, zero, 0.0),
                                                    model.constraint_gamma(s, zero, 0.0)]))
    sddot, lam = solution[:3], solution[3:]
    assert np.abs(sddot).max() < 1e-12
    assert lam[:2] == pytest.approx([0.0, bar.mass * g], abs=1e-12)
    torque = bar.mass * g * 0.2 * math.sin(0.3)
    assert model.drive_torques(s, zero, 0.0, lam) == pytest.approx([torque], rel=1e-12)


def test_rigid_body_with_offset_centroid_and_named_point_mass():
    """Mass matrix of a rigid link (x, y, theta) with centroid c, inertia I_c, and a point mass m_p
    with inertia J_p at a named point p: [[m I, m A' c], [m (A' c)^T, I_c + m |c|^2]] summed over
    the two bodies (Huygens-Steiner)."""
    c, p = np.array([0.12, 0.03]), np.array([0.2, -0.05])
    link = RigidLink("plate", 0.3, mass=1.7, inertia=0.011, centroid=tuple(c),
                     points={"tip": tuple(p)})
    mech = Mechanism("plate", (link,), (Revolute("O", GROUND, (0.0, 0.0), "plate", "start"),),
                     (PrescribedDrive("O", rate=3.0),),
                     point_masses=(PointMass("plate", "tip", 0.4, 0.002),))
    model = assemble(mech)
    theta = 0.8
    rotation_prime = np.array([[-math.sin(theta), -math.cos(theta)],
                               [math.cos(theta), -math.sin(theta)]])
    expected = np.zeros((3, 3))
    for mass, inertia, where in ((1.7, 0.011, c), (0.4, 0.002, p)):
        arm = rotation_prime @ where
        expected[:2, :2] += mass * np.eye(2)
        expected[:2, 2] += mass * arm
        expected[2, :2] += mass * arm
        expected[2, 2] += inertia + mass * where @ where
    assert model.mass_matrix(np.array([0.1, -0.2, theta])) == pytest.approx(expected, rel=1e-14)


def test_torque_drive_feedforward_enters_the_forces():
    """Q(feedforward) - Q(no feedforward) = tau_ff(t) h, h the gradient of the drive angle."""
    plain = assemble(fourbar(torque=True))
    driven = assemble(fourbar(torque=True), feedforward={"O": lambda t: 2.0 + 30.0 * t})
    s, sdot = random_state(plain, np.random.default_rng(5))
    h = np.zeros(plain.n_coords)
    h[2] = 1.0
    difference = driven.forces(s, sdot, 0.1) - plain.forces(s, sdot, 0.1)
    assert difference == pytest.approx(5.0 * h, abs=1e-12 * np.abs(plain.forces(s, sdot, 0.1)).max())
    with pytest.raises(ValueError, match="has no TorqueDrive"):
        assemble(fourbar(torque=True), feedforward={"A": lambda t: 0.0})


# ---------------------------------------------------------------------------------------------------
# geometric stiffening: the nonlinear model agrees with the linearisation (no membrane locking)
# ---------------------------------------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize("n_elements", [2, 4])
def test_stiffened_nonlinear_run_matches_the_linear_steady_state(n_elements):
    """The thesis four-bar at 40 rad/s with geometric stiffening: a full nonlinear run started on
    the linear periodic steady state (at t = 0) stays on it. The linear model takes the axial force
    from the rigid inverse dynamics and adds int N Sw'^T Sw' dx, the small-deflection limit of the
    projected membrane strain; the deflection (~1 mm on a 0.28 m coupler) is small, so the peak
    midspan deflection of the last of 6 periods must agree to 2 % (0.5-0.6 % measured: finite
    deflection and axial dynamics; with the pointwise strain u' + w'^2/2 the locked nonlinear model
    differed by 22 % (2 elements) and 9 % (4 elements)). Both integrations are held to 0.2 % of the
    peak so that they cannot hide or create a 2 % difference: the steady state by its own N/2-step
    estimate, the nonlinear run by Richardson between 1024 and 512 steps per period (second order:
    error of the finer ~ |difference| / 3); measured ~5e-4 and ~4e-5 of the peak."""
    spec = "coupler.deflection@0.5"
    mechanism = mk.four_bar(discretisation="fem", n_elements=n_elements, crank_speed=40.0)
    lin = linearize.about(mechanism, n_steps=512, observables=(spec,))
    steady = periodic.steady_state(lin.system)
    linear_peak = np.abs(lin.observe(steady.x)[spec]).max()
    assert steady.error_estimate < 2e-3 * linear_peak
    s, sdot = lin.full_state(steady.x, steady.v)
    peaks = []
    for steps in (512, 1024):
        run = mk.simulate(mechanism, n_periods=6, steps_per_period=steps, s0=s[0], sdot0=sdot[0],
                          observables=[spec], estimate_error=False)
        peaks.append(np.abs(run.observables[spec][-(steps + 1):]).max())
    assert abs(peaks[1] - peaks[0]) / 3 < 2e-3 * linear_peak
    assert peaks[1] == pytest.approx(linear_peak, rel=0.02)


def test_transverse_observable_of_a_clamped_free_arm_is_the_tip_deflection_from_the_root_tangent():
    """On the two-link arm, `transverse@1.0` must equal the distance of the tip (from the model's own
    world position of the link's end pin, an independent route through the constraint kernel) from
    the root tangent line, while `deflection@1.0` (from the chord) is zero by definition."""
    import mechanisms

    mechanism = mechanisms.load("two_link_arm")
    model = assemble(mechanism)
    rng = np.random.default_rng(5)
    s, _ = random_state(model, rng)
    name = next(link.name for link in mechanism.links if getattr(link, "boundary", "")
                == "clamped-free")
    lay = model.layouts[name]
    x, y, theta = s[lay.offset:lay.offset + 3]
    q = s[lay.elastic]
    tip = lay.shapes.evaluate([lay.link.length])
    # World tip position r = R + A (L + u, w): its distance from the root tangent line.
    local = np.array([lay.link.length + tip.u[0] @ q, tip.w[0] @ q])
    c, sn = np.cos(theta), np.sin(theta)
    world = np.array([x, y]) + np.array([[c, -sn], [sn, c]]) @ local
    offset = world - np.array([x, y])
    distance = -sn * offset[0] + c * offset[1]
    transverse = model.observable(f"{name}.transverse@1.0")
    assert transverse.value(s) == pytest.approx(distance, rel=1e-12)
    assert model.observable(f"{name}.deflection@1.0").value(s) == pytest.approx(0.0, abs=1e-15)
    _assert_gradient_matches_differences(model, transverse, s)


def test_assemble_reuses_the_model_of_the_same_mechanism_object_only():
    import mechanisms

    mechanism = mechanisms.load("four_bar_fem1")
    model = assemble(mechanism)
    assert assemble(mechanism) is model
    # An equal but distinct mechanism, and any feedforward, get a model of their own.
    assert assemble(mechanisms.load("four_bar_fem1")) is not model
    torque = mechanism.replace(drives=(mechanisms.TorqueDrive("O", rate=100.0),))
    assert assemble(torque, feedforward=lambda t: 0.0) is not assemble(torque, feedforward=None)


def test_a_pin_in_a_slot_follows_the_closed_form_quick_return():
    """Whitworth's quick return: a crank pin A (radius r about O) slides in the slot along a rigid
    rocker pivoted at C, so the rocker's angle is atan2(A - C); the slot's force on the rocker is
    normal to it at A, so about C: I_C theta'' = d lam, d = |A - C|, and the force on the crank pin
    along the slot's normal is -lam (``joint.S.normal``)."""
    r, c = 0.05, (0.0, -0.15)
    rocker_inertia = 2e-4                                  # kg m^2 about its centroid
    mass, length = 0.1, 0.3
    crank = RigidLink("crank", r, mass=0.02, inertia=1e-5)
    rocker = RigidLink("rocker", length, mass=mass, inertia=rocker_inertia)
    mech = Mechanism("quick_return", (crank, rocker),
                     (Revolute("O", GROUND, (0.0, 0.0), "crank", "start"),
                      Revolute("C", GROUND, c, "rocker", "start"),
                      mk.Slot("S", "crank", "end", "rocker")),
                     (PrescribedDrive("O", rate=10.0),), initial_angles={"rocker": 1.2})
    motion = mk.nominal_motion(mech, n_steps=64)
    model = motion.model

    def closed_form(t):
        phi = 10.0 * t
        return np.arctan2(r * np.sin(phi) - c[1], r * np.cos(phi) - c[0])

    theta = motion.s[:, model.link_coordinates("rocker").start + 2]
    np.testing.assert_allclose(np.unwrap(theta), np.unwrap(closed_form(motion.t)), rtol=0, atol=1e-12)
    h = 1e-4
    f = [closed_form(motion.t + k * h) for k in (-2, -1, 0, 1, 2)]
    theta_dd = (-f[0] + 16 * f[1] - 30 * f[2] + 16 * f[3] - f[4]) / (12 * h * h)
    np.testing.assert_allclose(motion.sddot[:, model.link_coordinates("rocker").start + 2], theta_dd,
                               rtol=0, atol=1e-6 * np.abs(theta_dd).max())
    phi = 10.0 * motion.t
    d = np.hypot(r * np.cos(phi) - c[0], r * np.sin(phi) - c[1])
    pivot_inertia = rocker_inertia + mass * (length / 2) ** 2
    normal = model.observable("joint.S.normal")
    np.testing.assert_allclose([normal.value_from(lam) for lam in motion.lam],
                               -pivot_inertia * theta_dd / d, rtol=0,
                               atol=1e-6 * np.abs(pivot_inertia * theta_dd / d).max())
    assert model.joint_rows("S").kind == "slot" and not model.joint_rows("S").point_force
    assert mk.loads(mech.to_toml()).joint("S") == mech.joint("S")
