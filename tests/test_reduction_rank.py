"""Issue 23: every ``modes`` the docs allow (1 up to the element model's coordinates) gives an
independent, well-scaled reduction basis, held to the full element model it reduces: its lowest
``modes`` frequencies are the element model's (the kept eigenmodes are in its span, so Rayleigh-Ritz
returns them exactly), every column's largest displacement along the link is about 1, and with every
coordinate kept the reduced four-bar's steady state is the element model's.

The failure it pins: the n-th bending mode of a pinned-pinned link of n elements has all its nodal
displacements zero; normalised by the largest *nodal* displacement (round-off) its column was scaled
by ~1e16 and the mass matrix came out singular (4 elements with 2 or more modes, 8 with 8)."""

import dataclasses

import numpy as np
import pytest
from scipy.linalg import eigh

import linearize
import mechanisms as mc
import periodic

FOUR_BAR = mc.load("four_bar_fem4")
LINK = FOUR_BAR.link("coupler")
SPEC = "coupler.deflection@0.5"


def _shapes(n_elements, modes=None, link=LINK):
    return mc.beam_shapes(dataclasses.replace(link, discretisation=mc.Fem(n_elements, modes=modes)))


def _frequencies(shapes):
    mass, stiffness = mc.beam_matrices(shapes)
    return np.sqrt(eigh(stiffness, mass, eigvals_only=True))


def _cases():
    for link in (LINK, dataclasses.replace(LINK, axial=False)):
        for n_elements in (1, 2, 3, 4, 8):
            n_full = len(_shapes(n_elements, link=link).labels)
            for modes in range(1, n_full + 1):
                yield pytest.param(link, n_elements, modes, id=f"axial{link.axial}-{n_elements}el-{modes}modes")


@pytest.mark.parametrize("link, n_elements, modes", list(_cases()))
def test_every_allowed_mode_count_keeps_the_element_models_lowest_frequencies(link, n_elements, modes):
    full = _shapes(n_elements, link=link)
    reduced = _shapes(n_elements, modes, link=link)
    mass, stiffness = mc.beam_matrices(reduced)
    # independent and well scaled: the reduced mass matrix is far from singular
    values = np.linalg.eigvalsh(mass)
    assert values.min() > 1e-10 * values.max(), (values.min(), values.max())
    exact = _frequencies(full)[:modes]
    kept = _frequencies(reduced)[:modes]
    assert np.allclose(kept, exact, rtol=1e-7, atol=0.0)
    # every column is a displacement amplitude: normalised to 1 at its largest sample (nodes and Gauss
    # points), so on another sampling its largest displacement is near 1, never ~1e16
    x = np.linspace(0.0, link.length, 8 * n_elements + 1)
    along = reduced.evaluate(x)
    peak = np.max(np.maximum(np.abs(along.u), np.abs(along.w)), axis=0)
    assert np.all(peak > 0.9) and np.all(peak < 1.5), peak


@pytest.mark.slow
@pytest.mark.parametrize("n_elements, modes", [(4, 2), (4, 12), (8, 6), (8, 8), (16, 12)])
def test_the_four_bar_reduced_runs_and_approaches_its_element_model(n_elements, modes):
    """The settings of issue 23 that failed with a singular mass matrix: the steady state runs, and is
    the element model's when every coordinate is kept (to round-off), near it otherwise."""
    def peak_to_peak(mechanism):
        linear = linearize.about(mechanism, n_steps=128, observables=[SPEC])
        state = periodic.steady_state(linear.system, estimate_error=False)
        return float(np.ptp(linear.observe(state.x)[SPEC]))

    change = {"links.coupler.discretisation.n_elements": n_elements}
    full = peak_to_peak(FOUR_BAR.with_parameters(change))
    reduced = peak_to_peak(FOUR_BAR.with_parameters({**change, "links.coupler.discretisation.modes": modes}))
    n_full = len(_shapes(n_elements).labels)
    assert reduced == pytest.approx(full, rel=1e-8 if modes == n_full else 2e-2)
