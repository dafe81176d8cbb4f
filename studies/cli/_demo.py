"""``flexvib demo``: the periodic steady state and Floquet multipliers of ``periodic.demo_system``, written
to ``PREFIX.h5`` and ``PREFIX.png`` (each via a temporary file renamed on success).

HDF5 layout: datasets ``t`` (N+1,) s, ``x`` (N+1, 2) m, ``v`` (N+1, 2) m/s, ``multipliers`` (4,) complex;
attributes ``error_estimate`` (m, max abs error of x), ``run_time_s``, ``status``, ``settings`` (JSON)
and ``package_version``.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

import periodic

from .._errors import StudiesError
from .._store import versions


def write_demo(prefix: str | Path, *, n_steps: int = 512, extrapolate: bool = False) -> list[Path]:
    """Solve the demo system on ``n_steps`` steps (even, >= 4) and write ``PREFIX.h5`` and ``PREFIX.png``;
    returns their paths.  ``extrapolate`` Richardson-extrapolates N and N/2 steps (order 4)."""
    if isinstance(n_steps, bool) or not isinstance(n_steps, (int, np.integer)):
        raise TypeError(f"n_steps: expected an even integer >= 4, got {type(n_steps).__name__}")
    if n_steps < 4 or n_steps % 2:
        raise StudiesError(f"n_steps: expected an even integer >= 4 (the error estimate uses N/2 steps), got {n_steps}")
    prefix = Path(prefix)
    system = periodic.demo_system(int(n_steps))
    result = periodic.steady_state(system, extrapolate=extrapolate)
    settings = {
        "n_steps": n_steps,
        "extrapolate": extrapolate,
        "beta": result.scheme.beta,
        "gamma": result.scheme.gamma,
        "period_s": system.period,
        "system": "damped 2-DOF Mathieu-type demo (periodic.demo_system)",
    }
    prefix.parent.mkdir(parents=True, exist_ok=True)
    h5_path = prefix.with_name(prefix.name + ".h5")
    png_path = prefix.with_name(prefix.name + ".png")
    _write_hdf5(h5_path, result, settings)
    _plot(png_path, result)
    return [h5_path, png_path]


def _write_hdf5(path: Path, result: periodic.SteadyState, settings: dict) -> None:
    import h5py

    tmp = path.with_name(path.name + f".tmp{os.getpid()}")
    try:
        with h5py.File(tmp, "w") as h5:
            h5.create_dataset("t", data=result.t).attrs["units"] = "s"
            h5.create_dataset("x", data=result.x).attrs["units"] = "m"
            h5.create_dataset("v", data=result.v).attrs["units"] = "m/s"
            h5.create_dataset("multipliers", data=result.multipliers)
            h5.attrs["error_estimate"] = result.error_estimate
            h5.attrs["error_estimate_units"] = "m (max abs error of x)"
            h5.attrs["run_time_s"] = result.run_time
            h5.attrs["status"] = result.status
            h5.attrs["settings"] = json.dumps(settings)
            h5.attrs["package_version"] = versions()["flexvib"]
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def _plot(path: Path, result: periodic.SteadyState) -> None:
    # A bare Figure draws with Agg and leaves pyplot's global state (backend, open figures) alone.
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 4))
    ax_x, ax_mu = fig.subplots(1, 2)
    for i in range(result.x.shape[1]):
        ax_x.plot(result.t, result.x[:, i], label=f"x{i + 1}")
    ax_x.set(xlabel="t [s]", ylabel="x [m]", title=f"periodic steady state (error est. {result.error_estimate:.1e} m)")
    ax_x.legend()
    circle = np.exp(1j * np.linspace(0.0, 2.0 * np.pi, 200))
    ax_mu.plot(circle.real, circle.imag, "k:", lw=0.8)
    ax_mu.plot(result.multipliers.real, result.multipliers.imag, "o")
    ax_mu.set(xlabel="Re mu", ylabel="Im mu", title="Floquet multipliers", aspect="equal")
    fig.tight_layout()
    tmp = path.with_name(path.name + f".tmp{os.getpid()}.png")
    try:
        fig.savefig(tmp, dpi=100)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
