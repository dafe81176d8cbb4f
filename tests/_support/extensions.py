"""Extensions of flexvib written as a user would write them: outside the packages, with their public
faces only (``periodic``, ``mechanisms``, ``studies``), each registered when this module is imported.

* ``Gear``: a joint, a fixed ratio between the material angles of two links (one
  ``mechanisms.AngleRow``, no new kernel), ``mechanisms.register_joint``;
* ``Legendre``: a link discretisation, a Ritz basis of Legendre polynomials for pinned-pinned links,
  ``mechanisms.register_discretisation``; ``bending_1``, ``bending_2``, ``axial_1``: the first of its
  shapes as module-level functions, for ``mechanisms.UserShapes``;
* ``curvature``, ``slope``, ``chord_angle``: observables, ``mechanisms.register_observable``;
* ``PeakTable``, ``peak_table``, ``KIND``: a study kind ("peak_table": the steady state's peak to peak
  of each observable at a few speeds), ``studies.register_kind``;
* ``ThetaMethod``, ``THETA_SCHEMES``: a periodic scheme in numpy ("theta-0.6", "theta-0.5"),
  ``periodic.register_scheme``;
* ``GaugedPD``: a controller, ``mechanisms.register_controller``;
* ``ServoDrive``: a drive kind, a torque drive tuned by its closed-loop bandwidth,
  ``mechanisms.register_drive``.

The tests ``tests/test_extend_*.py`` check each against what does not know of it;
``tests/test_extension.py`` runs them together, and checks that this module imports public names
only (no edit to any package was needed).
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from typing import Any, ClassVar, Mapping

import numpy as np
from numpy.polynomial import legendre

import mechanisms
import periodic
import studies

#: The studies' scheme when a table names none (``studies.steady_state``'s default).
TRAPEZOIDAL = "trapezoidal"


# ---------------------------------------------------------------------------------------------------
# a joint: the gear pair
# ---------------------------------------------------------------------------------------------------
@mechanisms.register_joint
@dataclass(frozen=True)
class Gear:
    """A gear pair: ``theta_b + ratio theta_a - offset = 0`` between the material angles of two
    links at their points; its force is the torque (N m) on ``link_b``."""

    name: str
    link_a: str
    point_a: Any
    link_b: str
    point_b: Any
    ratio: float
    offset: float = 0.0

    TYPE: ClassVar[str] = "gear"
    KEYS: ClassVar[tuple[str, ...]] = ("type", "link_a", "point_a", "link_b", "point_b", "ratio",
                                       "offset")
    n_equations: ClassVar[int] = 1
    point_force: ClassVar[bool] = False     # it transmits a moment
    force_unit: ClassVar[str] = "N m"

    @classmethod
    def from_table(cls, name, table):
        return cls(name, table.string("link_a"), table.point("point_a"), table.string("link_b"),
                   table.point("point_b"), table.number("ratio", "1"),
                   table.number("offset", "rad", 0.0))

    def to_table(self):
        return {"type": self.TYPE, "link_a": self.link_a, "point_a": self.point_a,
                "link_b": self.link_b, "point_b": self.point_b, "ratio": self.ratio,
                "offset": self.offset}

    @property
    def ends(self):
        return ((self.link_a, self.point_a), (self.link_b, self.point_b))

    def constraint_rows(self):
        return (mechanisms.AngleRow("ratio", (mechanisms.AngleTerm(self.link_b, self.point_b, 1.0),
                                              mechanisms.AngleTerm(self.link_a, self.point_a,
                                                                   self.ratio)),
                                    -self.offset),)

    def force_components(self):
        # the generalized force of the row on theta_b is -dPhi/dtheta_b lam = -lam
        return {"torque": (-1.0,)}

    def drive_terms(self):
        return None

    def coincident_points(self):
        return ()


# ---------------------------------------------------------------------------------------------------
# a discretisation: the Legendre Ritz basis
# ---------------------------------------------------------------------------------------------------
def _legendre_shape(coefficients, x, length):
    """Value, d/dx, d2/dx2 of the Legendre series ``coefficients`` in ``xi = 2 x / L - 1``."""
    h = 2.0 / length
    xi = h * np.asarray(x, dtype=float) - 1.0
    return (legendre.legval(xi, coefficients), h * legendre.legval(xi, legendre.legder(coefficients)),
            h * h * legendre.legval(xi, legendre.legder(coefficients, 2)))


def _bending_coefficients(k):
    """``P_{k+2} - P_k``: zero at both ends, since ``P_n(+-1) = (+-1)^n``."""
    c = np.zeros(k + 3)
    c[k + 2], c[k] = 1.0, -1.0
    return c


def _axial_coefficients(j):
    """``P_{j+1} + P_j``: zero at the start (``xi = -1``)."""
    c = np.zeros(j + 2)
    c[j + 1] = c[j] = 1.0
    return c


@mechanisms.register_discretisation
@dataclass(frozen=True)
class Legendre:
    """Legendre Ritz basis of a pinned-pinned link: ``n_bending`` bending and ``n_axial`` axial
    shapes."""

    n_bending: int = 4
    n_axial: int = 1

    TYPE: ClassVar[str] = "legendre"
    KEYS: ClassVar[tuple[str, ...]] = ("type", "n_bending", "n_axial")
    check_boundary: ClassVar[bool] = True

    @classmethod
    def from_table(cls, table):
        return cls(table.integer("n_bending", 4, minimum=1, maximum=40, why="Legendre test basis"),
                   table.integer("n_axial", 1, minimum=0, maximum=40, why="Legendre test basis"))

    def to_table(self):
        return {"type": self.TYPE, "n_bending": self.n_bending, "n_axial": self.n_axial}

    def layout(self, link, attachments=None):
        if link.boundary != "pinned-pinned":
            raise mechanisms.MechanismError(f"link {link.name!r}: the Legendre basis is for "
                                            f"pinned-pinned links, got {link.boundary!r}")
        n_axial = self.n_axial if link.axial else 0
        return mechanisms.ShapeLayout(tuple(f"b{i + 1}" for i in range(self.n_bending))
                                      + tuple(f"a{j + 1}" for j in range(n_axial)))

    def values(self, link, x, basis=None):
        m, nb = len(x), self.n_bending
        na = self.n_axial if link.axial else 0
        u, du, w, dw, ddw = (np.zeros((m, nb + na)) for _ in range(5))
        for k in range(nb):
            w[:, k], dw[:, k], ddw[:, k] = _legendre_shape(_bending_coefficients(k), x, link.length)
        for j in range(na):
            u[:, nb + j], du[:, nb + j], _ = _legendre_shape(_axial_coefficients(j), x, link.length)
        return mechanisms.ShapeValues(u, du, w, dw, ddw)

    def refined(self):
        """Two more polynomial degrees of each kind (the optional refinement the studies' mesh
        term reads); no ``convergence_order``: the polynomial basis converges faster than any
        power of a size, and the mesh term observes its rate from three levels."""
        return Legendre(self.n_bending + 2, self.n_axial + 2 if self.n_axial else 0)


# the same shapes as module-level functions, for UserShapes (a scene names them module:qualname)
def bending_1(x, length):
    return _legendre_shape(_bending_coefficients(0), x, length)


def bending_2(x, length):
    return _legendre_shape(_bending_coefficients(1), x, length)


def axial_1(x, length):
    return _legendre_shape(_axial_coefficients(0), x, length)


# ---------------------------------------------------------------------------------------------------
# observables: curvature, slope, chord angle
# ---------------------------------------------------------------------------------------------------
def _section(model, link, fraction):
    """The link's layout and its shape functions at ``fraction`` of its length; a rigid link is
    refused (the message reaches the user with the spec)."""
    layout = model.layouts[link]
    if layout.shapes is None:
        raise ValueError(f"link {link!r} is rigid: it does not bend")
    return layout, layout.shapes.evaluate([fraction * layout.link.length])


def _linear_in_q(model, layout, rows):
    """value = rows . q (q the link's elastic coordinates), gradient constant."""
    def value(s):
        return float(rows @ s[layout.elastic])

    def gradient(s):
        out = np.zeros(model.n_coords)
        out[layout.elastic] = rows
        return out

    return value, gradient


def curvature(model, link, fraction):
    """w''(x) (1/m) in the link's frame, x = fraction L."""
    layout, shapes = _section(model, link, fraction)
    return _linear_in_q(model, layout, shapes.ddw[0])


def slope(model, link, fraction):
    """w'(x) (1) in the link's frame, x = fraction L."""
    layout, shapes = _section(model, link, fraction)
    return _linear_in_q(model, layout, shapes.dw[0])


def chord_angle(model, link, fraction):
    """The global angle (rad) of the chord from the link's start to its deformed tip:
    theta + atan2(w(L), L + u(L)), nonlinear in the elastic coordinates."""
    layout, tip = _section(model, link, 1.0)
    length, u, w = layout.link.length, tip.u[0], tip.w[0]
    theta = layout.coords.start + 2

    def value(s):
        q = s[layout.elastic]
        return float(s[theta] + math.atan2(w @ q, length + u @ q))

    def gradient(s):
        q = s[layout.elastic]
        cx, cy = length + u @ q, w @ q
        out = np.zeros(model.n_coords)
        out[theta] = 1.0
        out[layout.elastic] = (cx * w - cy * u) / (cx * cx + cy * cy)
        return out

    return value, gradient


mechanisms.register_observable("curvature", curvature, unit="1/m", elastic_only=True)
mechanisms.register_observable("slope", slope, unit="1", elastic_only=True)
mechanisms.register_observable("chord_angle", chord_angle, unit="rad", at_point=False)


# ---------------------------------------------------------------------------------------------------
# a study kind: the peak table
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class PeakTable(studies.StudyResult):
    """Peak to peak of each observable of the steady state at each speed.

    Attributes
    ----------
    problem : str
        The problem's name.
    speeds : ndarray, shape (n_speeds,)
        Crank speeds, rad/s.
    units : mapping of str to str
        Unit of each observable.
    peak, peak_to_peak : mapping of str to ndarray, shape (n_speeds,)
        Largest magnitude and peak to peak of each observable at each speed, in its unit.
    peak_error, peak_to_peak_error : mapping of str to ndarray, shape (n_speeds,)
        Their estimated errors (N against N/2 steps).
    n_steps : int
        Steps per period.
    scheme : str
        The periodic scheme's registered name.
    status, message : str
        The worst of the steady states' verdicts and its reason.
    run_time : float
        Seconds.
    """

    problem: str
    speeds: np.ndarray
    units: Mapping[str, str]
    peak: Mapping[str, np.ndarray]
    peak_error: Mapping[str, np.ndarray]
    peak_to_peak: Mapping[str, np.ndarray]
    peak_to_peak_error: Mapping[str, np.ndarray]
    n_steps: int
    scheme: str
    status: str
    message: str
    run_time: float

    _units = {"speeds": "rad/s", "peak": "@observables", "peak_error": "@observables",
              "peak_to_peak": "@observables", "peak_to_peak_error": "@observables"}

    def plot(self, *, axes: Any = None) -> studies.Plot:
        import matplotlib.pyplot as plt

        if axes is None:
            _, axes = plt.subplots(len(self.peak_to_peak), 1, squeeze=False)
            axes = list(axes[:, 0])
        artists = {}
        for ax, (spec, values) in zip(axes, self.peak_to_peak.items()):
            artists[spec] = ax.plot(self.speeds, values, "o-")
            ax.set_xlabel("speed (rad/s)")
            ax.set_ylabel(f"{spec} peak to peak ({self.units[spec]})")
            ax.set_title(f"{self.problem}: peak to peak, {self.status}", fontsize="small")
        return studies.Plot(figure=axes[0].figure, axes=list(axes), artists=artists)


def peak_table(problem: Any, speeds, *, n_steps: int = 64, scheme: str = TRAPEZOIDAL) -> PeakTable:
    """The steady state of ``problem`` at each of ``speeds`` (rad/s) with the periodic scheme named
    ``scheme``: the peak to peak of each observable and its error estimate."""
    started = time.perf_counter()
    steadies = [studies.steady_state(problem, {"speed": float(speed)}, n_steps=n_steps, scheme=scheme)
                for speed in speeds]
    specs = list(steadies[0].peak_to_peak)
    worst = max(steadies, key=lambda steady: steady.status != "ok")
    def over_speeds(name: str) -> dict[str, np.ndarray]:   # a steady state's {spec: float} field, per speed
        return {spec: np.array([getattr(steady, name)[spec] for steady in steadies]) for spec in specs}

    return PeakTable(problem=problem.name, speeds=np.asarray(speeds, dtype=float), units=dict(steadies[0].units),
                     peak=over_speeds("peak"), peak_error=over_speeds("peak_error"),
                     peak_to_peak=over_speeds("peak_to_peak"), peak_to_peak_error=over_speeds("peak_to_peak_error"),
                     n_steps=n_steps, scheme=scheme, status=worst.status, message=worst.message,
                     run_time=time.perf_counter() - started)


def _check(where: str, table: Mapping[str, Any], n_steps: int) -> dict[str, Any]:
    speeds = table.get("speeds")
    if not isinstance(speeds, list) or not speeds or not all(
            isinstance(s, (int, float)) and not isinstance(s, bool) and s > 0 for s in speeds):
        raise studies.StudiesError(f"[{where}] speeds: expected a list of positive speeds (rad/s), got {speeds!r}")
    steps = table.get("n_steps", n_steps)
    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 16 or steps % 4:
        raise studies.StudiesError(f"[{where}] n_steps: expected a multiple of 4, at least 16, got {steps!r}")
    return {"speeds": [float(s) for s in speeds], "n_steps": steps}


def _run(problem: Any, options: Mapping[str, Any], **_: Any) -> PeakTable:
    # the plan adds the [studies] table's scheme (the kind declares schemes=True); a direct call may not
    return peak_table(problem, options["speeds"], n_steps=options["n_steps"],
                      scheme=options.get("scheme", TRAPEZOIDAL))


def _cost(name: str, problem: Any, options: Mapping[str, Any], workers: int) -> studies.Estimate:
    return studies.steady_solves(name, problem, [{"speed": s} for s in options["speeds"]], options["n_steps"])


def _summary(result: PeakTable) -> str:
    return f"{len(result.speeds)} speeds, {result.status}; {result.run_time:.3g} s"


def _headlines(result: PeakTable) -> studies.Summary:
    rows = [studies.Headline(f"{spec} peak to peak at {speed:g} rad/s", float(value), result.units[spec],
                             float(error))
            for spec, values in result.peak_to_peak.items()
            for speed, value, error in zip(result.speeds, values, result.peak_to_peak_error[spec])]
    return studies.Summary(status=result.status, run_time=result.run_time, rows=rows)


#: The kind's table in the built-in mathieu scene of ``flexvib run``.
DEMO_SPEEDS = [0.5, 0.9, 1.4]

KIND = studies.register_kind(studies.StudyKind(
    name="peak_table", result=PeakTable, keys=("speeds", "n_steps"), check=_check, run=_run,
    summary=_summary, headlines=_headlines, cost=_cost, demo={"speeds": DEMO_SPEEDS, "n_steps": 64},
    schemes=True))


# ---------------------------------------------------------------------------------------------------
# a periodic scheme: the theta-method
# ---------------------------------------------------------------------------------------------------
class ThetaMethod:
    """The theta-method on ``z = (x, v)``, ``z' = F(t, z) = (v, a)`` with ``M a = f - C v - K x``:
    ``z_{k+1} = z_k + h ((1 - theta) F_k + theta F_{k+1})``.  A-stable for ``theta >= 1/2``; order 2 and
    time-symmetric at ``theta = 1/2`` (the trapezoidal rule), order 1 otherwise.  Not a member of Newmark's
    family for ``theta != 1/2`` (the a_k weight of the position update differs)."""

    def __init__(self, theta: float):
        self.theta = float(theta)
        self.symmetric = self.theta == 0.5
        self.order = 2 if self.symmetric else 1
        self.error_factor = 1.0 / (2.0**self.order - 1.0)
        self.unconditionally_stable = self.theta >= 0.5

    def __repr__(self):
        return f"ThetaMethod({self.theta})"

    def march(self, system, forced, x, v, a, x_hist, v_hist, a_hist):
        """``periodic.Scheme.march``.  Per step, the unknown a_{k+1} solves
        ``(M + theta h C + theta^2 h^2 K) a_{k+1} = forced f - C v~ - K x~`` with the known parts
        ``v~ = v_k + h (1 - theta) a_k`` and ``x~ = x_k + h v_k + h^2 theta (1 - theta) a_k``; then
        ``v_{k+1} = v~ + h theta a_{k+1}`` and ``x_{k+1} = x~ + h^2 theta^2 a_{k+1}``."""
        if system.n_first_order:
            raise periodic.PeriodicError(f"scheme: {self!r} does not integrate first-order coordinates "
                                         f"{system.first_order.tolist()}")
        h, theta = system.step, self.theta
        M, C, K, f = system.M, system.C, system.K, system.f
        store = len(x_hist) > 0

        def solve(k, matrix, x_known, v_known):
            rhs = np.outer(f[k], forced) - C[k] @ v_known - K[k] @ x_known
            return np.linalg.solve(matrix, rhs)

        try:
            a[:] = solve(0, M[0], x, v)
        except np.linalg.LinAlgError:
            return 0
        for k in range(system.n_steps + 1):
            if store:
                x_hist[k], v_hist[k], a_hist[k] = x, v, a
            if k == system.n_steps:
                break
            v_known = v + h * (1.0 - theta) * a
            x_known = x + h * v + h * h * theta * (1.0 - theta) * a
            matrix = M[k + 1] + theta * h * C[k + 1] + theta**2 * h * h * K[k + 1]
            try:
                a[:] = solve(k + 1, matrix, x_known, v_known)
            except np.linalg.LinAlgError:
                return k + 1
            v[:] = v_known + h * theta * a
            x[:] = x_known + h * h * theta**2 * a
        return -1


THETA_SCHEMES = {"theta-0.6": ThetaMethod(0.6), "theta-0.5": ThetaMethod(0.5)}
for _name, _scheme in THETA_SCHEMES.items():
    periodic.register_scheme(_name, _scheme)


# ---------------------------------------------------------------------------------------------------
# a controller: PD on the driven angle plus the feedback of a strain gauge
# ---------------------------------------------------------------------------------------------------
@mechanisms.register_controller
@dataclass(frozen=True)
class GaugedPD:
    """Adds ``kp (angle_nominal - angle) + kd (rate_nominal - rate) - gain o``, ``o`` the strain at
    the coupler's midspan."""

    name: str
    joint: str
    kp: float = 0.0
    kd: float = 0.0
    gain: float = 0.0
    lag: float = 0.0

    TYPE: ClassVar[str] = "gauged_pd"
    KEYS: ClassVar[tuple[str, ...]] = ("type", "joint", "kp", "kd", "gain")

    @classmethod
    def from_table(cls, name, table):
        return cls(name, table.string("joint"), table.number("kp", "N m/rad", 0.0),
                   table.number("kd", "N m s/rad", 0.0), table.number("gain", "N m", 0.0))

    def to_table(self):
        return {"type": self.TYPE, "joint": self.joint, "kp": self.kp, "kd": self.kd,
                "gain": self.gain}

    def law(self):
        return mechanisms.ControllerLaw(kp=self.kp, kd=self.kd, observable="coupler.strain@0.5",
                                        gain=self.gain)


# ---------------------------------------------------------------------------------------------------
# a drive kind: a torque drive whose PD gains follow from a closed-loop bandwidth
# ---------------------------------------------------------------------------------------------------
@mechanisms.register_drive
@dataclass(frozen=True)
class ServoDrive(mechanisms.TorqueDrive):
    """A torque drive tuned by its closed-loop ``bandwidth`` w (rad/s) and ``damping_ratio`` zeta for
    the inertia ``crank_inertia`` J (kg m^2) its designer expects at the crank: ``kp = J w^2``,
    ``kd = 2 zeta J w``; otherwise a torque drive (feedforward, motor, flywheel, torque limit)."""

    bandwidth: float = 0.0
    damping_ratio: float = 0.7
    crank_inertia: float = 0.0

    TYPE: ClassVar[str] = "servo"
    KEYS: ClassVar[tuple[str, ...]] = ("type", "joint", "rate", "offset", "harmonics", "bandwidth",
                                       "damping_ratio", "crank_inertia", "motor", "flywheel",
                                       "torque_limit")

    def __post_init__(self):
        object.__setattr__(self, "kp", self.crank_inertia * self.bandwidth**2)
        object.__setattr__(self, "kd", 2.0 * self.damping_ratio * self.crank_inertia * self.bandwidth)
        super().__post_init__()

    @classmethod
    def from_table(cls, joint, table):
        motor = (mechanisms.DCMotor.from_table(table.table("motor"), f"{table.path}.motor")
                 if table.has("motor") else None)
        limit = table.number("torque_limit", "N m", positive=True) if table.has("torque_limit") else math.inf
        return cls(joint if joint is not None else table.string("joint"),
                   rate=table.number("rate", "rad/s", 0.0), offset=table.number("offset", "rad", 0.0),
                   harmonics=tuple(tuple(h) for h in table.raw("harmonics", [])), motor=motor,
                   flywheel=table.number("flywheel", "kg m^2", 0.0), torque_limit=limit,
                   bandwidth=table.number("bandwidth", "rad/s", 0.0, nonnegative=True),
                   damping_ratio=table.number("damping_ratio", "1", 0.7, nonnegative=True),
                   crank_inertia=table.number("crank_inertia", "kg m^2", 0.0, nonnegative=True))

    def to_table(self):
        # the torque drive's table with the bandwidth, damping ratio and inertia in place of the gains
        entry = {key: value for key, value in super().to_table().items() if key not in ("kp", "kd", "feedforward")}
        return {**entry, "bandwidth": self.bandwidth, "damping_ratio": self.damping_ratio,
                "crank_inertia": self.crank_inertia}

    @staticmethod
    def table_without_feedback(table):
        return {**table, "bandwidth": 0.0}

    def without_feedback(self):
        return dataclasses.replace(self, bandwidth=0.0)
