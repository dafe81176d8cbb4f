"""One step of the generalized-alpha method on the index-3 constrained equations of motion (``_Stepper``:
Newton's method on the step equations, with its numba kernels; ``_Lags``: the lagged controllers' states).

The equations (see ``_protocol.py``, seed eq. 2.10), n coordinates ``s`` and r multipliers ``lam``:

    M(s) s'' + Phi_s(s, t)^T lam = Q(s, s', t),        Phi(s, t) = 0.

Generalized-alpha (Chung & Hulbert 1993, for constrained systems Arnold & Bruls 2007, Multibody Syst.
Dyn. 18:185) advances positions ``q``, velocities ``v``, the true accelerations ``sddot`` and the
auxiliary "alpha accelerations" ``a`` from ``t_n`` to ``t_{n+1} = t_n + h``:

    (1 - alpha_m) a_{n+1} + alpha_m a_n = (1 - alpha_f) sddot_{n+1} + alpha_f sddot_n      (GA1)
    q_{n+1} = q_n + h v_n + h^2 (1/2 - beta) a_n + h^2 beta a_{n+1}                      (GA2)
    v_{n+1} = v_n + h (1 - gamma) a_n + h gamma a_{n+1}                                  (GA3)

with the equations of motion and the position constraints ``Phi(q_{n+1}, t_{n+1}) = 0`` imposed
exactly at ``t_{n+1}`` (index 3: no drift). With the spectral radius at infinity ``rho_inf`` in
[0, 1] (Chung & Hulbert eq. 25-26):

    alpha_m = (2 rho - 1) / (rho + 1),  alpha_f = rho / (rho + 1),
    gamma = 1/2 + alpha_f - alpha_m,    beta = (gamma + 1/2)^2 / 4,

which is second order for ``q`` and ``v`` and damps the unresolved (stiff, e.g. axial) modes.
Eliminating ``a_{n+1}`` leaves ``q_{n+1} = qhat + beta' sddot_{n+1}``, ``v_{n+1} = vhat + gamma'
sddot_{n+1}`` with ``beta' = h^2 beta (1 - alpha_f) / (1 - alpha_m)`` and ``gamma' = h gamma
(1 - alpha_f) / (1 - alpha_m)``; Newton's method is run on ``x = (sddot_{n+1}, lam_{n+1})`` for

    r_q = M(q) sddot + Phi_s(q)^T lam - Q(q, v, t) = 0,     r_c = Phi(q, t) / beta' = 0,     (NR)

the constraint rows divided by ``beta'`` (Arnold & Bruls sec. 3.3; Bottasso, Bauchau & Cardona 2007)
so that the iteration matrix

    [ M + beta' K_t + gamma' C_t   Phi_s^T ]     K_t = d(M sddot)/ds - dQ/ds + d(Phi_s^T lam)/ds
    [ Phi_s                        0       ]     C_t = -dQ/dsdot

stays O(1) as h -> 0 instead of having rows of size O(h^2). ``M`` and ``Phi_s`` are evaluated for
the residual at every iteration anyway, so the matrix is refactorised with them once per step; the
tangent terms ``beta' K_t + gamma' C_t`` (the model's analytic derivatives) are kept across steps
while the iteration contracts by 1/4 or better, and re-evaluated when it does not (modified Newton)
or when the previous step took more than ``REFRESH_AFTER_ITERATIONS`` iterations.

Robustness (coarse grids, stiff geometrically nonlinear links, approximately consistent starts): an
increment that grows while the matrix is not the Jacobian at the current iterate is undone and
replaced by a true Newton step; an increment larger than the configuration scale, or two growing
ones in a row, end the attempt. A failed attempt is repeated by full Newton from the constant
predictor, and a step that still fails is retried as 2, 4, ..., ``2**max_step_halvings`` equal
substeps (the alpha acceleration (GA1) carries over between steps of different sizes unchanged);
the output stays on the user's uniform grid (``_alpha_run``). ``mechanisms.simulate`` (``_simulate``) checks the
options and reports; ``_alpha_tangent`` differentiates the step for the monodromy of a run.

A model that offers ``step_kernel()`` (``Model``, with torque laws affine in s, s') runs this Newton
iteration in one numba call per attempt (``_alpha_kernel``, the same iteration line for line); the
Python iteration ``_Stepper._newton`` below serves any other ``ConstrainedModel``.
"""
from __future__ import annotations

import contextlib
import math

import numba
import numpy as np

from periodic import lapack

from . import _alpha_kernel
from ._alpha_kernel import _fill_iteration_matrix, _newton_update
from ._parts import ArgumentError

#: Whether a model that offers ``step_kernel()`` (``Model``) is stepped by the fused kernel
#: (``_alpha_kernel``): True, False, or "auto" (``fused_step_wanted``: when the kernel is compiled
#: already, in this process or in numba's disk cache, or the run is long enough to repay its compile).
#: The Python iteration below stays for any other ``ConstrainedModel`` and for torque laws the kernel
#: does not evaluate (tests set True and False to compare the two).
FUSED_STEP = "auto"
#: Steps of one run from which "auto" compiles the fused kernel on a cold cache: its compile, about
#: 12-19 s CPU beside the Python iteration's kernels (which every run needs anyway: the start,
#: the substeps' fallback), is repaid at about 0.5 ms saved a step (docs/benchmarks.md). A shorter
#: run on a cold cache (the main job's nonlinear check) keeps the Python iteration, so the first
#: run's compile time does not grow by it; once compiled (a long run, a run-up), every run uses it.
FUSED_COMPILE_STEPS = 20000
#: A step that took more iterations than this starts the next one with fresh tangent terms (the
#: Jacobian at its predictor) instead of the kept ones. From a kept tangent that still contracts
#: well a step takes two iterations (an increment and the one below ``tol`` that confirms it); a
#: third says the kept terms have gone stale, and the next step, much like this one, would repeat
#: that with them. On four_bar_fem4's run-up (benchmarks/bench_run_up.py) the runs at dt, 2 dt and
#: 4 dt took 2.9, 4.4 and 8.2 iterations a step with the tangent kept across steps and 2.4, 3.3
#: and 5.7 with this rule, 0.69-0.77 of their CPU time (docs/benchmarks.md, session 8).
REFRESH_AFTER_ITERATIONS = 2


@contextlib.contextmanager
def fused_step(mode: bool | str = True):
    """``with mechanisms.fused_step(True): ...`` steps the runs inside by the fused kernel (``False``:
    the Python iteration; ``"auto"``: the default rule, ``FUSED_STEP``), and restores the setting
    after. The studies whose runs are many (nonlinear states, sweeps, run-ups) compile the kernel in
    their JIT warm-up this way, so that their runs take it under "auto"."""
    global FUSED_STEP
    if mode not in (True, False, "auto"):
        raise ArgumentError(f"fused_step: expected True, False or 'auto', got {mode!r}")
    previous, FUSED_STEP = FUSED_STEP, mode
    try:
        yield
    finally:
        FUSED_STEP = previous


@contextlib.contextmanager
def fused_step_for(total_steps: int):
    """``with mechanisms.fused_step_for(total): ...``: under "auto", the runs inside take the fused
    kernel when together they step ``total`` times or more (``FUSED_COMPILE_STEPS``): a study of many
    short runs (a nonlinear sweep: some 50 orbits of about 8 periods each) repays the compile as one
    long run does. A setting of True or False (``fused_step``) is kept."""
    mode = True if FUSED_STEP == "auto" and total_steps >= FUSED_COMPILE_STEPS else FUSED_STEP
    with fused_step(mode):
        yield


def fused_step_wanted(n_steps: int) -> bool:
    """Whether a run of ``n_steps`` steps takes the fused kernel under ``FUSED_STEP``. The two paths
    agree to round-off (bitwise without torque drives; tests/test_alpha_kernel.py)."""
    if FUSED_STEP != "auto":
        return bool(FUSED_STEP)
    return n_steps >= FUSED_COMPILE_STEPS or _alpha_kernel.compiled()


# The iteration matrix (n + r ~ 20-70) is factorised once and reused over a modified-Newton
# iteration, and its pivots give ``min_pivot_ratio``. LAPACK's dgetrf / dgetrs (``periodic.lapack``, the
# packages' one binding) do the work; numba's np.linalg.solve, which factorises and copies at every solve, made
# the thesis four-bar's runs 14-18 % slower (20 revolutions at 125 and 400 steps per period), whereas direct
# dgetrf / dgetrs calls cost 0-4 % (125) and 3-10 % (400) against the hand-written LU they replaced (medians
# of interleaved runs; a cold OpenBLAS call takes ~2-3 us more). The matrix is built transposed
# (``periodic.lapack``'s order).
@numba.njit(cache=True, no_cfunc_wrapper=True)
def _lu_factor(G_T, piv):
    """``P G = L U`` of the iteration matrix G whose transpose ``G_T`` (n, n) is given (``periodic.lapack``'s
    convention; LAPACK dgetrf), in place; ``piv`` (n,) int32 receives the pivots.

    Returns ``min |u_kk| / max |u_kk|`` (0.0 when a pivot is exactly zero) as a cheap singularity
    indicator."""
    if not lapack.factor_lapack(G_T, piv):
        return 0.0  # info > 0: u_kk exactly zero at k = info
    return lapack.pivot_ratio(G_T)


@numba.njit(cache=True, no_cfunc_wrapper=True)
def _tangent_terms(dMa_ds, dQ_ds, dQ_dv, dPhiTlam_ds, beta_p, gamma_p, out):
    """``beta' K_t + gamma' C_t`` of (NR), the part of the Newton matrix kept across iterations."""
    n = dMa_ds.shape[0]
    for i in range(n):
        for j in range(n):
            out[i, j] = (beta_p * (dMa_ds[i, j] - dQ_ds[i, j] + dPhiTlam_ds[i, j])
                         - gamma_p * dQ_dv[i, j])


@numba.njit(cache=True, no_cfunc_wrapper=True)
def _max_abs(x):
    """``max |x_i|`` (0 for an empty array, NaN if any entry is NaN)."""
    out = 0.0
    for i in range(x.shape[0]):
        if not abs(x[i]) <= out:
            out = abs(x[i])
            if np.isnan(out):
                return out
    return out


@numba.njit(cache=True, no_cfunc_wrapper=True)
def _start_step(q, v, a, sddot_n, lam_n, sddot_prev, lam_prev, extrapolate, h, alpha_m, alpha_f,
                beta, gamma, beta_p, gamma_p, qhat, vhat, sddot, lam, q_new, v_new):
    """Predictor of the step from ``t_n``: the parts of (GA2), (GA3) known at ``t_n`` (``a_{n+1}``
    from (GA1) split into its known part ``(alpha_f sddot_n - alpha_m a_n) / (1 - alpha_m)`` and
    ``(1 - alpha_f) / (1 - alpha_m) sddot_{n+1}``), the guess of ``sddot_{n+1}, lam_{n+1}`` (linear
    extrapolation from ``t_{n-1}, t_n``, or the values at ``t_n``) and the positions and velocities
    ``q = qhat + beta' sddot``, ``v = vhat + gamma' sddot`` it implies."""
    for i in range(q.shape[0]):
        a_known = (alpha_f * sddot_n[i] - alpha_m * a[i]) / (1.0 - alpha_m)
        qhat[i] = q[i] + h * v[i] + h * h * ((0.5 - beta) * a[i] + beta * a_known)
        vhat[i] = v[i] + h * ((1.0 - gamma) * a[i] + gamma * a_known)
        sddot[i] = 2.0 * sddot_n[i] - sddot_prev[i] if extrapolate else sddot_n[i]
        q_new[i] = qhat[i] + beta_p * sddot[i]
        v_new[i] = vhat[i] + gamma_p * sddot[i]
    for k in range(lam.shape[0]):
        lam[k] = 2.0 * lam_n[k] - lam_prev[k] if extrapolate else lam_n[k]


@numba.njit(cache=True, no_cfunc_wrapper=True)
def _advance_alpha_acceleration(a, sddot_old, sddot_new, alpha_m, alpha_f):
    """(GA1) solved for ``a_{n+1}``, in place."""
    for i in range(a.shape[0]):
        a[i] = (alpha_f * sddot_old[i] + (1.0 - alpha_f) * sddot_new[i] - alpha_m * a[i]) / (
            1.0 - alpha_m)


def _generalized_alpha_parameters(rho_inf: float) -> tuple[float, float, float, float]:
    """(alpha_m, alpha_f, beta, gamma) of Chung & Hulbert (1993) eq. 25-26 for ``rho_inf``."""
    alpha_m = (2.0 * rho_inf - 1.0) / (rho_inf + 1.0)
    alpha_f = rho_inf / (rho_inf + 1.0)
    gamma = 0.5 + alpha_f - alpha_m
    beta = 0.25 * (gamma + 0.5) ** 2
    return alpha_m, alpha_f, beta, gamma


class _Stepper:
    """Newton's method on (NR) for one step of any size from a given state, with the buffers, the
    kept tangent terms and the counts shared by all steps of a run."""

    def __init__(self, model, rho, abs_tol, max_iterations, jacobian_reuse, length_scale, fused=True):
        self.model = model
        # a Newton increment larger than the configuration itself is outside the region of
        # convergence: Newton from there found spurious roots of the step equations (positions of
        # 1e3 m on the four-bar scene at 16 steps per period)
        self.max_increment = length_scale
        self.alpha_m, self.alpha_f, self.beta, self.gamma = _generalized_alpha_parameters(rho)
        self.abs_tol, self.max_iterations, self.jacobian_reuse = abs_tol, max_iterations, \
            jacobian_reuse
        n, r = int(model.n_coords), int(model.n_constraints)
        # the Newton iterates (updated in place); after a converged solve, the new state
        self.q, self.v, self.sddot, self.lam = np.empty(n), np.empty(n), np.empty(n), np.empty(r)
        self.qhat, self.vhat = np.empty(n), np.empty(n)
        self.sddot_before, self.lam_before = np.empty(n), np.empty(r)
        self.rhs = np.empty(n + r)
        self.G = np.empty((n + r, n + r))
        self.tangent = np.empty((n, n))
        self.piv = np.empty(n + r, dtype=np.int32)
        self.tangent_h = None      # the step the kept tangent terms were scaled with, or None
        self.last_iterations = 0   # Newton iterations of the last step solved (all its attempts)
        self.residual = np.nan     # max |Phi| at the last converged solve
        self._counts = {"n_newton": 0, "n_jacobian": 0, "n_factorizations": 0}   # Python iteration's
        self.min_pivot_ratio = np.inf
        # lagged controllers' states, integrated with the step (None without lags)
        self.lags = _Lags(model) if len(getattr(model, "lag_names", ())) else None
        self.t = np.nan            # the time of the last step solved
        # the fused step's: its counts (as ``_counts``, added up by the kernel) and its numbers
        self.kernel_counts = np.zeros(3, dtype=np.int64)
        self.kernel_info = np.zeros(4)
        make_kernel = getattr(model, "step_kernel", None) if fused else None
        self.kernel = make_kernel() if make_kernel is not None else None
        self._kernel_arguments = self.kernel.bind(self) if self.kernel is not None else ()

    @property
    def counts(self):
        """Newton iterations, Jacobian evaluations and factorisations of all steps so far."""
        return {key: value + int(self.kernel_counts[k])
                for k, (key, value) in enumerate(self._counts.items())}

    def drop_tangent(self):
        self.tangent_h = None

    def solve(self, q_n, v_n, a_n, sddot_n, lam_n, sddot_prev, lam_prev, extrapolate, t, h,
              full_newton=False):
        """The step from ``t - h`` (state ``q_n, v_n``, alpha acceleration ``a_n``, ``sddot_n``,
        ``lam_n``) to ``t``. The predictor extrapolates linearly from ``sddot_prev, lam_prev`` (at
        ``t - 2h``) when ``extrapolate``; if modified Newton fails from it, the step is solved once
        more by full Newton (Jacobian at every iterate) from the constant predictor, the most
        robust variant on the stiff, geometrically nonlinear links (on the shipped six-bar and
        four-bar scenes modified Newton failed at coarse steps where full Newton converged).
        Returns "" on success (new state in ``q, v, sddot, lam``), else what went wrong."""
        alpha_m, alpha_f, beta, gamma = self.alpha_m, self.alpha_f, self.beta, self.gamma
        beta_p = h * h * beta * (1.0 - alpha_f) / (1.0 - alpha_m)
        gamma_p = h * gamma * (1.0 - alpha_f) / (1.0 - alpha_m)
        if self.tangent_h != h or self.last_iterations > REFRESH_AFTER_ITERATIONS:
            self.tangent_h = None
        iterations_before = self._counts["n_newton"] + int(self.kernel_counts[0])
        self.t = t
        if self.lags is not None:
            self.lags.begin(h)
        newton = self._newton
        if self.kernel is not None:
            self.kernel.at(t, self.lags)
            newton = self._fused_newton
        full_newton = full_newton or not self.jacobian_reuse
        failure = ""
        for _attempt in range(2):
            failure = newton(q_n, v_n, a_n, sddot_n, lam_n, sddot_prev, lam_prev,
                                   extrapolate, t, h, beta_p, gamma_p, full_newton)
            if not failure:
                if full_newton:
                    self.tangent_h = None
                break
            self.tangent_h = None
            if full_newton and not extrapolate:
                break           # the retry would repeat this attempt exactly
            extrapolate, full_newton = False, True
        self.last_iterations = self._counts["n_newton"] + int(self.kernel_counts[0]) - iterations_before
        return failure

    def _fused_newton(self, q_n, v_n, a_n, sddot_n, lam_n, sddot_prev, lam_prev, extrapolate, t, h,
                      beta_p, gamma_p, full_newton):
        """``_newton`` in one call of the model's ``StepKernel`` (its terms at ``t`` set by ``solve``)."""
        code, tangent_valid, iterations = _alpha_kernel.newton(
            q_n, v_n, a_n, sddot_n, lam_n, sddot_prev, lam_prev, extrapolate, h, beta_p, gamma_p,
            full_newton, self.tangent_h is not None, *self._kernel_arguments)
        self.tangent_h = h if tangent_valid else None
        if code:
            return _alpha_kernel.failure_message(code, iterations, self.kernel_info)
        self.residual = self.kernel_info[0]
        self.min_pivot_ratio = min(self.min_pivot_ratio, self.kernel_info[1])
        return ""

    def _newton(self, q_n, v_n, a_n, sddot_n, lam_n, sddot_prev, lam_prev, extrapolate, t, h,
                beta_p, gamma_p, full_newton):
        model, abs_tol, max_iterations = self.model, self.abs_tol, self.max_iterations
        q, v, sddot, lam, qhat, vhat = self.q, self.v, self.sddot, self.lam, self.qhat, self.vhat
        G, piv, tangent, counts = self.G, self.piv, self.tangent, self._counts
        _start_step(q_n, v_n, a_n, sddot_n, lam_n, sddot_prev, lam_prev, extrapolate, h,
                    self.alpha_m, self.alpha_f, self.beta, self.gamma, beta_p, gamma_p, qhat, vhat,
                    sddot, lam, q, v)
        factorized = False
        iterations, prev_dq, phi_scale = 0, np.inf, 1.0
        candidate, growths = False, 0
        min_pivot_ratio = np.inf
        while True:
            Phi = np.ascontiguousarray(model.constraints(q, t), dtype=np.float64)
            if candidate:
                # the increments say converged; accept if the constraints agree to tol as well
                step_residual = _max_abs(Phi)
                if step_residual <= abs_tol * phi_scale:
                    self.residual = step_residual
                    self.min_pivot_ratio = min(self.min_pivot_ratio, min_pivot_ratio)
                    return ""
                candidate = False
                if iterations >= max_iterations:
                    return (f"the constraint residual stalled at {step_residual:.3g} > "
                            f"{abs_tol * phi_scale:.3g} after {iterations} iterations (`tol` "
                            "below round-off?)")
            M = np.ascontiguousarray(model.mass_matrix(q), dtype=np.float64)
            Q = np.ascontiguousarray(model.forces(q, v, t), dtype=np.float64)
            if self.lags is not None:
                Q = Q + self.lags.force(q, v, t)
            Phi_s = np.ascontiguousarray(model.constraint_jacobian(q, t), dtype=np.float64)
            exact = self.tangent_h is None    # the matrix will be the Jacobian at this iterate
            if exact:
                dQ_ds, dQ_dv = model.force_jacobians(q, v, t)
                if self.lags is not None:
                    dQ_ds, dQ_dv = self.lags.add_force_jacobians(q, v, t, dQ_ds, dQ_dv)
                _tangent_terms(
                    np.ascontiguousarray(model.mass_matrix_jacobian(q, sddot), dtype=np.float64),
                    np.ascontiguousarray(dQ_ds, dtype=np.float64),
                    np.ascontiguousarray(dQ_dv, dtype=np.float64),
                    np.ascontiguousarray(model.constraint_force_jacobian(q, lam, t),
                                         dtype=np.float64),
                    beta_p, gamma_p, tangent)
                counts["n_jacobian"] += 1
                self.tangent_h = h
                factorized = False
            if not factorized:
                # M and Phi_s are evaluated for the residual anyway: the matrix takes them fresh
                # once per step (they rotate with the links) and keeps the O(h) tangent terms,
                # which are re-evaluated only when the iteration contracts slowly
                phi_scale = _fill_iteration_matrix(M, tangent, Phi_s, G)
                pivot_ratio = _lu_factor(G, piv)
                counts["n_factorizations"] += 1
                factorized = True
                min_pivot_ratio = min(min_pivot_ratio, pivot_ratio)
                if not pivot_ratio > 0.0:
                    return ("the iteration matrix is singular (zero pivot): check for redundant "
                            "constraints or a toggle position")
            self.sddot_before[:], self.lam_before[:] = sddot, lam
            dq = _newton_update(G, piv, M, sddot, Phi_s, lam, Q, Phi, qhat, vhat, beta_p, gamma_p,
                                self.rhs, q, v)
            counts["n_newton"] += 1
            iterations += 1
            # contraction of the increments (Hairer & Wanner II, sec. IV.8), across refactorisations
            theta = dq / prev_dq if math.isfinite(prev_dq) and prev_dq > 0.0 else 0.0
            if not math.isfinite(dq):
                # NaN or inf anywhere in M, Q, Phi, Phi_s or the matrix reaches the increment
                return "the Newton increment is not finite (non-finite model output?)"
            # error left in the iterate: about theta |dq| < |dq| / 4 (see below). The cheaper test
            # theta / (1 - theta) |dq| <= tol (Hairer & Wanner II, sec. IV.8) was tried and
            # accepted errors of ~100 tol in the elastic coordinates: a stale matrix contracts
            # unevenly over 2-3 iterates. A candidate is accepted once Phi at it is also below tol
            # times the row sums of Phi_s (checked above, in the evaluation the next iteration
            # would need anyway).
            if dq <= abs_tol:
                candidate = True
                continue
            if iterations >= max_iterations:
                return (f"Newton's method did not converge in {iterations} iterations (last "
                        f"position increment {dq:.3g}, tolerance {abs_tol:.3g})")
            wild = dq > self.max_increment
            if wild and exact:
                return (f"Newton's method diverged (position increment {dq:.3g} larger than the "
                        f"configuration scale {self.max_increment:.3g})")
            if (theta > 1.0 or wild) and not exact:
                # a growing increment from a matrix evaluated elsewhere (an earlier iterate or
                # step): on strongly nonlinear links (geometric stiffening couples the stiff axial
                # and the bending coordinates) one such increment can throw the iterate out of
                # Newton's region of convergence (the arm and four-bar scenes did). Undo it and
                # take a true Newton step from the previous iterate instead.
                sddot[:], lam[:] = self.sddot_before, self.lam_before
                np.add(qhat, beta_p * sddot, out=q)
                np.add(vhat, gamma_p * sddot, out=v)
                self.tangent_h = None
                continue
            prev_dq = dq
            # growing increments with the exact Jacobian: outside Newton's region of convergence;
            # two in a row end the attempt (the caller then retries with a smaller step) instead
            # of iterating to overflow
            growths = growths + 1 if theta > 1.0 else 0
            if growths >= 2:
                return f"Newton's method diverged (position increment {dq:.3g})"
            # contracting too slowly: re-evaluate the matrix at this iterate. An evaluation costs
            # about one iteration, and at theta = 0.25 the stale matrix gains only 0.6 digits per
            # iteration, whereas a fresh one converges quadratically.
            if theta > 0.25 or full_newton:
                self.tangent_h = None

    def advance_alpha_acceleration(self, a, sddot_old):
        """(GA1) for the step just solved: ``a`` becomes ``a_{n+1}``; the lag states move on with it."""
        _advance_alpha_acceleration(a, sddot_old, self.sddot, self.alpha_m, self.alpha_f)
        if self.lags is not None:
            self.lags.commit(self.q, self.v, self.t)


class _Lags:
    """The states ``y`` (N m) of a model's lagged controllers, ``tau y' + y = u(t, s, s')``
    (``Model.lag_inputs_along``), integrated with each step by the trapezoidal rule (order 2, A-stable,
    as the generalized-alpha step):

        y_{n+1} = ((1 - r) y_n + r (u_n + u_{n+1})) / (1 + r),     r = h / (2 tau),

    implicit in the step's unknowns through ``u_{n+1}``: Newton's forces get ``h_i y_{n+1}`` and its
    Jacobians ``h_i r / (1 + r) du/ds`` (and ``du/ds'``), so the step solves the mechanism and its
    lags together.  ``y`` starts at 0 (the lag at rest; ``u`` is 0 on the nominal motion)."""

    def __init__(self, model):
        self.model = model
        self.tau = np.asarray(model.lag_time_constants, dtype=float)
        self.gradients = np.asarray(model.lag_gradients, dtype=float)   # (L, n)
        self.y = np.zeros(self.tau.size)
        self.u = None              # the input at the committed state (None before the first step)
        self.ratio = np.zeros(self.tau.size)
        self.history = [self.y.copy()]

    def _input(self, q, v, t):
        u, du_ds, du_dv = self.model.lag_inputs_along(np.array([t], dtype=float), q[None], v[None])
        return u[0], du_ds[0], du_dv[0]

    def start(self, q, v, t, y0=None):
        """The states ``y0`` (default 0) and the input at the initial state (once, before the first step)."""
        if y0 is not None:
            self.y = np.array(y0, dtype=float)
            self.history = [self.y.copy()]
        self.u = self._input(q, v, t)[0]

    def begin(self, h):
        self.ratio = 0.5 * h / self.tau

    def _next(self, u_new):
        r = self.ratio
        return ((1.0 - r) * self.y + r * (self.u + u_new)) / (1.0 + r)

    def force(self, q, v, t):
        """``sum_i h_i y_{n+1, i}`` (n,) at the iterate ``q, v`` of the step to ``t``."""
        return self._next(self._input(q, v, t)[0]) @ self.gradients

    def add_force_jacobians(self, q, v, t, dQ_ds, dQ_dv):
        _, du_ds, du_dv = self._input(q, v, t)
        weights = self.gradients.T * (self.ratio / (1.0 + self.ratio))    # (n, L)
        return dQ_ds + weights @ du_ds, dQ_dv + weights @ du_dv

    def commit(self, q, v, t):
        """The step to ``t`` converged at ``q, v``: move the states on."""
        u_new = self._input(q, v, t)[0]
        self.y, self.u = self._next(u_new), u_new

    def snapshot(self):
        return self.y.copy(), self.u.copy()

    def restore(self, saved):
        self.y, self.u = saved[0].copy(), saved[1].copy()
