"""The resource guard (studies/_guard.py), the loader's limits on scene sizes, the empty [studies]
table and the frozen samples a file records."""

from __future__ import annotations

import math
import tracemalloc

import numpy as np
import pytest

import mechanisms
import studies
from studies import MechanismProblem, ResourceError, _mechanism, estimate, guard, kinds  # _mechanism: caches
from studies._cost import format_bytes, format_seconds  # the guard's message formatting: no public face
from studies._guard import memory_limit  # the guard's limit from the machine: no public face
from studies.cli import _run as _plan  # patched: the run the command would start
from studies.cli import load_scene, main

ELEMENTS = "links.coupler.discretisation.n_elements"


def _scene(tmp_path, table: str, scene: str = "four_bar_fem4") -> str:
    path = tmp_path / "scene.toml"
    path.write_text(mechanisms.load(scene).to_toml() + table)
    return str(path)


def _checked(kind: str, table: dict, n_steps: int = 256) -> dict:
    return kinds()[kind].check(f"studies.{kind}", table, n_steps)


@pytest.fixture(scope="module")
def four_bar():
    return MechanismProblem.from_mechanism(mechanisms.load("four_bar_fem4"))


# ---------------------------------------------------------------------------------------------------
# estimates
# ---------------------------------------------------------------------------------------------------
def test_the_memory_estimate_of_a_steady_state_bounds_its_traced_peak(four_bar):
    # an independent measurement: numpy reports its allocations to tracemalloc
    options = _checked("steady_state", {"n_steps": 128})
    kinds()["steady_state"].run(four_bar, options)  # warm: JIT and caches of the scene
    _mechanism._families.clear()
    tracemalloc.start()
    kinds()["steady_state"].run(four_bar, options)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    guess = estimate(four_bar, "steady_state", options).memory
    assert peak <= guess <= 10 * peak


def test_estimates_grow_with_the_sizes_as_the_cost_model_says(four_bar):
    small = estimate(four_bar, "sweep", _checked("sweep", {"start": 50.0, "stop": 150.0, "count": 10}))
    many = estimate(four_bar, "sweep", _checked("sweep", {"start": 50.0, "stop": 150.0, "count": 1000}))
    assert small.sizes == "10 speeds x 256 steps x 12 coordinates"
    # the points' solves grow 100 times, the one linearisation of the speed family does not
    assert 10 < many.time / small.time < 100
    fine = estimate(four_bar, "steady_state", _checked("steady_state", {"n_steps": 1024}))
    coarse = estimate(four_bar, "steady_state", _checked("steady_state", {"n_steps": 256}))
    assert fine.memory / coarse.memory == pytest.approx(1025 / 257)
    assert fine.time > coarse.time
    # twice the workers: shorter, and each worker holds its own linearisation
    parallel = estimate(four_bar, "sweep", _checked("sweep", {"start": 50.0, "stop": 150.0, "count": 1000}),
                        workers=2)
    assert parallel.time < many.time and parallel.memory > many.memory


def test_a_study_is_sized_at_the_largest_number_of_elements_on_its_axes(four_bar):
    problem = MechanismProblem.from_mechanism(mechanisms.load("four_bar_fem4"), parameter_paths=(ELEMENTS,))
    options = _checked("error_cost", {"resolution": {"parameter": ELEMENTS, "values": [1, 2, 8]}})
    largest = mechanisms.assemble(problem.mechanism({ELEMENTS: 8.0}))
    assert f"{largest.n_coords - largest.n_constraints} coordinates" in estimate(problem, "error_cost", options).sizes
    nominal = estimate(four_bar, "steady_state", _checked("steady_state", {}))
    assert "12 coordinates" in nominal.sizes


MODES = "links.coupler.discretisation.modes"


def test_a_reduced_link_is_sized_by_its_modes_and_corrections_not_its_elements():
    """A 64-element coupler reduced to 6 modes counts the 9 coordinates it assembles to (6 modes, 3
    static corrections), not its element model's 192; the steady state adds the reduction check
    (modes + 2); a grid over ``modes`` is sized at its largest mode count."""
    reduced = mechanisms.load("four_bar_fem4").with_parameters({ELEMENTS: 64, MODES: 6})
    problem = MechanismProblem.from_mechanism(reduced, parameter_paths=(MODES,))
    model = mechanisms.assemble(reduced)
    assert model.n_coords - model.n_constraints == 9
    steady = estimate(problem, "steady_state", _checked("steady_state", {}))
    assert steady.sizes == "256 steps x 9 coordinates + the reduction check at 11"
    full = estimate(MechanismProblem.from_mechanism(
        mechanisms.load("four_bar_fem4").with_parameters({ELEMENTS: 64})),
        "steady_state", _checked("steady_state", {}))
    assert "192 coordinates" in full.sizes and full.time > 10 * steady.time
    chart = estimate(problem, "stability_chart", _checked("stability_chart", {
        "x": {"parameter": "speed", "values": [50.0, 100.0]},
        "y": {"parameter": MODES, "values": [2, 20]}}))
    largest = mechanisms.assemble(problem.mechanism({MODES: 20.0}))
    assert f"{largest.n_coords - largest.n_constraints} coordinates" in chart.sizes
    assert largest.n_coords - largest.n_constraints == 23


def test_units_of_the_messages():
    assert format_bytes(2.3 * 2**30) == "2.3 GiB" and format_bytes(512) == "512 B"
    assert format_seconds(3 * 3600.0) == "3 h" and format_seconds(40.0) == "40 s"
    assert format_seconds(1.5 * 86400) == "1.5 days"
    assert 0 < memory_limit() <= 4 * 2**30


# ---------------------------------------------------------------------------------------------------
# refusing, and --force
# ---------------------------------------------------------------------------------------------------
HUGE_SWEEP = "\n[studies.sweep]\nstart = 20.0\nstop = 400.0\ncount = 100000\nn_steps = 65536\n"


def test_a_study_above_the_limits_is_refused_with_its_estimate(tmp_path):
    with pytest.raises(ResourceError) as error:
        load_scene(_scene(tmp_path, HUGE_SWEEP))
    message = str(error.value)
    assert message.startswith("sweep: about ") and "100000 speeds x 65536 steps x 12 coordinates" in message
    assert "limits" in message and "--force" in message
    assert isinstance(error.value, studies.StudiesError)


def test_force_runs_it_anyway(tmp_path):
    problem, declared = load_scene(_scene(tmp_path, HUGE_SWEEP), force=True)
    assert declared["sweep"]["values"].size == 100000
    estimates = guard(problem, declared, force=True)
    assert estimates[0].time > 2 * 3600.0


def test_all_studies_together_are_held_to_the_time_limit(four_bar):
    # a sweep and a Campbell diagram each estimated at about 60 % of the limit
    def table(kind: str, count: int) -> dict:
        return _checked(kind, {"start": 50.0, "stop": 150.0, "count": count, "n_steps": 16384})

    def count(kind: str) -> int:
        # the time of the points grows in proportion to their count, on top of a fixed part (the
        # error budget's mesh term at the headline points)
        first, second = (estimate(four_bar, kind, table(kind, n)).time for n in (1000, 2000))
        per_point = (second - first) / 1000
        return round((0.6 * 7200.0 - (first - 1000 * per_point)) / per_point)

    counts = {kind: count(kind) for kind in ("sweep", "campbell")}
    declared = {kind: table(kind, count) for kind, count in counts.items()}
    assert all(0.4 * 7200.0 < e.time < 7200.0 for e in guard(four_bar, declared, force=True))
    with pytest.raises(ResourceError, match="^all studies together: about 2.. h estimated .sweep 1.. h, "
                                            "campbell 1.. h.; limits"):
        guard(four_bar, declared)


def test_flexvib_run_refuses_exit_2_no_file_and_force_passes(tmp_path, monkeypatch, capsys):
    scene, out = _scene(tmp_path, HUGE_SWEEP), tmp_path / "out.h5"
    assert main(["run", scene, "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("flexvib: error: sweep: about") and err.count("\n") == 1
    assert not out.exists()
    started = []
    monkeypatch.setattr(_plan, "run_plan", lambda *args, **kwargs: started.append(args) or ({}, {}))
    assert main(["run", scene, "--out", str(out), "--quiet", "--force"]) == 0
    assert len(started) == 1


def test_a_value_the_scene_cannot_take_is_refused_before_anything_runs(tmp_path):
    # the guard builds the scene at the ends of every axis
    table = ("\n[studies.stability_chart]\nx = { parameter = 'speed', values = [50.0, 100.0] }\n"
             "y = { parameter = 'links.coupler.thickness', values = [1.6e-3, -1.0e-3] }\n")
    with pytest.raises(mechanisms.MechanismError, match="thickness"):
        load_scene(_scene(tmp_path, table))


# ---------------------------------------------------------------------------------------------------
# [studies] tables: empty, sizes
# ---------------------------------------------------------------------------------------------------
def test_an_empty_studies_table_lists_the_kinds_and_a_missing_one_runs_the_defaults(tmp_path, capsys):
    scene = _scene(tmp_path, "\n[studies]\n")
    assert main(["run", scene, "--out", str(tmp_path / "out.h5"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "declares no study" in err and all(f"[studies.{kind}]" in err for kind in kinds())
    assert not (tmp_path / "out.h5").exists()
    _, declared = load_scene(_scene(tmp_path, ""))
    assert set(declared) == {"steady_state", "sweep", "campbell", "nonlinear_check"}


@pytest.mark.parametrize("table, message", [
    ("[studies]\nn_steps = 65540\n[studies.steady_state]\n", "[studies] n_steps: at most 65536"),
    ("[studies.steady_state]\nn_steps = 131072\n", "[studies.steady_state] n_steps: at most 65536"),
    ("[studies.sweep]\nstart = 1.0\nstop = 2.0\ncount = 100001\n", "count: at most 100000"),
    ("[studies.sweep]\nvalues = [1.0, 2.0]\nmax_harmonic = 1000000000\n", "max_harmonic: at most 100"),
    ("[studies.campbell]\nvalues = [1.0, 2.0]\nn_steps = 32\nfrozen_samples = 64\n",
     "frozen_samples: at most 32 (samples are taken among the n_steps = 32 steps"),
    ("[studies.campbell]\nvalues = [2.0, 1.0]\n", "positive, increasing crank speeds"),
    ("[studies.nonlinear_check]\nn_periods = 10001\n", "n_periods: at most 10000"),
    ("[studies.nonlinear_check]\nfrom_rest = true\nmax_periods_from_rest = 100000\n", "at most 10000"),
    ("[studies.nonlinear_check]\ntolerance = -0.1\n", "tolerance: expected a fraction in [0, 1)"),
    ("[studies.error_cost]\nn_steps = [32, 16]\n", "[studies.error_cost] n_steps: expected increasing"),
    (f"[studies.error_cost]\nn_steps = {list(range(2, 40, 2))}\n", "at most 16 even step counts"),
    ("[studies.stability_chart]\nx = {values = [1.0, 2.0]}\ny = {values = [1.0, 2.0]}\n", "different parameters"),
])
def test_size_keys_of_the_studies_tables_have_limits(table, message, tmp_path, capsys):
    out = tmp_path / "out.h5"
    assert main(["run", _scene(tmp_path, "\n" + table), "--out", str(out), "--quiet"]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_values_of_an_axis_have_a_limit():
    with pytest.raises(studies.StudiesError, match="values: at most 100000"):
        _checked("sweep", {"values": [1.0] * 100001})


# ---------------------------------------------------------------------------------------------------
# loader limits
# ---------------------------------------------------------------------------------------------------
def _four_bar_text(**changes) -> str:
    """four_bar_fem4 with keys changed (``links__coupler__discretisation`` for a nested key)."""
    # the scene writer (no public face) checks no sizes: it writes any spec
    from mechanisms._parts.spec import dumps

    spec = mechanisms.load("four_bar_fem4").to_spec()
    for path, value in changes.items():
        *parents, key = path.split("__")
        table = spec
        for parent in parents:
            table = table[parent]
        table[key] = value
    return dumps(spec)


@pytest.mark.parametrize("changes, message", [
    ({"links__coupler__discretisation": {"type": "fem", "n_elements": 1000}},
     "links.coupler.discretisation.n_elements must be at most 128"),
    ({"links__coupler__discretisation": {"type": "ritz", "n_bending": 65}},
     "links.coupler.discretisation.n_bending must be at most 64"),
    ({"links__coupler__discretisation": {"type": "ritz", "n_axial": 1000000000}}, "n_axial must be at most 64"),
    ({"period": 2 * math.pi, "drive__rate": 1.0e6}, "turns 1e+06 times per period; at most 100"),
    ({"drive__harmonics": [[1000000000, 0.0, 0.1]]}, "harmonics[0] order k must be an integer from 1 to 1000"),
    ({"drive__harmonics": [[k, 0.0, 1e-3] for k in range(1, 200)]}, "at most 100"),
])
def test_size_like_scene_keys_are_refused_when_read(changes, message):
    with pytest.raises(mechanisms.MechanismError) as error:
        mechanisms.loads(_four_bar_text(**changes))
    assert message in str(error.value)


def test_the_limits_themselves_are_accepted():
    assert mechanisms.Fem(128).n_elements == 128 and mechanisms.Ritz(64, 64).n_axial == 64
    with pytest.raises(mechanisms.MechanismError, match="from 1 to 128"):
        mechanisms.Fem(129)
    # 100 turns per period: the most a drive may turn
    assert mechanisms.loads(_four_bar_text(period=2 * math.pi, drive__rate=100.0)).period == 2 * math.pi


def test_a_scene_file_that_is_not_text_is_a_mechanism_error(tmp_path):
    path = tmp_path / "binary.toml"
    path.write_bytes(b"\xff\xfe\x00name")
    with pytest.raises(mechanisms.MechanismError, match="not UTF-8"):
        mechanisms.load(path)


# ---------------------------------------------------------------------------------------------------
# frozen samples: the file records the number used
# ---------------------------------------------------------------------------------------------------
def test_campbell_and_sweep_record_the_frozen_samples_they_used(crossing_problem):
    problem = crossing_problem()
    campbell = studies.campbell(problem, [1.0, 1.5], n_steps=32, frozen_samples=64)
    assert campbell.settings["frozen_samples"] == 32
    assert campbell.crank_angle.shape == (32,) and campbell.frozen.shape[1] == 32
    assert _checked("campbell", {"values": [1.0, 2.0], "n_steps": 32})["frozen_samples"] == 32
    assert _checked("campbell", {"values": [1.0, 2.0]}, n_steps=256)["frozen_samples"] == 64
    sweep = studies.sweep(problem, "speed", [1.0, 1.5], n_steps=16)
    assert sweep.settings["frozen_samples"] == 16
    with pytest.raises(studies.StudiesError, match="frozen_samples"):
        studies.campbell(problem, [1.0, 1.5], n_steps=32, frozen_samples=1)
    assert np.isfinite(sweep.frozen_mean).all()
