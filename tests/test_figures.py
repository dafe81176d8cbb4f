"""What the figures say: no legend over data (checked with matplotlib's extents), titles that name the
scene and the point, numbers with their units, Campbell diagrams whose title, range and mode labels
match what is drawn, no negative frequency band in the summary, the nonlinear periodic state with its
error bars."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import studies
from studies import MechanismProblem, kind_of
from studies.cli import main
from tests._support.figure_text import legend_problems, text_problems


def _figures(results):
    import matplotlib.pyplot as plt

    for name, result in results.items():
        for suffix, draw in kind_of(result).figures(result).items():
            plot = draw()
            yield f"{name}{suffix}", plot
            plt.close(plot.figure)


def test_the_legend_checker_sees_a_legend_over_data():
    import matplotlib.pyplot as plt

    from studies._plots import legend_outside  # the figures' legend placement: no public face

    x = np.linspace(0.0, 1.0, 50)
    figure, ax = plt.subplots(layout="constrained")
    ax.plot(x, x, label="rising")          # through the lower left and the upper right
    ax.plot(x, 1.0 - x, label="falling")   # through the upper left and the lower right
    ax.legend(loc="upper left")
    assert any("covers 'falling'" in problem for problem in legend_problems(figure))
    ax.get_legend().remove()
    legend_outside(ax)
    assert legend_problems(figure) == []
    # a line crossing the legend between two vertices is seen too
    ax.get_legend().remove()
    ax.plot([0.0, 1.0], [0.5, 0.5], label="flat")
    ax.legend(loc="center")
    assert any("covers 'flat'" in problem for problem in legend_problems(figure))
    plt.close(figure)


@pytest.fixture(scope="module")
def mathieu_results(tmp_path_factory):
    """Every study kind with a demo table, on the Mathieu scene, written by ``flexvib run``."""
    path = tmp_path_factory.mktemp("figures") / "m.h5"
    assert main(["run", "mathieu", "--out", str(path), "--quiet"]) == 0
    return studies.load(path)


@pytest.mark.slow
def test_no_legend_covers_data_in_any_kind_s_figure(mathieu_results):
    for name, plot in _figures(mathieu_results):
        assert legend_problems(plot.figure) == [], name
        assert text_problems(plot.figure) == [], name


@pytest.fixture(scope="module")
def four_bar_check():
    """A short nonlinear check of the thesis four-bar at 60 rad/s."""
    problem = MechanismProblem.from_scene("four_bar_thesis")
    return studies.nonlinear_check(problem, {"speed": 60.0}, n_steps=64, n_periods=2)


@pytest.mark.slow
def test_nonlinear_check_title_names_scene_speed_and_units(four_bar_check):
    plot = four_bar_check.plot()
    assert plot.figure._suptitle.get_text() == "four_bar_thesis at speed 60 rad/s: nonlinear model against linear"
    title = plot.axes[0].get_title()
    assert title.startswith("coupler.deflection@0.5:")
    difference = studies._plots.plain(four_bar_check.difference["coupler.deflection@0.5"])
    assert f"max difference {difference} m " in title
    assert "estimated errors: linear " in title and title.count(" m,") + title.count(" m\n") >= 2
    assert legend_problems(plot.figure) == [] and text_problems(plot.figure) == []


@pytest.fixture(scope="module")
def fem4_campbell():
    return studies.campbell(MechanismProblem.from_scene("four_bar_fem4"), np.linspace(40.0, 240.0, 3),
                            n_steps=32, frozen_samples=8)


@pytest.mark.slow
def test_campbell_labels_range_and_error_match_what_is_drawn(fem4_campbell):
    labels = fem4_campbell.mode_labels
    assert len(set(labels)) == len(labels), labels   # finite elements: several modes peak at one slope
    plot = fem4_campbell.plot()
    ax = plot.axes[0]
    title = ax.get_title()
    assert "speeds 40–240 rad/s" in title and "shown to" not in title
    # the error the title states is the largest of the characteristic frequencies inside the axes
    top = ax.get_ylim()[1]
    drawn = np.asarray(fem4_campbell.characteristic) <= top
    stated = studies._plots.plain(np.nanmax(np.where(drawn, fem4_campbell.characteristic_error, np.nan)))
    assert f"error up to {stated} rad/s" in title
    entries = [t.get_text() for t in ax.get_legend().get_texts() if t.get_text().startswith("mode")]
    assert entries == [name for name in labels if name in plot.artists]
    assert legend_problems(plot.figure) == []


def test_a_negative_frozen_band_is_shown_as_a_growth_rate(mathieu_results):
    campbell = mathieu_results["campbell"]
    band_min = np.array(campbell.band_min, dtype=float)
    band_min[0, 0] = -138.0        # sign(lam) sqrt(|lam|): the frozen stiffness negative there
    negative = dataclasses.replace(campbell, band_min=band_min)
    rows = kind_of(negative).headlines(negative).rows
    band = next(row for row in rows if row.quantity.endswith("frozen frequency band"))
    assert str(band.value).startswith("0–") and "-" not in str(band.value)
    assert "growth rate up to 138 1/s" in band.where


def _orbit_result():
    """A nonlinear periodic state made up of known numbers (the figure, not the numerics, is tested)."""
    angle = np.linspace(0.0, 2 * np.pi, 33)
    response = 1e-3 * np.sin(angle)
    return studies.NonlinearSteadyState(
        problem="four_bar_thesis", scene="", parameters={"speed": 100.0}, units={"coupler.deflection@0.5": "m"},
        response={"coupler.deflection@0.5": response}, response_error={"coupler.deflection@0.5": 2e-5},
        linear_response={"coupler.deflection@0.5": 0.98 * response}, labels=("coupler.b1",),
        t=angle / 100.0, crank_angle=angle, x=response[:, None], state=np.array([0.0, 0.1]),
        multipliers=np.array([0.5 + 0.3j, 0.5 - 0.3j]), multiplier_errors=np.array([3e-4, 3e-4]),
        spectral_radius=float(abs(0.5 + 0.3j)), error_estimate=0.15, iterations=3, map_calls=8, residual=1e-9,
        status="ok", message="", is_stable=True, instability_kind="", n_steps=32, run_time=0.5,
        linear_run_time=0.1, shooting_run_time=0.4)


def test_nonlinear_periodic_state_figure_has_error_bars_and_no_bare_numbers():
    from matplotlib.collections import PolyCollection

    plot = _orbit_result().plot()
    response_axes, multiplier_axes = plot.axes
    band = [a for a in plot.artists["coupler.deflection@0.5"] if isinstance(a, PolyCollection)]
    assert len(band) == 1        # the nonlinear curve's error bar, +- 2e-5 m about it
    vertices = band[0].get_paths()[0].vertices
    assert np.ptp(vertices[:, 1]) == pytest.approx(2e-3 + 4e-5, rel=1e-3)
    assert "error estimate 2.0×10⁻⁵ m" in response_axes.get_title()
    radius_title = multiplier_axes.get_title()
    assert "± 3.0×10⁻⁴" in radius_title and "state error" not in radius_title
    assert plot.figure._suptitle.get_text().startswith("four_bar_thesis at speed 100 rad/s")
    assert legend_problems(plot.figure) == [] and text_problems(plot.figure) == []
