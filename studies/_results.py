"""Result objects of the studies: frozen dataclasses with units, ``.to_hdf5(group)`` and ``.plot()``.

Shapes use ``n`` for the grid points of a sweep, ``N + 1`` for the samples of one period, ``m`` for the
independent coordinates, ``n_obs`` for the observables. Dicts keyed by observable spec hold one array
per observable (unit in ``units``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from ._store import Result, register


@register
@dataclass(frozen=True, eq=False)
class SteadyStateResult(Result):
    """Periodic steady response over one period, with Floquet multipliers.

    ``t`` (N+1,) s; ``crank_angle`` (N+1,) rad; ``x`` (N+1, m) independent coordinates (SI unit of each
    coordinate, see ``labels``); ``response`` {spec: (N+1,)} observables; ``response_error``
    {spec: float} estimated max abs error of each; ``multipliers`` (2m,) complex; ``error_estimate``
    max abs error of ``x``; ``run_time`` s (linearisation, N and N/2 shooting); for mechanisms
    ``outlines`` {link: (N+1, n_points, 2)} m, points along each link over the period with the
    deflection magnified ``magnification`` times (empty for other problems).
    """

    problem: str
    parameters: Mapping[str, float]
    scene: str
    labels: tuple[str, ...]
    units: Mapping[str, str]
    t: np.ndarray
    crank_angle: np.ndarray
    x: np.ndarray
    response: Mapping[str, np.ndarray]
    response_error: Mapping[str, float]
    multipliers: np.ndarray
    spectral_radius: float
    error_estimate: float
    status: str
    message: str
    n_steps: int
    run_time: float
    shooting_run_time: float
    outlines: Mapping[str, np.ndarray] = field(default_factory=dict)
    magnification: float = float("nan")

    _units = {"t": "s", "crank_angle": "rad", "x": "SI (see labels)", "response": "@observables",
              "multipliers": "1", "outlines": "m"}

    def plot(self, *, axes: Any = None) -> dict[str, list]:
        from ._plots import plot_steady_state

        return plot_steady_state(self, axes=axes)

    def plot_mechanism(self, *, ax: Any = None, n_frames: int = 8) -> list:
        """The deformed mechanism at ``n_frames`` crank angles over the period."""
        from ._plots import plot_mechanism

        return plot_mechanism(self, ax=ax, n_frames=n_frames)

    def plot_multipliers(self, *, ax: Any = None) -> list:
        from ._plots import plot_multipliers

        return plot_multipliers(self.multipliers, ax=ax, title=f"{self.problem}: Floquet multipliers")


@dataclass(frozen=True, eq=False)
class GridResult(Result):
    """Fields shared by the grid studies: ``problem`` name, ``scene`` text, ``settings``; per grid
    point ``done`` (bool; False where an interrupted run did not get), ``status`` ("ok", a periodic
    status, "inaccurate" or "failed"), ``message`` (str) and ``point_run_time`` (s)."""

    problem: str
    scene: str
    settings: Mapping[str, Any]
    done: np.ndarray
    status: np.ndarray
    message: np.ndarray
    point_run_time: np.ndarray

    _units = {"done": "1", "status": "1", "message": "1", "point_run_time": "s"}


@register
@dataclass(frozen=True, eq=False)
class SweepResult(GridResult):
    """Peak-to-peak response and stability against one parameter.

    ``values`` (n,) of ``parameter`` (unit ``parameter_unit``); ``speed`` (n,) crank speed rad/s at
    each point; ``peak_to_peak`` {spec: (n,)} and ``peak_to_peak_error`` {spec: (n,)} (twice the max
    error estimate); ``spectral_radius`` (n,); ``multipliers`` (n, 2m) complex; ``error_estimate`` (n,)
    max error of the coordinates; ``frozen_min``, ``frozen_max``, ``frozen_mean`` (n, m) rad/s the
    band of each frozen-time natural frequency (ascending order) over the period; ``resonances`` ((k, mode, value), ...) where ``k * speed`` crosses the mean of
    frozen frequency ``mode`` (0-based); ``instabilities`` ((start, end), ...) parameter intervals with
    spectral radius above 1 (parametric instability); ``run_time`` s wall time of the whole sweep.
    """

    parameter: str
    parameter_unit: str
    labels: tuple[str, ...]
    units: Mapping[str, str]
    values: np.ndarray
    speed: np.ndarray = None
    peak_to_peak: Mapping[str, np.ndarray] = field(default_factory=dict)
    peak_to_peak_error: Mapping[str, np.ndarray] = field(default_factory=dict)
    spectral_radius: np.ndarray = None
    multipliers: np.ndarray = None
    error_estimate: np.ndarray = None
    frozen_min: np.ndarray = None
    frozen_max: np.ndarray = None
    frozen_mean: np.ndarray = None
    resonances: tuple = ()
    instabilities: tuple = ()
    run_time: float = float("nan")

    _units = {"values": "@parameter_unit", "speed": "rad/s", "peak_to_peak": "@observables",
              "peak_to_peak_error": "@observables", "spectral_radius": "1", "multipliers": "1",
              "error_estimate": "SI (see labels)", "frozen_min": "rad/s", "frozen_max": "rad/s",
              "frozen_mean": "rad/s", **GridResult._units}

    def plot(self, *, axes: Any = None) -> dict[str, list]:
        from ._plots import plot_sweep

        return plot_sweep(self, axes=axes)


@register
@dataclass(frozen=True, eq=False)
class CampbellResult(GridResult):
    """Campbell diagram: frozen-time natural frequencies against crank speed.

    ``speeds`` (n,) rad/s; ``crank_angle`` (n_frozen,) rad at which the frozen systems are taken;
    ``frozen`` (n, n_frozen, m) rad/s ascending at each sample; ``shapes`` (n, m, m) mode shapes at
    crank angle 0 (columns); ``multipliers`` (n, 2m) and ``multipliers_coarse`` (n, 2m) with N and
    N/2 steps; ``period`` (n,) s; after the grid: ``order``
    (n, m) tracked mode j is frequency column ``order[i, j]`` at speed i (MAC tracking),
    ``tracking_mac`` (n, m) the MAC of each step, ``band_min``/``band_max``/``band_mean`` (n, m) rad/s
    band of each tracked mode over the crank angle, ``characteristic`` (n, 2m) rad/s Floquet
    characteristic frequencies unfolded to the nearest frozen mean frequency and
    ``characteristic_error`` (n, 2m) rad/s their estimated error (N against N/2), ``mode_labels`` (m,),
    ``harmonics`` the k of the lines ``k * speed``.
    """

    labels: tuple[str, ...]
    speeds: np.ndarray
    crank_angle: np.ndarray = None
    frozen: np.ndarray = None
    shapes: np.ndarray = None
    multipliers: np.ndarray = None
    multipliers_coarse: np.ndarray = None
    period: np.ndarray = None
    order: np.ndarray = None
    tracking_mac: np.ndarray = None
    band_min: np.ndarray = None
    band_max: np.ndarray = None
    band_mean: np.ndarray = None
    characteristic: np.ndarray = None
    characteristic_error: np.ndarray = None
    mode_labels: tuple = ()
    harmonics: tuple = ()
    run_time: float = float("nan")

    _units = {"speeds": "rad/s", "crank_angle": "rad", "frozen": "rad/s", "shapes": "1",
              "multipliers": "1", "multipliers_coarse": "1", "period": "s", "order": "1",
              "tracking_mac": "1", "characteristic_error": "rad/s", "band_min": "rad/s",
              "band_max": "rad/s", "band_mean": "rad/s", "characteristic": "rad/s", **GridResult._units}

    def plot(self, *, ax: Any = None) -> list:
        from ._plots import plot_campbell

        return plot_campbell(self, ax=ax)


@register
@dataclass(frozen=True, eq=False)
class StabilityChart(GridResult):
    """Spectral radius over two parameters.

    ``first`` (n1,) values of ``parameters[0]``, ``second`` (n2,) of ``parameters[1]`` (units
    ``parameter_units``); ``spectral_radius`` (n1, n2) and ``spectral_radius_error`` (n1, n2) its
    estimated error (N against N/2 steps); ``stability_tol`` the tolerance of
    ``|mu| = 1``; ``run_time`` s.
    """

    parameters: tuple[str, str]
    parameter_units: tuple[str, str]
    first: np.ndarray
    second: np.ndarray
    spectral_radius: np.ndarray = None
    spectral_radius_error: np.ndarray = None
    stability_tol: float = 1e-6
    run_time: float = float("nan")

    _units = {"spectral_radius": "1", "spectral_radius_error": "1", **GridResult._units}

    def _unit(self, name: str, key: str | None = None) -> str:
        if name == "first":
            return self.parameter_units[0]
        if name == "second":
            return self.parameter_units[1]
        return super()._unit(name, key)

    def plot(self, *, ax: Any = None) -> list:
        from ._plots import plot_chart

        return plot_chart(self, ax=ax)


@register
@dataclass(frozen=True, eq=False)
class NonlinearCheck(Result):
    """The full nonlinear model against the linear periodic solution.

    ``t_linear`` (N+1,) s and ``linear`` {spec: (N+1,)}: the linear steady state over one period;
    ``t`` (n_t,) s and ``nonlinear`` {spec: (n_t,)}: the nonlinear run from the linear state at t = 0
    over ``n_periods``; ``linear_error`` and ``nonlinear_error`` {spec: float} the estimated max
    error of each route (NaN when the integrator gives none); ``difference`` {spec: float} max over the last period of |nonlinear - linear|;
    ``relative_difference`` {spec: float} the same over the linear peak-to-peak;
    ``periodicity_defect`` {spec: float} max |o(t) - o(t - T)| over the last period of the nonlinear
    run; from rest (when asked): ``t_rest``, ``rest`` {spec: (n_rest,)}, ``rest_difference``
    {spec: float} over the last period, ``periods_to_steady`` (periods until the periodicity defect
    fell below ``steady_tol`` times the peak-to-peak, NaN if never); costs ``linear_run_time``,
    ``nonlinear_run_time``, ``rest_run_time`` s.
    """

    problem: str
    scene: str
    parameters: Mapping[str, float]
    units: Mapping[str, str]
    settings: Mapping[str, Any]
    t_linear: np.ndarray
    linear: Mapping[str, np.ndarray]
    linear_error: Mapping[str, float]
    t: np.ndarray
    nonlinear: Mapping[str, np.ndarray]
    nonlinear_error: Mapping[str, float]
    difference: Mapping[str, float]
    relative_difference: Mapping[str, float]
    periodicity_defect: Mapping[str, float]
    linear_run_time: float
    nonlinear_run_time: float
    t_rest: np.ndarray = None
    rest: Mapping[str, np.ndarray] = field(default_factory=dict)
    rest_difference: Mapping[str, float] = field(default_factory=dict)
    periods_to_steady: float = float("nan")
    rest_run_time: float = float("nan")

    _units = {"t_linear": "s", "linear": "@observables", "t": "s", "nonlinear": "@observables",
              "t_rest": "s", "rest": "@observables"}

    def plot(self, *, axes: Any = None) -> dict[str, list]:
        from ._plots import plot_nonlinear

        return plot_nonlinear(self, axes=axes)


@register
@dataclass(frozen=True, eq=False)
class ErrorCostResult(Result):
    """Error against run time.

    ``resolutions`` (n_r,) values of ``resolution_parameter`` (e.g. a number of elements; empty name
    when only the steps vary); ``n_steps`` (n_s,) steps per period; ``n_dof`` (n_r,) size of the linear
    system; ``error`` {spec: (n_r, n_s)} max abs difference from the reference over the period,
    divided by the reference's peak-to-peak; ``error_estimate`` {spec: (n_r, n_s)} the self-estimated
    error (same scaling); ``run_time`` (n_r, n_s) s of linearisation plus shooting; the reference is
    the finest resolution with ``reference_steps`` steps and Richardson extrapolation.
    """

    problem: str
    scene: str
    resolution_parameter: str
    units: Mapping[str, str]
    settings: Mapping[str, Any]
    resolutions: np.ndarray
    n_steps: np.ndarray
    n_dof: np.ndarray
    error: Mapping[str, np.ndarray]
    error_estimate: Mapping[str, np.ndarray]
    run_time: np.ndarray
    reference_steps: int
    reference_run_time: float

    _units = {"resolutions": "1", "n_steps": "1", "n_dof": "1", "error": "1", "error_estimate": "1",
              "run_time": "s"}

    def plot(self, *, ax: Any = None) -> list:
        from ._plots import plot_error_cost

        return plot_error_cost(self, ax=ax)
