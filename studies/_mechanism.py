"""The problem of a mechanism scene: ``linearize`` at given scene parameters, ``mechanisms.simulate``
for the nonlinear route, link outlines for drawings.

Parameters are named by their dotted path in the scene file (``"links.coupler.thickness"``) or
``"speed"`` for the motion's fundamental frequency ``2 pi / period`` (the crank speed of a crank
turning once per period). When every drive is prescribed, the points that differ only in speed
share one ``linearize.speed_family`` per process (the coefficients are polynomials in the speed);
torque drives, and any other change, are linearised afresh at each point.
"""

from __future__ import annotations

import functools
import math
import tomllib
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from ._errors import ComputationError, StudiesError
from ._problem import SPEED, Description, Linear, NonlinearRun, resolve_values

# Units of scene parameters by their last key (docs/scenes.md); others are reported as "SI".
_UNITS = {"rate": "rad/s", "length": "m", "width": "m", "thickness": "m", "area": "m^2",
          "second_moment": "m^4", "density": "kg/m^3", "youngs_modulus": "Pa", "mass": "kg",
          "inertia": "kg m^2", "ratio": "1", "alpha": "1/s", "beta": "s", "kp": "N m/rad",
          "kd": "N m s/rad", "period": "s"}
_CACHE_SIZE = 8
_mechanisms: OrderedDict = OrderedDict()
_families: OrderedDict = OrderedDict()


def _cached(cache: OrderedDict, key: Any, make):
    if key in cache:
        cache.move_to_end(key)
        return cache[key]
    value = make()
    cache[key] = value
    if len(cache) > _CACHE_SIZE:
        cache.popitem(last=False)
    return value


def _build(text: str, source: str):
    """The ``mechanisms.Mechanism`` of scene ``text`` (its scene dict kept as ``spec``)."""
    import mechanisms

    try:
        spec = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise mechanisms.MechanismError(f"{source}: not valid TOML: {error}") from None
    return mechanisms.build(spec, source=source)


def _with_values(spec: Mapping[str, Any], changes: Mapping[str, Any]) -> dict[str, Any]:
    """A copy of the scene dict ``spec`` with the values at dotted paths replaced (the tables on each
    path copied, the rest shared: ``mechanisms.build`` copies what it keeps)."""
    result = dict(spec)
    for path, value in changes.items():
        table, parts = result, path.split(".")
        for key in parts[:-1]:
            table[key] = dict(table.get(key, {}))
            table = table[key]
        table[parts[-1]] = value
    return result


def _get_path(spec: Mapping[str, Any], path: str) -> Any:
    node: Any = spec
    for part in path.split("."):
        if not isinstance(node, Mapping) or part not in node:
            raise KeyError(path)
        node = node[part]
    return node


@dataclass(frozen=True)
class MechanismProblem:
    """A scene (TOML ``text``) as a study problem.

    ``parameter_paths``: the scene parameters studies may vary besides ``"speed"`` (their nominal
    values are read from the scene); ``observable_specs``: observable specs (None:
    ``linearize.default_observables``). The text travels to worker processes; in each process the
    scene is built into a ``mechanisms.Mechanism`` once (``from_scene`` and ``from_mechanism`` hand
    over the one they have), and a parameter change builds its variant from that mechanism's scene
    dict, without writing or parsing text.
    """

    name: str
    text: str
    parameter_paths: tuple[str, ...] = ()
    observable_specs: tuple[str, ...] | None = None
    #: the nominal parameter values, read from the scene once (and pickled with the problem)
    _nominal: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        mechanism = self.mechanism()
        nominal = {SPEED: _speed(mechanism)}
        for path in self.parameter_paths:
            try:
                value = _get_path(mechanism.spec, path)
            except KeyError:
                raise StudiesError(f"scene {self.name!r} has no parameter {path!r} (dotted path of a "
                                   f"number in the scene file, e.g. 'links.coupler.thickness'"
                                   f"{_nearest_path(mechanism.spec, path)})") from None
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise StudiesError(f"scene {self.name!r}: parameter {path!r} is {value!r}, not a number")
            nominal[path] = float(value)
        object.__setattr__(self, "_nominal", nominal)

    @classmethod
    def from_scene(cls, name_or_path: str, *, parameter_paths=(), observables=None) -> "MechanismProblem":
        """The problem of a built-in scene name or a .toml file."""
        import mechanisms

        return cls.from_mechanism(mechanisms.load(name_or_path), parameter_paths=parameter_paths,
                                  observables=observables)

    @classmethod
    def from_mechanism(cls, mechanism: Any, *, parameter_paths=(), observables=None) -> "MechanismProblem":
        """The problem of a ``mechanisms.Mechanism`` (kept as this process's built scene), e.g.
        ``MechanismProblem.from_mechanism(mechanisms.four_bar())``. By default studies may vary the
        crank ``speed`` only and report ``linearize.default_observables``; ``parameter_paths``: the
        scene values they may vary besides (a dotted path or a sequence of them, e.g.
        ``"links.coupler.thickness"``); ``observables``: observable specs."""
        import mechanisms

        if not isinstance(mechanism, mechanisms.Mechanism):
            raise TypeError(f"from_mechanism() takes a mechanisms.Mechanism, got "
                            f"{type(mechanism).__name__} (for a scene name or file use from_scene)")
        if isinstance(parameter_paths, str):  # one path, not its characters
            parameter_paths = (parameter_paths,)
        if isinstance(observables, str):
            observables = (observables,)
        text = mechanism.to_toml()
        if mechanism.spec is None:  # made from parts: variants are built from a scene dict
            mechanism = mechanisms.build(tomllib.loads(text), source=f"scene {mechanism.name!r}")
        _cached(_mechanisms, text, lambda: mechanism)
        return cls(name=mechanism.name, text=text, parameter_paths=tuple(parameter_paths),
                   observable_specs=None if observables is None else tuple(observables))

    def mechanism(self, values: Mapping[str, float] | None = None):
        """The ``mechanisms.Mechanism`` at ``values`` (cached per process)."""
        import mechanisms

        base = _cached(_mechanisms, self.text, lambda: _build(self.text, f"scene {self.name!r}"))
        changes = {}
        counts = count_keys() if values else ()
        for key, value in (values or {}).items():
            if key == SPEED:
                changes.update(_speed_changes(base, value))
            else:
                changes[key] = int(round(value)) if key.split(".")[-1] in counts else value
        if not changes:
            return base
        return _cached(_mechanisms, (self.text, tuple(sorted(changes.items()))),
                       lambda: mechanisms.build(_with_values(base.spec, changes),
                                                source=f"{self.name} with {changes}"))

    @property
    def parameters(self) -> dict[str, float]:
        return dict(self._nominal)

    @property
    def units(self) -> dict[str, str]:
        counts = count_keys()   # a count (of elements, modes) has unit 1
        return {name: "1" if name.split(".")[-1] in counts
                else _UNITS.get(name.split(".")[-1], "rad/s" if name == SPEED else "SI")
                for name in self.parameters}

    def resolve(self, values: Mapping[str, float] | None) -> dict[str, float]:
        unknown = [key for key in (values or {}) if key not in self._nominal]
        if unknown:
            raise StudiesError(f"problem {self.name!r} has no parameter {unknown[0]!r} (parameters: "
                               f"{sorted(self._nominal)}); {self.parameter_advice(unknown[0])}")
        return resolve_values(self.name, self._nominal, values)

    def parameter_advice(self, path: str) -> str:
        """How to make the scene value at ``path`` a parameter studies may vary (the end of the
        unknown-parameter error)."""
        try:
            _get_path(self.mechanism().spec, path)
        except KeyError:
            nearest = _nearest_path(self.mechanism().spec, path).removeprefix("; ")
            return (f"the scene has no value at {path!r}{f' ({nearest})' if nearest else ''}; "
                    f"parameters are 'speed' and the dotted paths of scene values passed as "
                    f"parameter_paths")
        return (f"to vary this scene value, make the problem with it: MechanismProblem.from_mechanism("
                f"mechanism, parameter_paths=[{path!r}]) (or from_scene(name, parameter_paths=[...]))")

    def describe(self, values: Mapping[str, float] | None = None) -> Description:
        """Coordinate labels, observables and units at ``values`` from the assembled model (cached by
        ``mechanisms.assemble``), without linearising. When the constraints fix every rigid
        coordinate (prescribed drives) the independent coordinates are the elastic ones; otherwise
        ``linearize`` picks further ones along the motion, and a coarse linearisation names them."""
        import linearize
        import mechanisms

        params = self.resolve(values)
        mechanism = self.mechanism({k: v for k, v in params.items() if k != SPEED and v != self._nominal[k]})
        model = mechanisms.assemble(mechanism)
        specs = (linearize.default_observables(mechanism) if self.observable_specs is None
                 else tuple(self.observable_specs))
        elastic = np.sort(np.asarray(model.elastic_index, dtype=np.int64))
        if model.n_coords - model.n_constraints == elastic.size:
            labels = tuple(model.coord_labels[i] for i in elastic)
        else:
            labels = tuple(self.linearize(values, n_steps=4).labels)
        return Description(labels=labels, observables=tuple(specs),
                           units=tuple(model.observable(spec).unit for spec in specs))

    #: ``linearize(..., kinematics=...)`` reuses a nominal motion (the sensitivities' neighbours)
    reuses_kinematics = True

    def linearize(self, values: Mapping[str, float] | None = None, *, n_steps: int,
                  context: bool = True, kinematics: Any = None) -> Linear:
        """The linear periodic system at ``values``. ``context=False`` skips building the
        ``linearize`` result object (mechanism, nominal motion at that speed) that only the nonlinear
        route and drawings need: grid points take the speed family's polynomials directly.
        ``kinematics``: the nominal motion (``mechanisms.NominalMotion``, same speed and grid) of a
        point whose linkage these values do not move, reused (``linearize.about``)."""
        import linearize

        params = self.resolve(values)
        others = {k: v for k, v in params.items() if k != SPEED and v != self._nominal[k]}
        speed = params[SPEED]
        if kinematics is not None:
            # the same object as the caller's configuration check built (its model cached)
            at_scene_speed = math.isclose(speed, self._nominal[SPEED], rel_tol=1e-12)
            mechanism = self.mechanism(others if at_scene_speed else dict(others, speed=speed))
            lin = linearize.about(mechanism, n_steps=n_steps, observables=self.observable_specs,
                                  kinematics=kinematics)
            return _linear(lin, lin.system, lin, linear_range=lin.linear_range)
        mechanism = self.mechanism(others)
        # Prescribed drives make the motion a function of the phase 2 pi t / period: a speed
        # family covers every speed (torque drives are linearised at each speed).
        prescribed = linearize.supports_speed_family(mechanism)
        family_key = (self.text, tuple(sorted(others.items())), n_steps, self.observable_specs)
        at_scene_speed = math.isclose(speed, _speed(mechanism), rel_tol=1e-12)
        if prescribed and at_scene_speed and family_key not in _families:
            # One speed, the scene's own, and no family built yet: one linearisation, not the
            # three a speed family costs.
            lin = linearize.about(mechanism, n_steps=n_steps, observables=self.observable_specs)
            return _linear(lin, lin.system, lin, linear_range=lin.linear_range)
        if prescribed:
            family = _cached(_families, family_key,
                             lambda: linearize.speed_family(mechanism, n_steps=n_steps,
                                                            observables=self.observable_specs))
            # the family's speed carries the sign of the first drive's rate (a crank turning
            # clockwise has a negative one); the studies' speed is 2 pi / period
            speed = math.copysign(speed, family.rate)
            if at_scene_speed:
                return _linear(family.base, family.base.system, family.base,
                               linear_range=family.base.linear_range)
            if not context:
                # On the phase grid the configuration (hence the gains of the observables of
                # the configuration) is the base's; the coefficients and the maps of forces,
                # torques and stresses change with the speed.
                return _linear(family.base, family.system_at(speed), None,
                               linear_range=_family_range(family, speed),
                               maps=family.observable_maps_at(speed),
                               member=functools.partial(family.at_speed, speed, rebuild=False))
            lin = family.at_speed(speed)
        else:
            lin = linearize.about(self.mechanism(dict(others, speed=speed)), n_steps=n_steps,
                                  observables=self.observable_specs)
        return _linear(lin, lin.system, lin, linear_range=lin.linear_range)

    # --- nonlinear route --------------------------------------------------------------------------------
    supports_nonlinear = True

    def simulate(self, linear: Linear, x0: np.ndarray, v0: np.ndarray, *, n_periods: int,
                 steps_per_period: int) -> NonlinearRun:
        """``mechanisms.simulate`` from the nominal state plus ``x = V z`` (projected onto the
        constraints, which ``V z`` satisfies to first order only); observables as the linear route
        reports them (``MechanismLinear``): functions of the coordinates as deviations from their
        values along the nominal motion, with the simulation's Richardson error estimates; joint
        forces and drive torques as totals from the run's multipliers and rates (error NaN)."""
        import mechanisms

        lin = linear.context
        # the model a run of this mechanism integrates (a speed family's result keeps the base
        # speed's model, whose rheonomic drive constraint has the base speed)
        model = mechanisms.integrated_model(lin.mechanism)
        n = linear.system.n_steps
        # On the constraints exactly, with the second-order axial shortening of stiffened links.
        s0, sdot0 = lin.start_state(x0, v0)
        # the observables that are functions of s the integrator evaluates (with its error
        # estimates); forces, torques and magnitudes come from its multipliers and rates below
        direct = [spec for spec in linear.observables if of_coordinates(model.observable(spec))]
        # the lagged controllers' states are the last linear coordinates (linearize labels them
        # lag.<name>): the run starts them at the linear state, not at rest
        n_lags = len(getattr(model, "lag_names", ()))
        lag0 = np.asarray(x0, dtype=float)[-n_lags:] if n_lags else None
        run = mechanisms.simulate(model, n_periods=n_periods, steps_per_period=steps_per_period,
                                  s0=s0, sdot0=sdot0, observables=direct, estimate_error=True, lag0=lag0)
        if not run.success:
            raise ComputationError(f"nonlinear run of {self.name!r} failed: {run.message}")
        if steps_per_period != n:
            raise StudiesError(f"steps_per_period ({steps_per_period}) must equal the linear grid's "
                             f"n_steps ({n}) to subtract the nominal motion sample by sample")
        observables = observables_along(linear, model, run.t, run.s, run.sdot, run.lam, run.lag_states,
                                        computed=run.observables)
        error = {spec: float(run.observable_error.get(spec, float("nan")))
                 for spec in linear.observables}
        return NonlinearRun(t=run.t, observables=observables, run_time=run.run_time,
                            error=error, message=run.message)

    # --- drawings ----------------------------------------------------------------------------------------
    def outlines(self, linear: Linear, z: np.ndarray, *, n_points: int = 21,
                 magnification: float | None = None) -> tuple[dict[str, np.ndarray], float]:
        """Link outlines over the period: ``{link: (N+1, n_points, 2)}`` positions in m of points
        along each link's x-axis, the elastic transverse deflection magnified; and the magnification."""
        lin = linear.context
        model = lin.nominal.model
        labels = list(model.coord_labels)
        mechanism = lin.mechanism
        s_full, _ = lin.full_state(z, np.zeros_like(z))
        deflections = {}
        for link in mechanism.links:
            if model.layouts[link.name].shapes is None:   # a rigid link does not deflect
                continue
            rows = []
            for fraction in np.linspace(0.0, 1.0, n_points):
                observable = model.observable(f"{link.name}.deflection@{fraction:.6g}")
                rows.append([observable.value(sk) for sk in s_full])
            deflections[link.name] = np.array(rows).T  # (N+1, n_points)
        largest = max((np.abs(d).max() for d in deflections.values()), default=0.0)
        longest = max(link.length for link in mechanism.links)
        if magnification is None:
            magnification = 0.1 * longest / largest if largest > 0 else 1.0
        outlines = {}
        for link in mechanism.links:
            x = lin.nominal.s[:, labels.index(f"{link.name}.x")]
            y = lin.nominal.s[:, labels.index(f"{link.name}.y")]
            theta = lin.nominal.s[:, labels.index(f"{link.name}.theta")]
            xi = np.linspace(0.0, link.length, n_points)
            w = magnification * deflections.get(link.name, np.zeros((x.size, n_points)))
            c, s = np.cos(theta)[:, None], np.sin(theta)[:, None]
            outlines[link.name] = np.stack([x[:, None] + c * xi - s * w, y[:, None] + s * xi + c * w], axis=-1)
        return outlines, float(magnification)


def observables_along(linear: Linear, model: Any, t: np.ndarray, s: np.ndarray, sdot: np.ndarray,
                      lam: np.ndarray, lag_states: np.ndarray | None = None, *, stride: int = 1,
                      computed: Mapping[str, np.ndarray] | None = None,
                      specs: Any = None) -> dict[str, np.ndarray]:
    """{spec: (K,)} each of ``specs`` (default ``linear.observables``) along a run of ``model``, the
    full nonlinear model the run integrated (``mechanisms.integrated_model`` of
    ``linear.context.mechanism``: a torque drive's nominal torque is its feedforward), as the linear
    route reports it: functions of the coordinates as deviations from their values along the
    nominal motion (angles modulo 2 pi), joint forces from the run's multipliers and drive torques as
    the run applied them (feedforward plus feedback clipped to the drive's limits, plus the lagged
    controllers' states, which act outside them), both totals; stresses with the nominal axial
    stress of an axially rigid link.

    ``t`` (K,) s, ``s``, ``sdot`` (K, n), ``lam`` (K, r), ``lag_states`` (K, L) or None: the run on the
    grid of every ``stride``-th sample of the linear grid, from a whole period's start (t = 0, T, ...;
    whole periods or not);
    ``computed``: {spec: (K,)} values the integrator already evaluated. Package-internal, shared by
    the nonlinear check's transient and the nonlinear periodic states."""
    maps = dict(zip(linear.observables, linear.maps))
    run = _RunRoute(linear.context.nominal.s, stride, model, t, s, sdot, lam, lag_states, computed or {})
    return {spec: model.observable(spec).along_run(run, maps[spec])
            for spec in (linear.observables if specs is None else specs)}


class _RunRoute:
    """The ``RunRoute`` an observable's ``along_run`` reads (``mechanisms/_protocol.py``): a run
    of ``model`` at times ``t`` (K,) with ``s``, ``sdot`` (K, n), ``lam`` (K, r), ``lag_states``
    (K, L) or None, on the grid of every ``stride``-th sample of the nominal motion ``nominal_s``
    (N+1, n) from a whole period's start; ``computed`` {spec: (K,)} values the integrator
    evaluated."""

    def __init__(self, nominal_s, stride, model, t, s, sdot, lam, lag_states, computed):
        self.nominal_s, self.stride = nominal_s[::stride], stride
        self.model, self.t, self.s, self.sdot, self.lam = model, t, s, sdot, lam
        self.lag_states, self.computed = lag_states, computed
        self._reps = int(math.ceil(len(t) / (self.nominal_s.shape[0] - 1)))

    def _repeated(self, one_period) -> np.ndarray:
        """Samples over one period of the run's grid, repeated over the run."""
        return np.tile(np.asarray(one_period), self._reps)[: len(self.t)]

    def coordinates(self, observable: Any, linear_map: Any, value: Any = None) -> np.ndarray:
        """A function ``value`` of ``s`` (default ``observable.value``) as the linear route
        reports it: its change from its values along the nominal motion (angles modulo 2 pi),
        plus the map's nominal part when it has one (the axially rigid link's nominal axial
        stress)."""
        # the observable's values at many samples at once where it offers them (a link's built-in
        # quantities: the same formulas; about 5 us a sample in Python otherwise)
        along = getattr(observable, "values_along", None) if value is None else None
        value = observable.value if value is None else value

        def evaluate(samples: np.ndarray) -> np.ndarray:
            return along(samples) if along is not None else np.array([value(sk) for sk in samples])

        values = self.computed[observable.spec] if observable.spec in self.computed else evaluate(self.s)
        values = deviation_from_nominal(values, self._repeated(evaluate(self.nominal_s[:-1])), observable.unit)
        if linear_map.nominal is not None:   # on the linear grid (N+1,)
            values = values + self._repeated(np.asarray(linear_map.nominal)[::self.stride][:-1])
        return values

    def multipliers(self, weights: np.ndarray) -> np.ndarray:
        """``lam @ weights`` along the run (K,)."""
        return self.lam @ weights

    def drive_torque(self, drive_index: int) -> np.ndarray:
        """The torque (K,) N m the run's drive ``drive_index`` applied (``model.drive_torques``)."""
        lags = (self.lag_states if self.lag_states is not None and self.lag_states.size
                else [None] * len(self.t))
        return np.array([self.model.drive_torques(sk, vk, tk, lk, lag_states=yk)[drive_index]
                         for sk, vk, tk, lk, yk in zip(self.s, self.sdot, self.t, self.lam, lags)])


class _ReadsMore(Exception):
    """An observable's linear map asked ``_PartsRoute`` for more than functions of the coordinates."""


@dataclass(frozen=True)
class _PartMap:
    """The stand-in linear map ``_PartsRoute`` returns: no nominal part; a magnitude's component maps."""

    nominal: None = None
    components: tuple = ()


class _PartsRoute:
    """A ``LinearRoute`` (``mechanisms/_protocol.py``) that maps nothing: it records the functions of
    the coordinates an observable's ``linear_map`` is composed of and refuses every other primitive
    (multipliers, a torque law, a nominal axial force)."""

    def __init__(self) -> None:
        self.parts: list[Any] = []

    def coordinates(self, observable: Any, nominal: Any = None) -> _PartMap:
        if nominal is not None or not observable.of_coordinates:
            raise _ReadsMore
        self.parts.append(observable)
        return _PartMap()

    def magnitude(self, unit: str, components: tuple) -> _PartMap:
        return _PartMap(components=tuple(components))

    def multipliers(self, weights: np.ndarray, unit: str) -> Any:
        raise _ReadsMore

    def torque_law(self, drive_index: int, joint: str, unit: str) -> Any:
        raise _ReadsMore

    def axial_force(self, link: str, x: float) -> Any:
        raise _ReadsMore


def coordinate_parts(observable: Any) -> tuple[tuple, Any] | None:
    """``(parts, stand_in_map)``: the functions of the coordinates alone that ``observable`` is
    composed of (itself, or the components of a point's displacement magnitude) and a stand-in for
    its linear map that its ``along_run`` reads (``deviations_along``); None when it reads more than
    the coordinates (a joint force or its magnitude, a drive torque, an axially rigid link's stress).
    Found by building its linear map through a recording route: what the observable declares, not
    its class."""
    route = _PartsRoute()
    try:
        stand_in = observable.linear_map(route)
    except _ReadsMore:
        return None
    return tuple(route.parts), stand_in


def deviations_along(observable: Any, model: Any, nominal_s: np.ndarray, t: np.ndarray, s: np.ndarray,
                     computed: Mapping[str, np.ndarray]) -> np.ndarray:
    """The change (K,) of ``observable`` (a function of the coordinates or a composition of such,
    ``coordinate_parts``) along a run of ``model`` (``t`` (K,), ``s`` (K, n), from a whole period's
    start) from its values along the nominal motion ``nominal_s`` (N+1, n, the run's grid);
    ``computed`` {spec: (K,)} the parts' values the integrator evaluated."""
    _, stand_in = coordinate_parts(observable)
    run = _RunRoute(nominal_s, 1, model, t, s, None, None, None, computed)
    return observable.along_run(run, stand_in)


def count_keys() -> frozenset[str]:
    """Scene keys that are counts (whole numbers that change the number of coordinates), as every
    registered discretisation declares them (``COUNT_KEYS`` of the classes in
    ``mechanisms.DISCRETISATION_TYPES``): a study parameter on them is rounded, the guard sizes a
    study at their largest value, an optimisation refuses them as continuous bounds. Read at each
    call: a discretisation registered later counts too."""
    import mechanisms

    return frozenset(key for cls in mechanisms.DISCRETISATION_TYPES.values()
                     for key in getattr(cls, "COUNT_KEYS", ()))


def deviation_from_nominal(values: np.ndarray, nominal: np.ndarray, unit: str) -> np.ndarray:
    """``values - nominal`` of an observable along a nonlinear run, as the linear route reports it;
    an angle (``unit`` "rad") modulo 2 pi, in (-pi, pi]: a turning link's angle gains 2 pi per
    period while the nominal repeated over the run does not."""
    change = np.asarray(values, dtype=float) - nominal
    return np.pi - np.mod(np.pi - change, 2.0 * np.pi) if unit == "rad" else change


def of_coordinates(observable: Any) -> bool:
    """Whether ``observable`` is a function of the coordinates alone (``mechanisms.simulate``
    evaluates it; the observable declares it, ``mechanisms.Observable``): not a force, torque,
    magnitude or the stress of an axially rigid link."""
    return bool(observable.of_coordinates)


def _scene_paths(spec: Mapping[str, Any], prefix: str = "") -> list[str]:
    """The dotted paths of the numbers in a scene dict."""
    paths = []
    for key, value in spec.items():
        if isinstance(value, Mapping):
            paths += _scene_paths(value, f"{prefix}{key}.")
        elif isinstance(value, (int, float)) and not isinstance(value, bool):
            paths.append(f"{prefix}{key}")
    return paths


def _nearest_path(spec: Mapping[str, Any], path: str) -> str:
    """``"; did you mean 'links.coupler.thickness'?"`` for a misspelt ``path``, or ``""``."""
    import difflib

    close = difflib.get_close_matches(path, _scene_paths(spec), n=1)
    return f"; did you mean {close[0]!r}?" if close else ""


def _speed(mechanism) -> float:
    """The studies' ``speed`` of a mechanism: the fundamental angular frequency ``2 pi / period`` of its
    periodic motion, rad/s (the crank speed of a crank turning once per period)."""
    return 2.0 * math.pi / mechanism.period


def _speed_changes(mechanism, speed: float) -> dict[str, float]:
    """Scene parameter changes that make the motion's fundamental frequency ``speed``: every drive's
    rate scaled in proportion (so the drives still turn whole turns per period) and an explicit
    period scaled inversely; for oscillating drives (rate 0) the period alone."""
    if not (math.isfinite(speed) and speed > 0):
        raise StudiesError(f"parameter 'speed': expected a positive number (rad/s), got {speed!r}")
    factor = speed / _speed(mechanism)
    spec = mechanism.spec
    changes: dict[str, float] = {}
    if "drive" in spec:
        if mechanism.drives[0].rate:
            changes["drive.rate"] = mechanism.drives[0].rate * factor
    else:
        for drive in mechanism.drives:
            if drive.rate:
                changes[f"drives.{drive.joint}.rate"] = drive.rate * factor
    if "period" in spec or not changes:
        changes["period"] = mechanism.period / factor
    return changes


def _family_range(family: Any, speed: float):
    """The linear-range measures at ``speed`` of a speed family, for the cost of a few array
    operations (without building its result at that speed)."""
    return lambda z: family.linear_range(speed, z)


@dataclass(frozen=True, eq=False)
class MechanismLinear(Linear):
    """A ``Linear`` whose observables follow ``linearize.ObservableMap``s (``maps``, in the order
    of ``observables``): deviations linear in ``z`` (``gains`` holds their ``z`` gains, zero for
    the others) and the totals of joint forces, drive torques and stresses, which also need
    ``z'`` and ``z''`` (spectral derivatives of the periodic ``z``) and a nominal part, and
    magnitudes (``hypot`` of two such)."""

    maps: tuple = ()
    #: The ``linearize.LinearizedMechanism`` at this point whose full equations the error budget's
    #: linearisation term evaluates (``context``; with ``context=False`` the speed family's member,
    #: its mechanism not rebuilt at the speed).
    member: Any = None

    def observe(self, z: np.ndarray, *, stride: int = 1) -> np.ndarray:
        """Observables of the periodic ``z`` (N/stride + 1, m) sampled every ``stride`` samples:
        (N/stride + 1, n_obs). The N/2 solution of the error estimate goes through the same
        formulas on its own grid, so its difference from the N-step one estimates their error."""
        import linearize

        if not any(m.total or m.needs_derivatives or m.components for m in self.maps):
            return super().observe(z, stride=stride)
        zdot = zddot = None
        if any(m.needs_derivatives for m in self.maps):
            zdot, zddot, _ = linearize.spectral_derivatives(z, self.system.period)
        return np.stack([m.evaluate(z, zdot, zddot, stride=stride) for m in self.maps], axis=1)


def _given(value: Any) -> Any:
    return value


def _linear(lin: Any, system: Any, context: Any, *, linear_range: Any = None,
            maps: Mapping[str, Any] | None = None, member: Any = None) -> Linear:
    """A study's ``Linear`` from a ``linearize`` result (maps, gains and units of its observables;
    ``maps`` instead of ``lin``'s at another speed). The crank angle is the phase ``2 pi t / T``
    (the drive angle less its offset for a crank turning once per period; the phase of an
    oscillating drive)."""
    maps = lin.observable_maps if maps is None else maps
    ordered = tuple(maps[s] for s in lin.observables)
    n_samples, m = system.f.shape
    gains = np.zeros((n_samples, len(ordered), m))
    for k, observable_map in enumerate(ordered):
        if observable_map.position is not None and not observable_map.components:
            gains[:, k] = observable_map.position
    phase = 2.0 * math.pi * np.asarray(system.t) / system.period
    return MechanismLinear(system=system, crank_angle=phase,
                           labels=tuple(lin.labels), observables=tuple(lin.observables),
                           units=tuple(observable_map.unit for observable_map in ordered),
                           gains=gains, context=context, linear_range=linear_range, maps=ordered,
                           member=member if member is not None else functools.partial(_given, context))
