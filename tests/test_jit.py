"""The numba warm-up of ``flexvib run`` (studies/_jit.py) and the compile-time economies of the
kernels: the compile clock, the warm-up covering every kernel a run calls (so that no study's run
time includes a compilation) and one signature per kernel (the continuation's in-kernel solve is
tested in tests/test_lapack.py)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numba
import pytest

from studies.cli._jit import CompileClock  # the command's warm-up machinery: no public face

ROOT = Path(__file__).resolve().parent.parent


def test_compile_clock_counts_a_compilation_once_with_its_callees():
    @numba.njit  # defined here: not in any cache, so it compiles
    def inner(x):
        return 2.0 * x

    @numba.njit
    def outer(x):
        return inner(x) + 1.0

    clock = CompileClock(announce=False).start()
    try:
        assert outer(1.0) == 3.0
        assert outer(2.0) == 5.0  # compiled already: not counted again
    finally:
        seconds = clock.stop()
    assert clock.count == 1 and seconds > 0.0
    assert inner.signatures and outer.signatures


_COVERAGE_SCRIPT = textwrap.dedent("""
    import json, sys
    import numba
    import mechanisms, studies
    # the command's warm-up, run and [studies] check, called apart: no public face
    from studies.cli._jit import warm_up
    from studies.cli._run import run_plan
    from studies.cli._scene import plan

    scene = mechanisms.load("four_bar_thesis").to_toml() + sys.argv[2]
    problem = studies.MechanismProblem.from_mechanism(mechanisms.loads(scene),
                                                      parameter_paths=["links.coupler.thickness"])
    common, declared = plan(mechanisms.loads(scene).studies)

    def signatures():
        found = {}
        for name, module in list(sys.modules.items()):
            if name.split(".")[0] in ("periodic", "mechanisms", "linearize", "studies"):
                for attr, value in vars(module).items():
                    if isinstance(value, numba.core.registry.CPUDispatcher):
                        found[f"{name}.{attr}"] = [str(s) for s in value.signatures]
        return found

    clock = warm_up(problem, declared)
    after_warm_up = signatures()
    run_plan(problem, declared, sys.argv[1])
    clock.stop()
    print(json.dumps({"warm_up": after_warm_up, "run": signatures()}))
""")

_SCENE = """
[studies]
n_steps = 32

[studies.steady_state]

[studies.sweep]
parameter = "speed"
values = [60.0, 140.0]

[studies.stability_chart]
x = { parameter = "speed", values = [80.0, 120.0] }
y = { parameter = "links.coupler.thickness", values = [1.4e-3, 1.8e-3] }
n_steps = 32

[studies.nonlinear_check]
speeds = [60.0, 100.0]
n_periods = 2

[studies.nonlinear_steady_state]
n_steps = 32
"""


@pytest.mark.slow
def test_the_warm_up_compiles_every_kernel_the_run_calls(tmp_path):
    """In a fresh process (numba's disk cache as the suite left it), the studies of a run call no
    kernel, with no argument types, that the warm-up did not already compile or load: their run
    times hold no compilation. And no kernel has two signatures (read-only against writable arrays,
    a literal against an integer)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, "-c", _COVERAGE_SCRIPT, str(tmp_path / "run.h5"), _SCENE],
                          env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    found = json.loads(done.stdout.splitlines()[-1])
    assert found["run"] == found["warm_up"]
    called = {name: sigs for name, sigs in found["run"].items() if sigs}
    assert "periodic._newmark.newmark_march" in called and "mechanisms._batch.linear_terms_kernel" in called
    assert "mechanisms._alpha_tangent._tangent_steps" in called    # the shooting's monodromy
    assert not [name for name, sigs in called.items() if len(sigs) != 1]
    assert not [name for name, sigs in called.items() if any("Literal" in s for s in sigs)]

