"""periodic: the numba Newmark kernel against a slow, obvious numpy twin; the demo (``python -m periodic``
and ``studies.cli._demo.write_demo``) and its steady state against a long damped transient (scipy DOP853)."""

import os
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

import periodic
from periodic import __main__ as demo_command
from periodic import _demo as demo  # the demo's continuous M, C, K(t), f(t) (public: sampled only)
from periodic._newmark import (  # internal kernel and its solver paths: no public face
    SOLVE_INVERSE,
    SOLVE_LAPACK,
    SOLVE_LOOPS,
    march,
    mass_pivot_ratios,
)
from studies.cli._demo import write_demo  # flexvib demo's writer: no public face
from tests._support.newmark_twin import newmark_numpy

SOLVERS = [SOLVE_LOOPS, SOLVE_LAPACK, SOLVE_INVERSE]  # the kernels' linear-algebra paths


@pytest.mark.parametrize("solver", SOLVERS)
@pytest.mark.parametrize("n", [4, 10])  # plain loops and the BLAS path of the kernel
@pytest.mark.parametrize("beta, gamma", [(0.25, 0.5), (0.3025, 0.6), (0.0, 0.5)])
def test_kernel_matches_numpy_twin(beta, gamma, n, solver):
    rng = np.random.default_rng(7)
    n_steps, m = 30, 2 * n + 1
    M = rng.normal(size=(n_steps + 1, n, n)) * 0.2 + 2.0 * np.eye(n)  # random, non-symmetric, invertible
    C = rng.normal(size=(n_steps + 1, n, n))
    K = rng.normal(size=(n_steps + 1, n, n)) * 3.0
    f = rng.normal(size=(n_steps + 1, n))
    forced = rng.normal(size=m)
    x0, v0 = rng.normal(size=(n, m)), rng.normal(size=(n, m))
    h = 0.05
    expected = newmark_numpy(M, C, K, f, h, beta, gamma, forced, x0, v0)
    x, v, a = x0.copy(), v0.copy(), np.empty((n, m))
    hist = [np.empty((n_steps + 1, n, m)) for _ in range(3)]
    status = march(M, C, K, f, h, beta, gamma, forced, x, v, a, *hist, solver)
    assert status == -1
    # Same operations in a different order: differences are rounding, ~ n_steps * eps * growth.
    for got, want in zip(hist, expected):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-11 * np.abs(want).max())
    np.testing.assert_array_equal(x, hist[0][-1])
    np.testing.assert_array_equal(v, hist[1][-1])
    np.testing.assert_array_equal(a, hist[2][-1])


@pytest.mark.parametrize("solver", SOLVERS)
def test_kernel_reports_the_singular_sample(solver):
    n_steps = 6
    M = np.tile(np.eye(2), (n_steps + 1, 1, 1))
    C = np.zeros_like(M)
    K = np.zeros_like(M)
    M[4] = 0.0  # effective matrix M + 0 + 0 singular at sample 4
    x, v, a = np.eye(2), np.zeros((2, 2)), np.empty((2, 2))
    empty = np.empty((0, 2, 2))
    status = march(M, C, K, np.zeros((n_steps + 1, 2)), 0.1, 0.25, 0.5, np.zeros(2), x, v, a, empty, empty, empty,
                   solver)
    assert status == 4


def test_mass_pivot_ratios_against_singular_values():
    rng = np.random.default_rng(3)
    M = rng.normal(size=(5, 3, 3))
    M[2, :, 2] = M[2, :, 0] + M[2, :, 1]  # singular
    ratios = mass_pivot_ratios(M)
    smallest_sv = np.linalg.svd(M, compute_uv=False)[:, -1]
    assert ratios[2] < 1e-14
    assert np.all(ratios[[0, 1, 3, 4]] > 1e-3) and np.all(smallest_sv[[0, 1, 3, 4]] > 1e-3)


def test_demo_writes_result_and_figure(tmp_path):
    prefix = tmp_path / "new" / "demo"
    paths = write_demo(prefix, n_steps=64)
    assert paths == [prefix.with_suffix(".h5"), prefix.with_suffix(".png")]
    assert sorted(p.name for p in prefix.parent.iterdir()) == ["demo.h5", "demo.png"]  # no temporaries left
    with h5py.File(prefix.with_suffix(".h5")) as h5:
        assert h5["t"].shape == (65,) and h5["x"].shape == (65, 2) and h5["v"].shape == (65, 2)
        assert h5["multipliers"].shape == (4,)
        assert 0.0 < h5.attrs["error_estimate"] < 1e-3 and h5.attrs["run_time_s"] > 0.0
        assert '"n_steps": 64' in h5.attrs["settings"] and h5.attrs["package_version"]
    with pytest.raises(ValueError, match="n_steps: expected an even integer >= 4"):
        write_demo(prefix, n_steps=63)


def test_demo_command_prints_and_writes_nothing(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert demo_command.main(["--n-steps", "64"]) == 0
    assert "error estimate" in capsys.readouterr().out
    assert list(tmp_path.iterdir()) == []


def test_periodic_imports_neither_h5py_nor_matplotlib():
    """``periodic`` is usable without the file and figure libraries, its demo command included."""
    code = (
        "import sys; from periodic.__main__ import main; main(['--n-steps', '8']); "
        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('h5py', 'matplotlib')))"
    )
    root = str(Path(periodic.__file__).parents[1])  # this checkout's periodic, not an installed one
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, (root, os.environ.get("PYTHONPATH"))))}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env).stdout
    assert out.splitlines()[-1] == "[]"


@pytest.mark.slow
def test_demo_steady_state_equals_long_damped_transient():
    """Cross-algorithm: the shooting solution of the demo system against a 60-period DOP853 transient
    from rest.  The slowest transient decays by |mu|max = 0.818 per period, so after 60 periods it is
    ~0.818^60 * 0.03 m = 2e-7 m, about 1 % of the N = 256 Newmark error (~2e-5 m)."""
    import scipy.integrate

    def rhs(t, y):
        acceleration = np.linalg.solve(demo.MASS, demo.force(t) - demo.DAMPING @ y[2:] - demo.stiffness(t) @ y[:2])
        return np.concatenate((y[2:], acceleration))

    system = periodic.demo_system(256)
    n_periods = 60
    transient = scipy.integrate.solve_ivp(
        rhs, (0.0, n_periods * system.period), np.zeros(4), method="DOP853", rtol=1e-10, atol=1e-13,
        t_eval=(n_periods - 1) * system.period + system.t,
    )
    result = periodic.steady_state(system)
    assert np.abs(result.multipliers).max() < 0.82
    true_error = np.abs(result.x - transient.y[:2].T).max()
    assert result.error_estimate / true_error == pytest.approx(1.0, abs=0.2)
