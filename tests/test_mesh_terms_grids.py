"""The mesh terms of a sweep's spectral radius and of a Campbell diagram's characteristic frequencies
(``studies._budget.grid_radius_mesh``, ``grid_frequency_mesh``; ``studies._mesh_error``), against
four_bar_fem4 with its coupler converged to 32 Hermite elements on the same time grid (assembled apart
from the studies: ``linearize.about``, ``periodic.floquet``), files written before the terms, and the
guard's cost of them."""

from __future__ import annotations

import dataclasses
import json
import math
import warnings

import h5py
import numpy as np
import pytest

import mechanisms
import studies
from studies import _budget as budget  # the budget's words are internal to the studies (tested here)
from studies import _cost as cost  # the guard's cost model's parts (tested here)
from studies._mesh_error import frequency_mesh_error, match_multipliers
from tests._support.older_files import as_format_2

N_STEPS = 64
#: Stable at 100 and 140 rad/s (two resolved modes there), inside the instability tongue at 185.
SPEEDS = (100.0, 140.0, 185.0)


def _floquet(n_elements: int, speed: float):
    """``(multipliers, resolved, period)`` of four_bar_fem4 with ``n_elements`` coupler elements."""
    import linearize
    import periodic

    mechanism = mechanisms.load("four_bar_fem4").with_parameters({"drive.rate": speed})
    links = tuple(dataclasses.replace(link, discretisation=mechanisms.Fem(n_elements))
                  if getattr(link, "discretisation", None) is not None else link for link in mechanism.links)
    system = linearize.about(mechanism.replace(links=links), n_steps=N_STEPS).system
    result = periodic.floquet(system)
    return np.asarray(result.multipliers), np.asarray(result.resolved), system.period


def _resolved_upper(multipliers, resolved):
    """The resolved multipliers of the upper half plane (one of each conjugate pair), by argument."""
    upper = multipliers[resolved & (multipliers.imag >= 0.0)]
    return upper[np.argsort(np.angle(upper))]


@pytest.fixture(scope="module")
def converged():
    """{speed: {n_elements: (multipliers, resolved, period)}} for 4 and 32 elements."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return {speed: {n: _floquet(n, speed) for n in (4, 32)} for speed in SPEEDS}


@pytest.fixture(scope="module")
def fem4():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        problem = studies.MechanismProblem.from_scene("four_bar_fem4")
        campbell = studies.campbell(problem, list(SPEEDS), n_steps=N_STEPS)
        sweep = studies.sweep(problem, "speed", list(SPEEDS), n_steps=N_STEPS)
    return problem, campbell, sweep


# ---------------------------------------------------------------------------------------------------
# the characteristic frequencies' term
# ---------------------------------------------------------------------------------------------------
def _true_shifts(converged, speed):
    """{multiplier index of the 4-element model: |frequency change to 32 elements|} (rad/s) for its
    resolved upper-half-plane multipliers, paired with the 32-element model's by their order in
    argument (the same number resolved in both: checked)."""
    (coarse, resolved, period), (fine, fine_resolved, _) = converged[speed][4], converged[speed][32]
    mine, theirs = _resolved_upper(coarse, resolved), _resolved_upper(fine, fine_resolved)
    assert mine.size == theirs.size >= 1, (speed, mine, theirs)
    truth = {}
    for value, reference in zip(mine, theirs):
        index = int(np.argmin(np.abs(coarse - value)))
        truth[index] = abs(np.angle(value) - np.angle(reference)) / period
    return truth


@pytest.mark.parametrize("speed", SPEEDS)
def test_the_frequency_term_covers_the_32_element_error_and_is_not_loose(fem4, converged, speed):
    problem, _, _ = fem4
    found = frequency_mesh_error(problem, {"speed": speed}, n_steps=N_STEPS)
    assert found.applicable and "known order 4" in found.method and "matched by their multipliers" in found.method
    multipliers = converged[speed][4][0]
    for index, true in _true_shifts(converged, speed).items():
        # the conjugate too: the same frequency, the same term
        for k in (index, int(np.argmin(np.abs(multipliers - multipliers[index].conjugate())))):
            estimate = found.error[k]
            assert math.isfinite(estimate), (speed, k)
            if true > 1e-9 * found.frequencies[k]:
                assert true <= estimate <= 3.0 * true, (speed, k, estimate, true)
            else:   # a frequency locked inside the tongue (half the speed's multiple): no change
                assert estimate <= 1e-9 * found.frequencies[k], (speed, k, estimate)
    # an unresolved (stiff) multiplier has no term: unknown, said in the method
    unresolved = ~converged[speed][4][1]
    assert np.isnan(found.error[unresolved]).all() and "unknown here" in found.method


def test_the_campbell_diagram_carries_the_frequencies_term(fem4, converged):
    _, campbell, _ = fem4
    term = campbell.characteristic_mesh_error
    assert term.shape == campbell.characteristic.shape
    np.testing.assert_array_equal(campbell.error_budget["characteristic"]["mesh"], term)
    for i, speed in enumerate(SPEEDS):
        for index, true in _true_shifts(converged, speed).items():
            # the headline speeds' largest relative error of the mode, applied to its frequency here
            assert term[i, index] >= true, (speed, index, term[i, index], true)
            assert term[i, index] <= 3.0 * true or term[i, index] <= 1e-3 * campbell.characteristic[i, index]
    methods = campbell.error_methods["mesh"]
    assert "characteristic frequencies: one refinement" in methods and "matched by their multipliers" in methods
    assert "unknown for a mode matched at none" in methods
    # the figure's title and the summary show the total and its terms where the time step's was shown
    title = campbell.plot().axes[0].get_title()
    drawn = campbell.characteristic <= campbell.plot().axes[0].get_ylim()[1]
    assert np.isfinite(term[drawn]).all()   # every drawn frequency has its term here: the total stated
    total = studies._plots.plain(np.nanmax(np.where(drawn, campbell.characteristic_error + term, np.nan)))
    assert f"frequencies' error up to {total} rad/s (time step" in title and ", mesh " in title
    rows = {row.quantity: row for row in studies.kinds()["campbell"].headlines(campbell).rows}
    assert "mesh" in rows["characteristic frequencies of the lowest modes"].value


def test_multipliers_match_only_where_the_nearest_is_clearly_nearest():
    candidates = np.array([0.5 + 0.5j, 0.9 + 0.1j, 0.9 + 0.1j, -0.3 + 0.0j])   # a repeated one is one
    found = match_multipliers(np.array([0.51 + 0.5j, 0.6 + 0.3j, np.nan]), candidates)
    assert found[0] == 0.5 + 0.5j
    # as near the two (0.5 + 0.5j: 0.22, 0.9 + 0.1j: 0.45) as a quarter of their distance allows: unmatched
    assert np.isnan(found[1]) and np.isnan(found[2])
    assert np.isnan(match_multipliers(np.array([0.5 + 0.5j]), np.array([np.nan])))[0]


def test_without_elastic_links_the_frequency_term_does_not_apply():
    mathieu = studies.mathieu_problem(damping_ratio=0.02, force=0.0)
    found = frequency_mesh_error(mathieu, {"speed": 0.5}, n_steps=32)
    assert not found.applicable and found.method.startswith("not applicable")
    result = studies.campbell(mathieu, [0.2, 0.4], n_steps=32)
    assert result.characteristic_mesh_error is None
    assert result.error_budget["characteristic"]["mesh"] == budget.NOT_APPLICABLE
    assert "(mesh: not applicable)" in result.plot().axes[0].get_title()


def _drop(path, group, dataset, method_key):
    """As a file written before the term (format 2 here: a file without the dataset carries no
    checksum of it): ``dataset`` absent, ``method_key`` not in the methods."""
    with h5py.File(path, "a") as handle:
        del handle[f"{group}/{dataset}"]
        methods = json.loads(handle[group].attrs["error_methods"])
        if method_key in methods:
            del methods[method_key]
        else:
            methods["mesh"] = methods["mesh"].split("; characteristic frequencies:")[0]
        handle[group].attrs["error_methods"] = json.dumps(methods)
        as_format_2(handle, group)


def test_a_campbell_file_written_before_the_frequency_term_reads_not_estimated(fem4, tmp_path):
    _, campbell, _ = fem4
    path = tmp_path / "campbell.h5"
    campbell.save(path)
    again = studies.load(path)["campbell"]
    np.testing.assert_array_equal(again.characteristic_mesh_error, campbell.characteristic_mesh_error)
    _drop(path, "campbell", "characteristic_mesh_error", "")
    old = studies.load(path)["campbell"]
    assert old.characteristic_mesh_error is None
    assert old.error_budget["characteristic"]["mesh"] == budget.NOT_ESTIMATED
    assert "(mesh: not estimated)" in old.plot().axes[0].get_title()


# ---------------------------------------------------------------------------------------------------
# the sweep's spectral radius
# ---------------------------------------------------------------------------------------------------
def test_the_sweep_radius_term_covers_the_32_element_error(fem4, converged):
    from studies._mesh_error import radius_mesh_error

    problem, campbell, sweep = fem4
    term = sweep.spectral_radius_mesh_error
    assert term is not None and term.shape == sweep.spectral_radius.shape
    shares = []
    for i, speed in enumerate(SPEEDS):
        radius_4 = float(np.abs(converged[speed][4][0][converged[speed][4][1]]).max())
        radius_32 = float(np.abs(converged[speed][32][0][converged[speed][32][1]]).max())
        assert sweep.spectral_radius[i] == pytest.approx(radius_4, rel=1e-9)
        assert term[i] >= abs(radius_4 - radius_32), (speed, term[i], radius_4, radius_32)
        found = radius_mesh_error(problem, {"speed": speed}, n_steps=N_STEPS)
        shares.append(found.error / found.radius)
    # the headline speeds (the scene's, the largest radius, the one nearest 1: all on this grid) as a
    # stability chart's or a Campbell diagram's: the largest share applied to every point
    np.testing.assert_allclose(term, max(shares) * sweep.spectral_radius, rtol=1e-9)
    np.testing.assert_allclose(term, campbell.spectral_radius_mesh_error, rtol=1e-9)
    assert "headline points" in sweep.error_methods["spectral_radius_mesh"]
    rows = {row.quantity: row for row in studies.kinds()["sweep"].headlines(sweep).rows}
    row = rows["largest spectral radius"]
    k = int(np.argmax(sweep.spectral_radius))
    assert row.error == pytest.approx(sweep.spectral_radius_error[k] + term[k], rel=1e-12)
    assert "mesh up to" in rows["spectral radius error budget"].value


def test_a_sweep_point_is_judged_on_its_radius_total():
    """A time step fine enough that the radius's time-step error passes a tolerance its total does
    not: the mesh term makes the points inaccurate, the message naming it."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        problem = studies.MechanismProblem.from_scene("four_bar_fem4")
        sweep = studies.sweep(problem, "speed", [100.0], n_steps=1024, error_tolerance=2e-4)
    radius, step, mesh = (float(a[0]) for a in (sweep.spectral_radius, sweep.spectral_radius_error,
                                                 sweep.spectral_radius_mesh_error))
    assert step <= 2e-4 * radius < step + mesh and mesh > step, (radius, step, mesh)
    assert sweep.point_status[0] == "inaccurate"
    status, message = budget.radius_verdict(radius, step, 2e-4, mesh=mesh)
    assert status == "inaccurate" and "mostly mesh" in message and "spectral radius" in message
    assert message in sweep.point_message[0]
    # the time step's alone passes: without the term the radius would not be judged inaccurate
    assert budget.radius_verdict(radius, step, 2e-4) == ("ok", "")


def test_sweep_radius_term_not_applicable_skipped_and_in_older_files(fem4, tmp_path):
    mathieu = studies.sweep(studies.mathieu_problem(damping_ratio=0.02, force=0.0), "speed", [0.3, 0.5],
                            n_steps=32)
    assert mathieu.spectral_radius_mesh_error is None
    assert mathieu.error_methods["spectral_radius_mesh"].startswith("not applicable")
    rows = {row.quantity: row for row in studies.kinds()["sweep"].headlines(mathieu).rows}
    assert rows["spectral radius error budget"].value.startswith("time step, mesh not applicable")
    problem, _, sweep = fem4
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        alone = studies.sweep(problem, "speed", [100.0], n_steps=32, budget=False)
    assert alone.spectral_radius_mesh_error is None and "budget=False" in alone.error_methods["spectral_radius_mesh"]
    path = tmp_path / "sweep.h5"
    sweep.save(path)
    np.testing.assert_array_equal(studies.load(path)["sweep"].spectral_radius_mesh_error,
                                  sweep.spectral_radius_mesh_error)
    _drop(path, "sweep", "spectral_radius_mesh_error", "spectral_radius_mesh")
    old = studies.load(path)["sweep"]
    assert old.spectral_radius_mesh_error is None
    rows = {row.quantity: row for row in studies.kinds()["sweep"].headlines(old).rows}
    assert "largest spectral radius (time-step error; mesh not estimated)" in rows
    assert rows["spectral radius error budget"].value.startswith("time step, mesh not estimated")


# ---------------------------------------------------------------------------------------------------
# the guard's cost of the terms
# ---------------------------------------------------------------------------------------------------
def test_the_guard_counts_the_headline_solves_of_the_sweep_and_campbell():
    problem = studies.MechanismProblem.from_scene("four_bar_fem4")
    kinds = studies.kinds()
    sizes = cost.sizes_at(problem, {})
    refined = cost.Sizes(n=cost.MESH_REFINEMENT * sizes.n, m=cost.MESH_REFINEMENT * sizes.m)
    one_refined = cost.linearisation(128, refined)[1] + cost.solve_seconds(128, refined)
    one_plain = cost.linearisation(128, sizes)[1] + cost.solve_seconds(128, sizes)
    assert cost.sizes_at(problem, {}) == sizes
    speeds = np.linspace(50.0, 150.0, 5)
    sweep = kinds["sweep"].check("s", {"parameter": "speed", "values": list(speeds)}, 128)
    axis = ("speed", np.asarray(sweep["values"]))
    grid = cost.grid_cost("s", problem, [axis], 128, workers=1, frozen=32, point_doubles=lambda s: 8.0 * s.m + 4.0,
                          words=[cost.axis_words(*axis)], budget=True)
    grid = cost.with_reduction_check(grid, problem, {}, 128)
    # the response's mesh term at the scene's point (refined and user's solve), the radius's at three
    # headline speeds (the refined model's linearisation, a refined solve each)
    refined_solve = cost.solve_seconds(128, refined)
    found = kinds["sweep"].cost("s", problem, sweep, 1)
    assert found.time == pytest.approx(grid.time + 2 * one_refined + 2 * refined_solve + one_plain, rel=1e-12)
    options = kinds["campbell"].check("c", {"values": list(speeds)}, 128)
    axis = ("speed", np.asarray(options["speeds"]))
    frozen = options["frozen_samples"]
    grid = cost.grid_cost("c", problem, [axis], 128, frozen=frozen, workers=1,
                          point_doubles=lambda s: (frozen + s.m + 8.0) * s.m, words=[cost.axis_words(*axis)])
    grid = cost.with_reduction_check(grid, problem, {}, 128)
    # three headline speeds: a refined linearisation and solve (shared by the radius and the
    # frequencies) and the user's model's solve with 16 frozen samples (the frequencies') each
    found = kinds["campbell"].cost("c", problem, options, 1)
    assert found.time == pytest.approx(grid.time + 3 * (one_refined + cost.solve_seconds(128, sizes, frozen=16)),
                                       rel=1e-12)
