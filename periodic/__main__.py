"""``python -m periodic --out PREFIX``: periodic steady state and Floquet stability of a demo system.

The demo is a damped two-degree-of-freedom Mathieu-type system with harmonic forcing,

    M x'' + C x' + (K0 + K1 cos(Omega t)) x = F cos(Omega t),   T = 2 pi / Omega,

whose stiffness pulsates at the forcing frequency (as a link's stiffness does over a crank turn).
Writes ``PREFIX.h5`` and ``PREFIX.png`` (each via a temporary file renamed on success) and prints a
summary.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from importlib import metadata
from pathlib import Path

import numpy as np

from ._shooting import SteadyState, steady_state
from ._system import PeriodicSystem

OMEGA = 2.0 * np.pi  # rad/s, forcing and pulsation frequency: T = 1 s
MASS = np.array([[2.0, 0.5], [0.5, 1.0]])  # kg
STIFFNESS_MEAN = np.array([[900.0, -300.0], [-300.0, 500.0]])  # N/m
STIFFNESS_PULSE = np.array([[180.0, 0.0], [0.0, -100.0]])  # N/m, amplitude of the cos(Omega t) part
DAMPING = 1e-3 * STIFFNESS_MEAN + 0.2 * MASS  # N s/m, Rayleigh damping
FORCE = np.array([10.0, 0.0])  # N, amplitude of the cos(Omega t) force


def demo_system(n_steps: int) -> PeriodicSystem:
    """The demo system sampled on ``n_steps`` steps per period (T = 1 s)."""
    return PeriodicSystem.from_functions(
        2.0 * np.pi / OMEGA,
        lambda t: MASS,
        lambda t: DAMPING,
        lambda t: STIFFNESS_MEAN + STIFFNESS_PULSE * np.cos(OMEGA * t),
        lambda t: FORCE * np.cos(OMEGA * t),
        n_steps=n_steps,
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m periodic", description=__doc__.splitlines()[0])
    parser.add_argument("--out", required=True, help="output prefix; writes PREFIX.h5 and PREFIX.png")
    parser.add_argument("--n-steps", type=int, default=512, help="Newmark steps per period (even, default 512)")
    parser.add_argument("--extrapolate", action="store_true", help="Richardson-extrapolate N and N/2 (order 4)")
    args = parser.parse_args(argv)
    if args.n_steps < 4 or args.n_steps % 2:
        parser.error(f"--n-steps: expected an even integer >= 4, got {args.n_steps}")
    prefix = Path(args.out)
    prefix.parent.mkdir(parents=True, exist_ok=True)

    start = time.perf_counter()
    system = demo_system(args.n_steps)
    result = steady_state(system, extrapolate=args.extrapolate)
    settings = {
        "n_steps": args.n_steps,
        "extrapolate": args.extrapolate,
        "beta": 0.25,
        "gamma": 0.5,
        "period_s": system.period,
        "system": "damped 2-DOF Mathieu-type demo (periodic.__main__)",
    }
    h5_path = prefix.with_name(prefix.name + ".h5")
    png_path = prefix.with_name(prefix.name + ".png")
    _write_hdf5(h5_path, result, settings)
    _plot(png_path, result)
    elapsed = time.perf_counter() - start

    print(f"periodic demo: 2-DOF Mathieu-type system, T = {system.period:g} s, N = {args.n_steps} steps")
    print(f"  max |x| = {np.abs(result.x).max(axis=0)} m, error estimate {result.error_estimate:.2e} m")
    print(f"  Floquet multipliers |mu| = {np.abs(result.multipliers).round(6)}, stable: {result.is_stable}")
    print(f"  status: {result.status}; solve {result.run_time * 1e3:.1f} ms, total {elapsed:.2f} s")
    print(f"  wrote {h5_path} and {png_path}")
    return 0


def _write_hdf5(path: Path, result: SteadyState, settings: dict) -> None:
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
            h5.attrs["package_version"] = _version()
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def _plot(path: Path, result: SteadyState) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_x, ax_mu) = plt.subplots(1, 2, figsize=(10, 4))
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
        plt.close(fig)
        tmp.unlink(missing_ok=True)


def _version() -> str:
    try:
        return metadata.version("flexvib")
    except metadata.PackageNotFoundError:
        return "unknown"


if __name__ == "__main__":
    sys.exit(main())
