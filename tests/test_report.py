"""What an engineer reads off a run: the summary table, the report, the animation and the figures
(no overlapping or clipped text, the right abscissa, plates drawn as plates)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import studies
from studies import MechanismProblem, _kind, _summary, kind_of, kinds  # _kind, _summary: the summary table
from studies._drawing import frame_points, plate_corners  # the drawings' geometry: no public face
from studies._plots import plain  # the figures' number format: no public face
from studies.cli import _animate, main  # _animate: flexvib animate's machinery, no public face
from tests._support.figure_text import text_problems

FOUR_BAR_STUDIES = """
[studies]
n_steps = 32

[studies.steady_state]

[studies.sweep]
parameter = "speed"
start = 40.0
stop = 240.0
count = 21

[studies.campbell]
start = 40.0
stop = 240.0
count = 6
frozen_samples = 8
"""


@pytest.fixture(scope="module")
def mathieu_file(tmp_path_factory):
    """Every study kind on the Mathieu scene (fast, no mechanism), written by ``flexvib run``."""
    path = tmp_path_factory.mktemp("report") / "m.h5"
    assert main(["run", "mathieu", "--out", str(path), "--quiet"]) == 0
    return path


@pytest.fixture(scope="module")
def mechanism_steady():
    """Steady states of the six-bar (a three-pin plate) and the two-link arm (no crank)."""
    return {scene: studies.steady_state(MechanismProblem.from_scene(scene), n_steps=32)
            for scene in ("six_bar", "two_link_arm")}


@pytest.fixture(scope="module")
def four_bar_file(tmp_path_factory):
    """A four-bar steady state, a sweep through its resonances and a Campbell diagram."""
    import mechanisms

    folder = tmp_path_factory.mktemp("four_bar")
    scene = folder / "fb.toml"
    scene.write_text(mechanisms.load("four_bar_thesis").to_toml() + FOUR_BAR_STUDIES)
    path = folder / "fb.h5"
    assert main(["run", str(scene), "--out", str(path), "--quiet"]) == 0
    return path


# ---------------------------------------------------------------------------------------------------
# plain numbers
# ---------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("value, digits, text", [
    (302.0, 2, "300"), (299.6, 2, "300"), (51707.0, 3, "51700"), (13.6, 2, "14"), (0.0012, 2, "0.0012"),
    (1.0, 2, "1.0"), (1.234e-5, 2, "1.2×10⁻⁵"), (-2.5e-8, 2, "-2.5×10⁻⁸"), (1.5e7, 2, "1.5×10⁷"), (0.0, 2, "0"),
])
def test_plain_numbers_have_no_e_notation(value, digits, text):
    assert plain(value, digits) == text
    assert "e+" not in plain(value, digits) and "e-" not in plain(value, digits)


# ---------------------------------------------------------------------------------------------------
# the summary table and the report hold the results' numbers
# ---------------------------------------------------------------------------------------------------
def test_every_kind_names_its_headlines(mathieu_file):
    results = studies.load(mathieu_file)
    # the Mathieu file holds every kind with a demo table (those that run on a problem without a
    # mechanism); the kinds of the full nonlinear mechanism are summarised in test_nonlinear_steady.py,
    # the control comparison (a mechanism with a controller) in test_control_comparison.py
    demo_kinds = {name for name, kind in kinds().items() if kind.demo is not None}
    assert {kind_of(result).name for result in results.values()} == demo_kinds
    for name, kind in kinds().items():
        assert kind.headlines is not _kind._no_headlines, f"{name} has no headlines for the summary"
    for name, summary in _kind.summaries(results).items():
        assert summary.rows, name
        assert summary.status and math.isfinite(summary.run_time), name


def _headline_numbers(results):
    """The numbers the table must show, each worked out here from the results' fields."""
    steady, sweep = results["steady_state"], results["sweep"]
    ptp = float(np.ptp(steady.response["x"]))  # unit m: shown in mm
    best = int(np.nanargmax(sweep.peak_to_peak["x"]))
    lower = sweep.spectral_radius - sweep.spectral_radius_error
    assert steady.units["x"] == "m"
    return [f"{plain(1e3 * ptp, 3)} mm", f"± {plain(1e3 * steady.peak_to_peak_error['x'])} mm",
            f"{plain(steady.spectral_radius, 3)}", f"{plain(1e3 * sweep.peak_to_peak['x'][best], 3)} mm at speed "
            f"{plain(sweep.values[best], 3)} rad/s",
            *(f"{plain(a, 3)}–{plain(b, 3)}" for a, b in sweep.instabilities),
            *(f"{k}:{mode + 1} at {plain(value, 3)}" for k, mode, value in sweep.resonances),
            f"{int(((results['stability_chart'].point_status == 'unstable')).sum())} of "
            f"{results['stability_chart'].done.size}"], lower


@pytest.mark.slow
def test_run_prints_the_table_with_the_headline_numbers(tmp_path, capsys):
    path = tmp_path / "m.h5"
    assert main(["run", "mathieu", "--out", str(path), "--quiet"]) == 0
    out = capsys.readouterr().out
    results = studies.load(path)
    expected, lower = _headline_numbers(results)
    # the table printed is the kinds' headlines laid out, and its cells hold the numbers (unwrapped)
    assert _summary.text_table(_kind.summaries(results)) in out
    table = _summary.text_table(_kind.summaries(results), width=1000)
    for text in expected:
        assert text in table, text
    assert (lower > 1).any() and "unstable" in table  # the sweep crosses the principal tongue
    for name in results:
        assert f"\n{name}" in table


@pytest.mark.slow
def test_report_writes_markdown_html_and_the_figures(mathieu_file, tmp_path, capsys):
    outdir = tmp_path / "report"
    assert main(["report", str(mathieu_file), "--out", str(outdir)]) == 0
    markdown = (outdir / "report.md").read_text()
    page = (outdir / "report.html").read_text()
    results = studies.load(mathieu_file)
    expected, _ = _headline_numbers(results)
    for text in expected:
        assert text in markdown and text in page, text
    # every figure the report links is beside it, and each study has its section in run order
    links = [line.split("](")[1].rstrip(")") for line in markdown.splitlines() if line.startswith("![")]
    assert links and all((outdir / link).is_file() for link in links)
    sections = [line[3:] for line in markdown.splitlines() if line.startswith("## ")]
    assert sections == list(_kind.in_run_order(results))
    assert capsys.readouterr().out.splitlines()[0].endswith("report.md")


def test_report_output_folder_that_cannot_be_written_is_bad_input(mathieu_file, tmp_path, capsys):
    # was FileExistsError / FileNotFoundError, exit 1 "internal error"
    existing = tmp_path / "a_file"
    existing.write_text("")
    for out in (existing, "/proc/nope", existing / "below"):
        assert main(["report", str(mathieu_file), "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert err.startswith("flexvib: error: --out") and str(out) in err and len(err.splitlines()) == 1
    assert existing.read_text() == ""


# ---------------------------------------------------------------------------------------------------
# the drawing of a mechanism and its animation
# ---------------------------------------------------------------------------------------------------
def test_the_six_bar_drawing_holds_its_ground_pins_and_its_rigid_plate(mechanism_steady):
    steady = mechanism_steady["six_bar"]
    assert steady.ground_joints == ("O1", "O2", "O3") and steady.drive == "O1"
    for name, where in (("O1", (0.0, 0.0)), ("O2", (0.30, 0.0)), ("O3", (0.60, 0.0))):
        np.testing.assert_allclose(steady.joints[name], np.tile(where, (33, 1)), atol=1e-12)
    plate = steady.plates["plate"]  # O2, B and C: the plate's side lengths stay those of the scene
    assert plate.shape == (33, 3, 2)
    sides = sorted(np.linalg.norm(plate[0, i] - plate[0, i - 1]) for i in range(3))
    expected = sorted([0.15, 0.10, math.sqrt(0.15**2 + 0.10**2 - 2 * 0.15 * 0.10 * math.cos(math.radians(60)))])
    np.testing.assert_allclose(sides, expected, rtol=1e-9)
    for k in (0, 11):  # pins B and C are corners of the plate, O2 too
        corners = plate[k]
        for joint in ("B", "C", "O2"):
            assert np.min(np.linalg.norm(corners - steady.joints[joint][k], axis=1)) < 1e-9
    # the crank's end is pin A, wherever the crank is
    np.testing.assert_allclose(steady.rigid_outlines["crank"][:, -1], steady.joints["A"], atol=1e-12)


def test_another_magnification_is_the_deflection_scaled(mechanism_steady):
    """Outlines redrawn at another magnification agree with outlines computed at it directly."""
    problem = MechanismProblem.from_scene("two_link_arm")
    steady = mechanism_steady["two_link_arm"]
    linear = problem.linearize(None, n_steps=32)
    direct, magnification = problem.outlines(linear, steady.x, magnification=3.0)
    assert magnification == 3.0
    for k in (0, 7, 20):
        outlines, _, _ = frame_points(steady, k, 3.0)
        for name in direct:
            np.testing.assert_allclose(outlines[name], direct[name][k], atol=1e-12)


def test_plate_corners_go_round_their_centre():
    from mechanisms import RigidLink

    link = RigidLink("plate", 1.0, 1.0, 0.1, points={"P": (0.5, 0.5), "Q": (0.5, -0.5)})
    corners = plate_corners(link)
    angles = np.unwrap(np.arctan2(*(corners - corners.mean(axis=0)).T[::-1]))
    assert (np.diff(angles) > 0).all() and corners.shape == (4, 2)


@pytest.mark.slow
def test_animation_opens_with_one_frame_per_sample(mechanism_steady, tmp_path):
    from PIL import Image

    steady = mechanism_steady["six_bar"]
    path, n_frames = _animate.animate(steady, tmp_path / "six.gif", max_frames=6)
    assert n_frames == _animate.frame_samples(32, 6).size == 6  # every 6th of 32 samples
    with Image.open(path) as movie:
        assert movie.n_frames == n_frames and movie.size == (640, 480)


@pytest.mark.slow
def test_animate_command(mechanism_steady, tmp_path, capsys, monkeypatch):
    from matplotlib import animation

    path = tmp_path / "arm.h5"
    mechanism_steady["two_link_arm"].save(path, "steady_state")
    assert main(["animate", str(path), "--magnification", "50", "--frames", "4"]) == 0
    assert "arm_steady_state.gif (4 frames)" in capsys.readouterr().out
    # an .mp4 without ffmpeg, an unknown study, a study with nothing to draw: bad input, exit 2
    monkeypatch.setattr(animation.writers, "is_available", lambda name: False)
    assert main(["animate", str(path), "--out", str(tmp_path / "a.mp4")]) == 2
    assert "needs ffmpeg" in capsys.readouterr().err
    assert main(["animate", str(path), "--study", "sweep"]) == 2
    assert "no study 'sweep'" in capsys.readouterr().err
    assert main(["animate", str(path), "--out", str(tmp_path / "a.png")]) == 2
    assert ".gif or .mp4" in capsys.readouterr().err
    # missing folders are created, as `run --out a/b.h5` does; a path that cannot hold the file is
    # bad input naming it (was FileNotFoundError, exit 1 "internal error")
    nested = tmp_path / "new" / "folder" / "arm.gif"
    assert main(["animate", str(path), "--out", str(nested), "--frames", "2"]) == 0 and nested.is_file()
    capsys.readouterr()
    for out in (path / "x.gif", "/proc/nope/x.gif", tmp_path):
        assert main(["animate", str(path), "--out", str(out), "--frames", "2"]) == 2
        err = capsys.readouterr().err
        assert err.startswith("flexvib: error: --out") and str(out) in err and len(err.splitlines()) == 1


def test_animate_refuses_a_file_without_a_mechanism(mathieu_file, capsys):
    assert main(["animate", str(mathieu_file)]) == 2
    assert "no study in the file holds a mechanism drawing" in capsys.readouterr().err


# ---------------------------------------------------------------------------------------------------
# figures: no overlapping or clipped text, the right abscissa, plates as plates
# ---------------------------------------------------------------------------------------------------
def _all_figures(results):
    import matplotlib.pyplot as plt

    for name, result in results.items():
        for suffix, draw in kind_of(result).figures(result).items():
            plot = draw()
            yield f"{name}{suffix}", plot
            plt.close(plot.figure)


def test_the_text_checker_sees_overlap_and_clipping():
    import matplotlib.pyplot as plt

    figure, ax = plt.subplots(figsize=(3, 2))
    ax.annotate("4:1", (0.5, 1.0), xycoords="axes fraction")
    ax.annotate("3:1", (0.51, 1.0), xycoords="axes fraction")
    ax.set_ylabel("a label much too long to fit beside an axes this short, so clipped")
    problems = text_problems(figure)
    plt.close(figure)
    assert any("'4:1' overlaps '3:1'" in p for p in problems)
    assert any("outside the figure" in p for p in problems)


@pytest.mark.slow
def test_mathieu_figures_have_clean_text(mathieu_file):
    for name, plot in _all_figures(studies.load(mathieu_file)):
        assert text_problems(plot.figure) == [], name


@pytest.mark.slow
def test_mechanism_figures_have_clean_text_and_the_right_abscissa(mechanism_steady):
    from matplotlib.patches import Polygon

    for scene, steady in mechanism_steady.items():
        for name, plot in _all_figures({scene: steady}):
            assert text_problems(plot.figure) == [], name
            if name == scene:  # the response: against the crank's angle, or time for the arm
                expected = "drive angle at O1 (deg)" if scene == "six_bar" else "time (s)"
                assert plot.axes[0].get_xlabel() == expected
            if name == f"{scene}_mechanism" and scene == "six_bar":
                assert all(isinstance(a, Polygon) and a.get_xy().shape[0] >= 3 for a in plot.artists["plate"])


@pytest.mark.slow
def test_four_bar_figures_have_clean_text(four_bar_file):
    results = studies.load(four_bar_file)
    sweep = results["sweep"]
    assert len(sweep.resonances) >= 3  # labels that would crowd: the checker holds them apart
    for name, plot in _all_figures(results):
        assert text_problems(plot.figure) == [], name
        if name == "campbell":  # the legend lists only modes drawn
            entries = [t.get_text() for t in plot.axes[0].get_legend().get_texts()]
            drawn_modes = [label for label in results["campbell"].mode_labels if label in plot.artists]
            assert [e for e in entries if e.startswith("mode")] == drawn_modes


def test_sweep_headlines_take_the_highest_peak_of_points_the_machine_reaches(mathieu_file):
    """At an unstable point the linear periodic solution is not what the machine does: the headline
    is the curve's highest peak (largest local maximum) among the other points, with its status, and
    the overall largest is named with its status."""
    import dataclasses

    sweep = studies.load(mathieu_file)["sweep"]
    values = np.asarray(sweep.peak_to_peak["x"], dtype=float)
    worst = int(np.nanargmax(values))
    status = np.array(sweep.point_status, dtype=object)
    status[:] = "ok"
    status[worst] = "unstable"
    marked = dataclasses.replace(sweep, point_status=status.astype(str))
    rows = {row.quantity: row for row in kinds()["sweep"].headlines(marked).rows}
    peak = rows["x peak to peak, highest peak"]
    assert peak.value < values[worst] and peak.where.endswith(": ok")
    index = int(np.flatnonzero(values == peak.value)[0])
    assert 0 < index < values.size - 1 and values[index] >= max(values[index - 1], values[index + 1])
    overall = rows["largest x peak to peak, any point"]
    assert overall.value == pytest.approx(values[worst]) and "unstable" in overall.where
    status[worst] = "ok"
    rows = {row.quantity: row for row in kinds()["sweep"].headlines(
        dataclasses.replace(sweep, point_status=status.astype(str))).rows}
    assert rows["x peak to peak, highest peak"].value == pytest.approx(values[worst])
    assert "largest x peak to peak, any point" not in rows


def test_sweep_headline_peak_is_a_local_maximum_not_the_last_point_before_a_threshold(mathieu_file):
    """A curve with a resonance bump rising into points outside the linear range: the last "ok" point
    before them is the largest "ok" value but no peak; the headline is the bump, with its status
    (issue 22: the four-bar's 3:1 resonance at 98 rad/s, not 17.8 mm at 120 rad/s)."""
    import dataclasses

    sweep = studies.load(mathieu_file)["sweep"]
    n = len(sweep.values)
    x = np.arange(n, dtype=float)
    bump, edge = n // 4, n // 2
    curve = 1.0 + 0.8 * np.exp(-((x - bump) / 2.0) ** 2) + np.where(x >= edge - 3, 0.5 * (x - edge + 4), 0.0)
    assert curve[edge - 1] > curve[bump]               # the last ok point is the largest ok value
    status = np.array(["ok"] * n, dtype=object)
    status[edge:] = "outside_linear_range"
    status[bump] = "near_resonance"                     # a peak's own status is allowed, and shown
    marked = dataclasses.replace(sweep, point_status=status.astype(str), peak_to_peak={"x": curve},
                                 peak_to_peak_error={"x": 0.01 * curve}, peak={}, peak_error={})
    rows = {row.quantity: row for row in kinds()["sweep"].headlines(marked).rows}
    peak = rows["x peak to peak, highest peak"]
    assert peak.value == pytest.approx(curve[bump]) and peak.where.endswith(": near_resonance")
    assert peak.error == pytest.approx(0.01 * curve[bump])
    # a curve rising to the end of the grid has no interior peak: its largest point, said so
    status[:] = "ok"
    rising = dataclasses.replace(marked, point_status=status.astype(str), peak_to_peak={"x": 1.0 + x})
    rows = {row.quantity: row for row in kinds()["sweep"].headlines(rising).rows}
    assert rows["x peak to peak, highest peak"].value == n and "no interior peak" in rows[
        "x peak to peak, highest peak"].where


@pytest.mark.parametrize("size", [(3.0, 2.5), (6.4, 4.8)])
def test_log_axes_have_readable_labels_at_any_range(size):
    """Data over a few percent of a decade, about a decade, or many decades (an error-against-cost
    figure's run times can be nearly equal): after ``tidy_log_axes`` no tick labels overlap and the
    data stay inside the limits."""
    import matplotlib.pyplot as plt

    from studies._plots import tidy_log_axes  # the figures' axis helper: no public face

    for low, high in [(2.1e-3, 2.5e-3), (1.2e-3, 3e-3), (3e-3, 2.2e-2), (1e-4, 1e-1), (1e-9, 1e3)]:
        figure, ax = plt.subplots(layout="constrained", figsize=size)
        ax.loglog([low, high], [high, low], "o-")
        tidy_log_axes(ax)
        assert text_problems(figure) == [], (low, high)
        for lower, upper in (ax.get_xlim(), ax.get_ylim()):
            assert lower <= low and upper >= high and np.log10(upper / lower) >= 1.2 - 1e-9
        plt.close(figure)
