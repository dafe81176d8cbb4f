"""A new study kind defined here, outside the packages, with public API only (``studies.StudyKind``,
``studies.register_kind``, ``studies.Result``, ``studies.steady_solves``, ``studies.Summary``):
"peak_table", the steady state's peak to peak of each observable at a few speeds. Registered, it runs
through the ``flexvib`` entry point in-process (on a scene file declaring it, and in the built-in
mathieu scene through its demo table), its file loads back with ``studies.load``, and its numbers
are held to the closed form of the forced oscillator and to ``studies.steady_state`` itself."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Mapping

import h5py
import numpy as np
import pytest

import mechanisms
import studies
from studies.cli import main


# ---------------------------------------------------------------------------------------------------
# the new kind: its result class, table check, run, cost model, summary and headlines
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class PeakTable(studies.Result):
    """Peak to peak of each observable of the steady state at each speed.

    Attributes
    ----------
    problem : str
        The problem's name.
    speeds : ndarray, shape (n_speeds,)
        Crank speeds, rad/s.
    units : mapping of str to str
        Unit of each observable.
    peak_to_peak : mapping of str to ndarray, shape (n_speeds,)
        Peak to peak of each observable at each speed, in its unit.
    peak_to_peak_error : mapping of str to ndarray, shape (n_speeds,)
        Their estimated errors (N against N/2 steps).
    n_steps : int
        Steps per period.
    status, message : str
        The worst of the steady states' verdicts and its reason.
    run_time : float
        Seconds.
    """

    problem: str
    speeds: np.ndarray
    units: Mapping[str, str]
    peak_to_peak: Mapping[str, np.ndarray]
    peak_to_peak_error: Mapping[str, np.ndarray]
    n_steps: int
    status: str
    message: str
    run_time: float

    _units = {"speeds": "rad/s", "peak_to_peak": "@observables", "peak_to_peak_error": "@observables"}

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


def peak_table(problem: Any, speeds, *, n_steps: int = 64) -> PeakTable:
    started = time.perf_counter()
    steadies = [studies.steady_state(problem, {"speed": float(speed)}, n_steps=n_steps) for speed in speeds]
    specs = list(steadies[0].peak_to_peak)
    worst = max(steadies, key=lambda steady: steady.status != "ok")
    return PeakTable(problem=problem.name, speeds=np.asarray(speeds, dtype=float), units=dict(steadies[0].units),
                     peak_to_peak={s: np.array([steady.peak_to_peak[s] for steady in steadies]) for s in specs},
                     peak_to_peak_error={s: np.array([steady.peak_to_peak_error[s] for steady in steadies])
                                         for s in specs},
                     n_steps=n_steps, status=worst.status, message=worst.message,
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
    return peak_table(problem, options["speeds"], n_steps=options["n_steps"])


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


DEMO_SPEEDS = [0.5, 0.9, 1.4]

KIND = studies.StudyKind(name="peak_table", result=PeakTable, keys=("speeds", "n_steps"), check=_check, run=_run,
                         summary=_summary, headlines=_headlines, cost=_cost,
                         demo={"speeds": DEMO_SPEEDS, "n_steps": 64})


@pytest.fixture(scope="module", autouse=True)
def registered():
    return studies.register_kind(KIND)


# ---------------------------------------------------------------------------------------------------
def _oscillator_peak_to_peak(speed: float, *, natural_frequency=1.0, damping_ratio=0.02, force=1.0) -> float:
    """Twice the amplitude of x'' + 2 zeta w0 x' + w0^2 x = F cos(W t) in its steady state."""
    w0 = natural_frequency
    return 2.0 * force / math.hypot(w0**2 - speed**2, 2.0 * damping_ratio * w0 * speed)


def test_the_kind_is_registered_with_its_pieces():
    assert studies.kinds()["peak_table"] is KIND and studies.register_kind(KIND) is KIND  # idempotent
    with pytest.raises(studies.StudiesError, match="already registered"):
        studies.register_kind(studies.StudyKind(name="peak_table", result=PeakTable, keys=(), check=_check,
                                                run=_run, summary=_summary, cost=_cost))
    estimate = studies.estimate(studies.mathieu_problem(), "peak_table", {"speeds": DEMO_SPEEDS, "n_steps": 64})
    single = studies.estimate(studies.mathieu_problem(), "steady_state", {"values": {}, "n_steps": 64})
    # three solves one after the other: more time than one, the same peak memory
    assert "3 steady states x 64 steps" in estimate.sizes
    assert estimate.time > single.time and estimate.memory == single.memory


def test_its_numbers_meet_the_closed_form_of_the_forced_oscillator(tmp_path):
    """Without the parametric term (epsilon = 0) the Mathieu problem is the forced, damped oscillator,
    whose peak to peak is known in closed form; through the HDF5 round trip."""
    problem = studies.mathieu_problem(epsilon=0.0)
    result = KIND.run(problem, KIND.check("studies.peak_table", {"speeds": [0.5, 0.9, 1.4]}, 256))
    result.save(tmp_path / "table.h5")
    back = studies.load(tmp_path / "table.h5")["peak_table"]
    assert isinstance(back, PeakTable) and studies.kind_of(back) is KIND
    for speed, value, error in zip(back.speeds, back.peak_to_peak["x"], back.peak_to_peak_error["x"]):
        exact = _oscillator_peak_to_peak(speed)
        # within the estimated error of the peak to peak (the sampled extremes and the time step)
        assert abs(value - exact) <= 3.0 * error + 1e-3 * exact, (speed, value, exact, error)


def test_it_runs_in_the_mathieu_scene_through_its_demo_table(tmp_path, capsys):
    out = tmp_path / "mathieu.h5"
    assert main(["run", "mathieu", "--out", str(out), "--only", "peak_table", "--quiet"]) == 0
    assert "peak_table" in capsys.readouterr().out
    with h5py.File(out, "r") as handle:
        assert handle["peak_table"].attrs["kind"] == "peak_table"
    table = studies.load(out)["peak_table"]
    problem = studies.mathieu_problem()
    for speed, value in zip(DEMO_SPEEDS, table.peak_to_peak["x"]):
        direct = studies.steady_state(problem, {"speed": speed}, n_steps=64)
        assert value == pytest.approx(direct.peak_to_peak["x"], rel=1e-12)


def test_it_runs_on_a_scene_file_declaring_it(tmp_path, capsys):
    mechanism = mechanisms.load("four_bar_thesis")
    speed = 2.0 * math.pi / mechanism.period
    speeds = [0.8 * speed, 1.1 * speed]
    scene = tmp_path / "scene.toml"
    scene.write_text(mechanism.to_toml() + f"\n[studies]\nn_steps = 32\n\n[studies.peak_table]\nspeeds = {speeds!r}\n")
    out = tmp_path / "scene.h5"
    assert main(["run", str(scene), "--out", str(out), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "peak_table" in printed and "peak to peak at" in printed  # its line and its summary rows
    table = studies.load(out)["peak_table"]
    problem = studies.MechanismProblem.from_scene(str(scene))
    for k, value in enumerate(speeds):
        direct = studies.steady_state(problem, {"speed": value}, n_steps=32)
        for spec, values in table.peak_to_peak.items():
            assert values[k] == pytest.approx(direct.peak_to_peak[spec], rel=1e-9), spec
    # a bad table is refused with the kind's own message (exit code 2)
    scene.write_text(mechanism.to_toml() + "\n[studies.peak_table]\nspeeds = []\n")
    assert main(["run", str(scene), "--out", str(tmp_path / "bad.h5"), "--quiet"]) == 2
    assert "[studies.peak_table] speeds: expected a list of positive speeds" in capsys.readouterr().err


@pytest.mark.parametrize("change, message", [
    ({"name": "Peak table"}, "must be an identifier"),
    ({"name": "scheme"}, "is a key of the \\[studies\\] table"),
    ({"name": "peak_table_2", "cost": None}, "declares no cost model"),
    ({"name": "peak_table_2", "result": dict}, "result must be a subclass of studies.Result"),
    ({"name": "peak_table_2"}, "result class PeakTable is already the result of kind 'peak_table'"),
    ({"name": "peak_table_2", "grid": True}, "a grid study without a point function"),
    ({"name": "peak_table_2", "demo": [1.0]}, "demo must be a table"),
])
def test_a_kind_missing_a_piece_is_refused_at_registration(change, message):
    import dataclasses

    with pytest.raises(studies.StudiesError, match=message):
        studies.register_kind(dataclasses.replace(KIND, **change))
    assert set(studies.kinds()) >= {"peak_table"} and "peak_table_2" not in studies.kinds()
