"""The batched evaluations of an assembled model along a sampled motion (``Model.*_along``, one
kernel call per quantity, numpy summing the terms) equal the model's own per-sample methods (the
path ``mechanisms.*_along`` takes for any other ``ConstrainedModel``), on a mechanism with every
kind of term: elastic links with geometric stiffening, gravity, damping, point masses and a torque
drive."""

import numpy as np
import pytest

import mechanisms as mc

_BATCHED = ("linear_terms_along", "inertia_residual_along", "constraint_terms_along")


class _ProtocolOnly:
    """Hides the model's batched methods so that ``mechanisms.*_along`` takes its sample-by-sample
    path through the protocol's methods."""

    def __init__(self, model):
        self._model = model

    def __getattr__(self, name):
        if name in _BATCHED:
            raise AttributeError(name)
        return getattr(self._model, name)


def test_batched_terms_equal_method_by_method_evaluation():
    base = mc.four_bar(discretisation="fem", n_elements=2, gravity=(0.0, -9.81))
    mechanism = base.replace(
        drives=(mc.TorqueDrive("O", rate=100.0, kp=30.0, kd=0.4),),
        point_masses=(mc.PointMass("coupler", 0.1, 0.05, 1e-5),))
    model = mc.assemble(mechanism, feedforward=lambda t: 0.3 * np.sin(100.0 * t))
    rng = np.random.default_rng(3)
    n, r, n_samples = model.n_coords, model.n_constraints, 5
    t = rng.uniform(0, 0.06, n_samples)
    S = rng.standard_normal((n_samples, n))
    S[:, model.elastic_index] *= 1e-3
    Sd, Sdd = rng.standard_normal((2, n_samples, n))
    Lam = rng.standard_normal((n_samples, r))
    fast = mc.linear_terms_along(model, t, S, Sd, Sdd, Lam)
    slow = mc.linear_terms_along(_ProtocolOnly(model), t, S, Sd, Sdd, Lam)
    for name in ("mass", "damping", "stiffness", "residual", "jacobian"):
        # Same element kernels, same operations up to summation order: round-off only.
        a, b = getattr(fast, name), getattr(slow, name)
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-13 * np.abs(b).max(), err_msg=name)


def test_batched_inertia_residual_equals_the_model_methods():
    mechanism = mc.four_bar(discretisation="ritz", gravity=(0.0, -9.81)).replace(
        drives=(mc.TorqueDrive("O", rate=80.0, kp=5.0, kd=0.1),))
    model = mc.assemble(mechanism, feedforward=lambda t: 0.2 * np.cos(80.0 * t))
    rng = np.random.default_rng(11)
    n_samples = 4
    t = rng.uniform(0, 0.08, n_samples)
    S, Sd, Sdd = rng.standard_normal((3, n_samples, model.n_coords))
    S[:, model.elastic_index] *= 1e-3
    fast = model.inertia_residual_along(t, S, Sd, Sdd)
    slow = np.stack([model.mass_matrix(S[k]) @ Sdd[k] - model.forces(S[k], Sd[k], t[k])
                     for k in range(n_samples)])
    np.testing.assert_array_equal(mc.inertia_residual_along(_ProtocolOnly(model), t, S, Sd, Sdd),
                                  slow)
    np.testing.assert_allclose(fast, slow, rtol=0, atol=1e-13 * np.abs(slow).max())


def test_batched_constraint_terms_equal_the_model_methods():
    mechanism = mc.four_bar(discretisation="fem", n_elements=2).replace(
        drives=(mc.PrescribedDrive("O", rate=90.0, harmonics=((1, 0.05, 0.02), (3, 0.0, 0.01))),))
    model = mc.assemble(mechanism)
    rng = np.random.default_rng(13)
    n_samples = 4
    t = rng.uniform(0, 0.07, n_samples)
    S, Sd = rng.standard_normal((2, n_samples, model.n_coords))
    terms = model.constraint_terms_along(t, S, Sd, values=True)
    J, rate, gamma, phi = terms.jacobian, terms.rate, terms.gamma, terms.values
    assert model.constraint_terms_along(t, S).gamma is None
    assert model.constraint_terms_along(t, S).values is None
    slow = mc.constraint_terms_along(_ProtocolOnly(model), t, S, Sd, values=True)
    for name in ("jacobian", "rate", "gamma", "values"):
        a, b = getattr(terms, name), getattr(slow, name)
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-13 * np.abs(b).max(), err_msg=name)
    for k in range(n_samples):
        np.testing.assert_allclose(phi[k], model.constraints(S[k], t[k]), rtol=0, atol=1e-14)
        np.testing.assert_allclose(J[k], model.constraint_jacobian(S[k], t[k]), rtol=0, atol=1e-15)
        np.testing.assert_allclose(rate[k], model.constraint_rate(S[k], t[k]), rtol=0, atol=1e-15)
        np.testing.assert_allclose(gamma[k], model.constraint_gamma(S[k], Sd[k], t[k]), rtol=1e-13,
                                   atol=1e-13 * np.abs(gamma[k]).max())


def test_batched_evaluations_check_the_sample_shapes():
    """A multiplier array of the wrong width (the nominal motion's, with a drive row the model with
    feedforward does not have) is rejected, not read past its end."""
    mechanism = mc.four_bar(discretisation="fem", n_elements=2).replace(
        drives=(mc.TorqueDrive("O", rate=100.0, kp=3.0, kd=0.1),))
    model = mc.assemble(mechanism)
    n, r = model.n_coords, model.n_constraints
    t = np.zeros(3)
    S = np.zeros((3, n))
    with pytest.raises(ValueError, match=rf"lam must have shape \(3, {r}\).*\(3, {r + 1}\)"):
        model.linear_terms_along(t, S, S, S, np.zeros((3, r + 1)))
    with pytest.raises(ValueError, match=rf"sdot must have shape \(3, {n}\)"):
        model.inertia_residual_along(t, S, S[:2], S)
    with pytest.raises(ValueError, match="t must be a 1-d array"):
        model.constraint_terms_along(np.zeros((3, 1)), S)


def test_chunked_sums_equal_the_whole_motion_at_once(monkeypatch):
    """The (n, n) terms only summed into others (dQ/ds into the stiffness, the mass matrices of the
    inertia residual) are formed a chunk of samples at a time; chunks of 3 samples (the last one
    short) give the same numbers to the last bit as one chunk of all 7."""
    import mechanisms._batch as batch  # patched: the chunk size of the sums (internal)

    model = mc.assemble(mc.four_bar(discretisation="fem", n_elements=2, gravity=(0.0, -9.81)))
    rng = np.random.default_rng(17)
    n, r, n_samples = model.n_coords, model.n_constraints, 7
    t = rng.uniform(0, 0.06, n_samples)
    S, Sd, Sdd = rng.standard_normal((3, n_samples, n))
    S[:, model.elastic_index] *= 1e-3
    Lam = rng.standard_normal((n_samples, r))
    whole = model.linear_terms_along(t, S, Sd, Sdd, Lam), model.inertia_residual_along(t, S, Sd, Sdd)
    assert batch._chunks(n_samples, n)[1] == n_samples          # one chunk at this size
    monkeypatch.setattr(batch, "CHUNK_ENTRIES", 3 * n * n)
    assert batch._chunks(n_samples, n) == ([(0, 3), (3, 6), (6, 7)], 3)
    chunked = model.linear_terms_along(t, S, Sd, Sdd, Lam), model.inertia_residual_along(t, S, Sd, Sdd)
    for name in ("mass", "damping", "stiffness", "residual", "jacobian"):
        np.testing.assert_array_equal(getattr(chunked[0], name), getattr(whole[0], name), err_msg=name)
    np.testing.assert_array_equal(chunked[1], whole[1])
