"""A new link discretisation defined outside the packages with public API only: a Ritz basis of
Legendre polynomials, registered with ``mechanisms.register_discretisation`` (defined in
``tests/_support/extensions.py``).

On ``xi = 2 x / L - 1`` in [-1, 1], bending ``P_{k+2}(xi) - P_k(xi)`` (zero at both pins, since
``P_n(+-1) = (+-1)^n``) and axial ``P_{j+1}(xi) + P_j(xi)`` (zero at the start). Checked against
what does not know of it: the exact bending and axial frequencies of a pinned-pinned beam
(Rayleigh-Ritz upper bounds converging as the basis grows) and the steady state of the thesis
four-bar against the Hermite element model extrapolated in its element size. Then through a
steady state, its result file, a sweep on a 2-worker process pool (forked after the registration,
so the workers know the class) and the scene text. The same shapes given as ``UserShapes`` of
module-level functions reach the studies too (named ``"module:qualname"`` in the scene); a lambda
is refused, saying why.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import scipy.linalg

import mechanisms
import studies
from tests._support import extensions
from tests._support.extensions import Legendre, axial_1, bending_1, bending_2

BASE = mechanisms.load("four_bar_ritz")
SPEC = "coupler.deflection@0.5"


def _with_coupler(discretisation, **changes) -> mechanisms.Mechanism:
    coupler = dataclasses.replace(BASE.link("coupler"), discretisation=discretisation, **changes)
    return BASE.replace(links=(BASE.links[0], coupler, BASE.links[2]))


def _frequencies(link, n):
    """The lowest ``n`` frequencies (rad/s) of the link alone (frame held fixed)."""
    mass, stiffness = mechanisms.beam_matrices(mechanisms.beam_shapes(link))
    return np.sqrt(scipy.linalg.eigh(stiffness, mass, eigvals_only=True)[:n])


def test_legendre_basis_converges_to_the_exact_beam_frequencies():
    coupler = BASE.link("coupler")
    wave = math.sqrt(coupler.youngs_modulus * coupler.second_moment / (coupler.density * coupler.area))
    bending_exact = (np.arange(1, 3) * math.pi / coupler.length) ** 2 * wave
    errors = []
    for n in (2, 4, 6, 8):
        link = dataclasses.replace(coupler, discretisation=Legendre(n, 0), axial=False)
        relative = _frequencies(link, 2) / bending_exact - 1.0
        assert np.all(relative > -1e-12)            # Rayleigh-Ritz: upper bounds
        errors.append(relative.max())
    assert errors[0] > errors[1] > errors[2] > errors[3] and errors[3] < 1e-7, errors
    # axial: u(0) = 0, free at the end pin (the chord frame): (2k - 1) pi / (2 L) sqrt(E / rho)
    axial_exact = (2 * np.arange(1, 3) - 1) * math.pi / (2 * coupler.length) * math.sqrt(
        coupler.youngs_modulus / coupler.density)
    link = dataclasses.replace(coupler, discretisation=Legendre(1, 10))
    mass, stiffness = mechanisms.beam_matrices(mechanisms.beam_shapes(link))
    axial = np.sqrt(scipy.linalg.eigh(stiffness[1:, 1:], mass[1:, 1:], eigvals_only=True)[:2])
    np.testing.assert_allclose(axial, axial_exact, rtol=1e-9)


def _peak_to_peak(mechanism, n_steps=128):
    """The coupler's peak-to-peak midspan deflection (m); every model on the same time grid, so
    that they differ by their space discretisation only."""
    result = studies.steady_state(studies.MechanismProblem.from_mechanism(mechanism), n_steps=n_steps)
    return result.peak_to_peak[SPEC]


def test_legendre_steady_state_converges_to_the_extrapolated_element_model():
    # cubic Hermite elements: the deflection converges as h^4, so Richardson on 8 and 16 elements
    coarse, fine = (_peak_to_peak(_with_coupler(mechanisms.Fem(n))) for n in (8, 16))
    reference = fine + (fine - coarse) / 15.0
    errors = [abs(_peak_to_peak(_with_coupler(Legendre(n, n // 2))) - reference) / reference
              for n in (4, 6, 8)]
    assert errors[0] > errors[1] > errors[2] and errors[2] < 1e-6, errors


def test_legendre_link_through_a_steady_state_its_file_and_a_two_worker_sweep(tmp_path, assert_same):
    mech = _with_coupler(Legendre(6, 2))
    assert mechanisms.loads(mech.to_toml()) == mech
    problem = studies.MechanismProblem.from_mechanism(mech)
    steady = studies.steady_state(problem, n_steps=64)
    path = tmp_path / "legendre.h5"
    steady.save(path, "steady")
    loaded = studies.load(path)["steady"]
    assert_same(steady, loaded)
    assert mechanisms.loads(loaded.scene).link("coupler").discretisation == Legendre(6, 2)
    speeds = [80.0, 100.0, 120.0]
    serial = studies.sweep(problem, "speed", speeds, n_steps=64)
    pool = studies.process_pool(2)
    try:
        with studies.open_file(tmp_path / "sweep.h5") as out:
            pooled = studies.sweep(problem, "speed", speeds, n_steps=64, executor=pool, out=out)
    finally:
        pool.shutdown()
    np.testing.assert_allclose(pooled.peak_to_peak[SPEC], serial.peak_to_peak[SPEC], rtol=1e-12)
    assert serial.peak_to_peak[SPEC][1] == pytest.approx(steady.peak_to_peak[SPEC], rel=1e-12)
    # the file resumes to the same grid (its scene, the resume identity, names the Legendre basis)
    with studies.open_file(tmp_path / "sweep.h5") as out:
        resumed = studies.sweep(problem, "speed", speeds, n_steps=64, out=out)
    assert_same(pooled, resumed)
    stored = studies.load(tmp_path / "sweep.h5")["sweep"]
    assert stored.done.all() and 'type = "legendre"' in stored.scene


def test_user_shapes_of_module_functions_reach_the_studies_and_lambdas_are_refused():
    user = mechanisms.UserShapes((bending_1, bending_2), (axial_1,))
    mech = _with_coupler(user)
    table = mech.to_spec()["links"]["coupler"]["discretisation"]
    where = extensions.__name__       # the module that defines the functions
    assert table == {"type": "user", "bending": [f"{where}:bending_1", f"{where}:bending_2"],
                     "axial": [f"{where}:axial_1"]}
    assert mechanisms.loads(mech.to_toml()) == mech
    # the same space as the registered class: the same answer
    assert _peak_to_peak(mech, 64) == pytest.approx(_peak_to_peak(_with_coupler(Legendre(2, 1)), 64),
                                                    rel=1e-12)
    with pytest.raises(mechanisms.MechanismError, match=r"lambda.*top level of an importable module"):
        studies.MechanismProblem.from_mechanism(
            _with_coupler(mechanisms.UserShapes((lambda x, length: bending_1(x, length),))))
    spec = mech.to_spec()
    spec["links"]["coupler"]["discretisation"]["bending"] = ["no_such_module_xyz:f"]
    with pytest.raises(mechanisms.MechanismError, match=r"discretisation.bending: cannot import"):
        mechanisms.build(spec)
