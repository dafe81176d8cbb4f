"""The mesh term of the error budget (``studies/_mesh_error.py``) against converged discretisations
of the same scenes: Hermite elements refined to 16-32 elements, Ritz bases to 16 bending modes, all
on the same time grid (so that the comparison is the spatial error alone).

The estimate must cover the true error of the scene's own discretisation and not overstate it past
3x where that error is sizeable; the three-level route (Ritz, the Legendre extension) and the
terms that do not apply (no elastic link, a discretisation without a refinement) are checked too.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest

import mechanisms
import studies

# the module's function is the budget's internal interface (not exported); the reference solves
# use its plain steady response on purpose, the same route the estimate takes, and the studies'
# refined extremes
from studies._mesh_error import SAFETY_FACTOR, MeshError, mesh_error
from studies._mesh_error import _response as mesh_response
from studies._numerics import peak, peak_to_peak
from tests._support.extensions import Legendre, bending_1, bending_2

N_STEPS = 64
SPEED = {"speed": 100.0}


def _refined_to(mechanism, discretisation):
    links = tuple(dataclasses.replace(link, discretisation=discretisation)
                  if getattr(link, "discretisation", None) is not None else link for link in mechanism.links)
    return mechanism.replace(links=links)


def _response(mechanism, specs, speed, n_steps, scheme):
    """The plain steady response of ``mechanism`` (the route the estimate takes)."""
    problem = studies.MechanismProblem.from_mechanism(mechanism, observables=specs)
    return mesh_response(problem, speed, n_steps, scheme)


def _truth(mechanism, reference, specs):
    """{spec: (p2p error, response max abs error, peak error)} of ``mechanism`` against its
    ``reference`` discretisation, on the same time grid."""
    coarse = _response(mechanism, specs, SPEED, N_STEPS, "trapezoidal")
    fine = _response(_refined_to(mechanism, reference), specs, SPEED, N_STEPS, "trapezoidal")
    # the extremes refined as the studies report them (studies._numerics)
    return {spec: (abs(peak_to_peak(coarse[spec])[0] - peak_to_peak(fine[spec])[0]),
                   float(np.abs(coarse[spec] - fine[spec]).max()),
                   abs(peak(coarse[spec])[0] - peak(fine[spec])[0])) for spec in specs}


def _check_covers(estimate: MeshError, truth, *, peak_to_peak_of, least=0.0):
    for spec, (p2p, response, _) in truth.items():
        assert response <= estimate.response[spec] <= 3.0 * response, (spec, response, estimate.response[spec])
        if p2p > least * peak_to_peak_of[spec]:
            assert p2p <= estimate.peak_to_peak[spec] <= 3.0 * p2p, (spec, p2p, estimate.peak_to_peak[spec])


@pytest.fixture(scope="module")
def quiet():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yield


def test_four_bar_fem4_estimate_covers_the_32_element_error(quiet):
    mechanism = mechanisms.load("four_bar_fem4")
    problem = studies.MechanismProblem.from_mechanism(
        mechanism, observables=("coupler.deflection@0.5", "coupler.moment@0.5", "joint.B.fx",
                                "coupler.strain@0.5"))
    specs = problem.describe().observables
    estimate = mesh_error(problem, SPEED, n_steps=N_STEPS)
    assert estimate.applicable and "one refinement" in estimate.method and "n_elements 4 -> 8" in estimate.method
    truth = _truth(mechanism, mechanisms.Fem(32), specs)
    base = _response(mechanism, specs, SPEED, N_STEPS, "trapezoidal")
    _check_covers(estimate, truth, peak_to_peak_of={s: np.ptp(base[s]) for s in specs})
    # the deflection's estimate is the one-refinement formula with order 4, not a bound far above
    p2p, _, _ = truth["coupler.deflection@0.5"]
    assert estimate.peak_to_peak["coupler.deflection@0.5"] < 2.0 * p2p


@pytest.mark.slow
def test_six_bar_link4_peak_to_peak_below_the_16_element_value_is_covered(quiet):
    """The issue's case: link4's midspan peak-to-peak 2.6 % below the converged value with the
    scene's 2 elements per link, behind a time-step bar of 0.02 %."""
    mechanism = mechanisms.load("six_bar")
    problem = studies.MechanismProblem.from_mechanism(mechanism)
    specs = problem.describe().observables
    estimate = mesh_error(problem, SPEED, n_steps=N_STEPS)
    truth = _truth(mechanism, mechanisms.Fem(16), specs)
    base = _response(mechanism, specs, SPEED, N_STEPS, "trapezoidal")
    p2p = {s: np.ptp(base[s]) for s in specs}
    # 2.6 % at the default 256 steps, 3.0 % on this grid: the case of the issue
    assert 0.02 < truth["link4.deflection@0.5"][0] / p2p["link4.deflection@0.5"] < 0.04
    _check_covers(estimate, truth, peak_to_peak_of=p2p)
    for spec, (_, _, peak_error) in truth.items():
        assert peak_error <= estimate.peak[spec]


def test_ritz_estimate_from_three_levels_covers_the_16_mode_error(quiet):
    mechanism = mechanisms.load("four_bar_thesis")
    problem = studies.MechanismProblem.from_mechanism(
        mechanism, observables=("coupler.deflection@0.5", "coupler.moment@0.5", "coupler.strain@0.5"))
    specs = problem.describe().observables
    estimate = mesh_error(problem, SPEED, n_steps=N_STEPS)
    assert "three levels" in estimate.method and "n_bending 2 -> 4 -> 6" in estimate.method
    truth = _truth(mechanism, mechanisms.Ritz(16, 15), specs)
    base = _response(mechanism, specs, SPEED, N_STEPS, "trapezoidal")
    _check_covers(estimate, truth, peak_to_peak_of={s: np.ptp(base[s]) for s in specs}, least=1e-3)


def test_one_refinement_is_the_known_order_formula(quiet):
    """The estimate is SAFETY_FACTOR 2^p / (2^p - 1) times the difference from the 2x mesh."""
    mechanism = mechanisms.load("four_bar_fem4")
    problem = studies.MechanismProblem.from_mechanism(mechanism, observables=("coupler.deflection@0.5",
                                                                              "coupler.moment@0.5"))
    estimate = mesh_error(problem, SPEED, n_steps=N_STEPS)
    specs = problem.describe().observables
    coarse = _response(mechanism, specs, SPEED, N_STEPS, "trapezoidal")
    fine = _response(_refined_to(mechanism, mechanisms.Fem(8)), specs, SPEED, N_STEPS, "trapezoidal")
    for spec, order in (("coupler.deflection@0.5", 4), ("coupler.moment@0.5", 2)):
        factor = SAFETY_FACTOR * 2.0**order / (2.0**order - 1.0)
        assert estimate.response[spec] == pytest.approx(factor * np.abs(coarse[spec] - fine[spec]).max(), rel=1e-9)
    # the caller's response is used as given: the same estimate
    again = mesh_error(problem, SPEED, n_steps=N_STEPS, response=coarse)
    assert again.response == pytest.approx(estimate.response, rel=1e-9)


def test_legendre_extension_refines_through_its_own_method(quiet):
    """A user's discretisation that declares ``refined()`` and no order: three levels, and the
    estimate covers the error against a 12-polynomial basis."""
    base = mechanisms.load("four_bar_ritz")
    mechanism = _refined_to(base, Legendre(4, 1))
    problem = studies.MechanismProblem.from_mechanism(mechanism, observables=("coupler.deflection@0.5",))
    estimate = mesh_error(problem, SPEED, n_steps=N_STEPS)
    assert "three levels" in estimate.method and "n_bending 4 -> 6 -> 8" in estimate.method
    truth = _truth(mechanism, Legendre(12, 9), ("coupler.deflection@0.5",))
    p2p, response, _ = truth["coupler.deflection@0.5"]
    assert response <= estimate.response["coupler.deflection@0.5"]
    assert p2p <= estimate.peak_to_peak["coupler.deflection@0.5"]


def test_not_applicable_without_elastic_links_and_unknown_without_a_refinement():
    mathieu = mesh_error(studies.mathieu_problem(), {"speed": 0.7}, n_steps=32)
    assert not mathieu.applicable and mathieu.method.startswith("not applicable")
    assert np.isnan(mathieu.peak_to_peak["x"])
    shapes = mechanisms.UserShapes((bending_1, bending_2))
    mechanism = _refined_to(mechanisms.load("four_bar_ritz"), shapes)
    problem = studies.MechanismProblem.from_mechanism(mechanism, observables=("coupler.deflection@0.5",))
    unknown = mesh_error(problem, SPEED, n_steps=32)
    assert unknown.applicable and unknown.method.startswith("unknown") and "refined()" in unknown.method
    assert np.isnan(unknown.response["coupler.deflection@0.5"])


def test_discretisations_declare_their_refinement():
    assert mechanisms.Fem(4).refined() == mechanisms.Fem(8)
    assert mechanisms.Fem(3, modes=4).refined() == mechanisms.Fem(6, modes=4)
    assert mechanisms.Ritz(2, 1).refined() == mechanisms.Ritz(4, 3)
    assert mechanisms.Ritz(3, 0).refined() == mechanisms.Ritz(5, 0)
    fem = mechanisms.Fem(4)
    assert fem.convergence_order("deflection") == 4 and fem.convergence_order("moment") == 2
    assert fem.convergence_order("") == 4 and fem.convergence_order("curvature") is None
    assert getattr(mechanisms.Ritz(), "convergence_order", None) is None
    with pytest.raises(mechanisms.MechanismError, match="n_elements"):
        mechanisms.Fem(128).refined()


@pytest.mark.slow
@pytest.mark.parametrize("scene, reference", [("four_bar_fem1", mechanisms.Fem(32)),
                                              ("four_bar_controlled", mechanisms.Ritz(12, 11))])
def test_other_shipped_scenes_at_their_own_speed(quiet, scene, reference):
    """One element (50 % low: far from the asymptotic range, still covered within 3x) and a torque
    drive's Ritz coupler (0.56 %, three levels)."""
    mechanism = mechanisms.load(scene)
    problem = studies.MechanismProblem.from_mechanism(mechanism)
    speed = {"speed": problem.parameters["speed"]}
    specs = problem.describe().observables
    estimate = mesh_error(problem, speed, n_steps=128)
    coarse = mesh_response(studies.MechanismProblem.from_mechanism(mechanism, observables=specs), speed, 128,
                           "trapezoidal")
    fine = mesh_response(studies.MechanismProblem.from_mechanism(_refined_to(mechanism, reference),
                                                                 observables=specs), speed, 128, "trapezoidal")
    for spec in specs:
        true = abs(peak_to_peak(coarse[spec])[0] - peak_to_peak(fine[spec])[0])
        assert true <= estimate.peak_to_peak[spec] <= 3.0 * true, (spec, true, estimate.peak_to_peak[spec])
