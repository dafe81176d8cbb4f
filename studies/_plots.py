"""Figures of the study results (matplotlib, imported here only; Agg when no display is set).

Each function draws into given axes or a new figure and returns the artists, so users can restyle
them; ``artist.figure`` (or ``axes.figure``) reaches the figure for saving.
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np


def _pyplot():
    import matplotlib

    if matplotlib.get_backend().lower() not in ("agg", "svg", "pdf", "module://matplotlib_inline.backend_inline"):
        import os

        if not os.environ.get("DISPLAY"):
            matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _axes(n: int, axes: Any, *, width: float = 6.4, height: float = 2.6):
    if axes is not None:
        axes = list(np.atleast_1d(axes))
        if len(axes) != n:
            raise ValueError(f"axes: expected {n} axes, got {len(axes)}")
        return axes
    plt = _pyplot()
    figure, created = plt.subplots(n, 1, figsize=(width, height * n), squeeze=False, layout="constrained")
    return list(created[:, 0])


def _label(name: str, unit: str) -> str:
    return f"{name} ({unit})" if unit and unit != "1" else name


def _largest(values: Any) -> float:
    """Largest finite entry of an array, a mapping of arrays, or None (NaN if there is none)."""
    if values is None:
        return float("nan")
    arrays = values.values() if isinstance(values, Mapping) else [values]
    finite = [np.abs(np.asarray(a, dtype=float))[np.isfinite(np.asarray(a, dtype=float))]
              for a in arrays]
    finite = [a for a in finite if a.size]
    return float(max(a.max() for a in finite)) if finite else float("nan")


def _cost(error: str, run_time: float) -> str:
    """The line every figure carries: what its error estimate says and the run time that bought it."""
    return f"{error}; run time {run_time:.3g} s"


def plot_multipliers(multipliers: np.ndarray, *, ax: Any = None, title: str = "") -> list:
    """Multipliers in the complex plane with the unit circle; returns [circle, points]."""
    ax = ax if ax is not None else _axes(1, None, width=4.8, height=4.8)[0]
    angle = np.linspace(0.0, 2.0 * np.pi, 361)
    circle = ax.plot(np.cos(angle), np.sin(angle), color="0.6", lw=0.8, label="|mu| = 1")[0]
    values = np.asarray(multipliers).reshape(-1)
    points = ax.plot(values.real, values.imag, "x", color="C3", label="multipliers")[0]
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("Re mu")
    ax.set_ylabel("Im mu")
    if title:
        ax.set_title(title)
    return [circle, points]


def plot_steady_state(result: Any, *, axes: Any = None) -> dict[str, list]:
    """Each observable over one crank revolution (one axes each) and the multipliers (last axes)."""
    specs = list(result.response)
    axes = _axes(len(specs) + 1, axes)
    artists: dict[str, list] = {}
    angle = np.degrees(result.crank_angle - result.crank_angle[0])
    for ax, spec in zip(axes, specs):
        artists[spec] = ax.plot(angle, result.response[spec], color="C0")
        ax.set_xlabel("crank angle (deg)")
        ax.set_ylabel(_label(spec, result.units[spec]))
        ax.set_title(f"{spec}: error estimate {result.response_error[spec]:.2g} {result.units[spec]}",
                     fontsize="small")
    artists["multipliers"] = plot_multipliers(
        result.multipliers, ax=axes[-1],
        title=f"spectral radius {result.spectral_radius:.6f}\n" + _cost(
            f"max coordinate error {result.error_estimate:.2g} (N against N/2)", result.run_time))
    return artists


def plot_mechanism(result: Any, *, ax: Any = None, n_frames: int = 8) -> list:
    """Link outlines at ``n_frames`` crank angles over the period, later frames darker; the elastic
    deflection is magnified ``result.magnification`` times."""
    if not result.outlines:
        raise ValueError(f"{result.problem}: no link outlines to draw (not a mechanism problem)")
    ax = ax if ax is not None else _axes(1, None, height=4.8)[0]
    n_samples = next(iter(result.outlines.values())).shape[0] - 1
    frames = np.linspace(0, n_samples, n_frames, endpoint=False).astype(int)
    artists = []
    for rank, k in enumerate(frames):
        # One colour per link, so each link can be followed; later frames more opaque.
        alpha = 0.2 + 0.8 * rank / max(n_frames - 1, 1)
        for j, (name, points) in enumerate(result.outlines.items()):
            artists += ax.plot(points[k, :, 0], points[k, :, 1], color=f"C{j % 10}", alpha=alpha,
                               lw=1.5, label=name if rank == n_frames - 1 else None)
    ax.legend(fontsize="x-small", title="later frames darker", title_fontsize="x-small")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"{result.problem}: deformed mechanism over one period (deflection x "
                 f"{result.magnification:.3g})", fontsize="small")
    return artists


def plot_sweep(result: Any, *, axes: Any = None) -> dict[str, list]:
    """Peak-to-peak of each observable and the spectral radius against the swept parameter, with
    resonances (dotted lines, labelled k:mode) and parametric instabilities (shaded)."""
    specs = list(result.peak_to_peak)
    axes = _axes(len(specs) + 1, axes)
    x = result.values
    artists: dict[str, list] = {}
    xlabel = _label(result.parameter, result.parameter_unit)
    for ax, spec in zip(axes, specs):
        line = ax.semilogy(x, result.peak_to_peak[spec], ".-", color="C0", label="peak to peak")
        artists[spec] = line
        ax.set_ylabel(_label(f"{spec} peak to peak", result.units[spec]))
    if result.spectral_radius is not None:
        artists["spectral_radius"] = axes[-1].plot(x, result.spectral_radius, ".-", color="C1")
        artists["stability_limit"] = [axes[-1].axhline(1.0, color="k", lw=0.8)]
    axes[-1].set_ylabel("spectral radius |mu|max")
    relative = [np.asarray(result.peak_to_peak_error.get(spec), dtype=float)
                / np.asarray(result.peak_to_peak[spec], dtype=float)
                for spec in specs if result.peak_to_peak_error.get(spec) is not None]
    axes[0].set_title(_cost(f"{len(x)} points, largest estimated error "
                            f"{100 * _largest(relative):.2g} % of peak to peak",
                            result.run_time), fontsize="small", pad=14)  # above the k:mode labels
    for ax in axes:
        ax.set_xlabel(xlabel)
        for start, end in result.instabilities:
            artists.setdefault("instabilities", []).append(ax.axvspan(start, end, color="C3", alpha=0.2))
    for k, mode, value in result.resonances:
        for ax in axes:
            artists.setdefault("resonances", []).append(ax.axvline(value, color="0.5", ls=":", lw=0.8))
        axes[0].annotate(f"{k}:{mode + 1}", (value, 1.0), xycoords=("data", "axes fraction"),
                         fontsize="x-small", ha="center", va="bottom")
    return artists


def plot_campbell(result: Any, *, ax: Any = None) -> list:
    """Frozen-frequency bands of the tracked modes (shaded), their mean (line), Floquet characteristic
    frequencies (dots) and the lines k * speed."""
    ax = ax if ax is not None else _axes(1, None, height=4.8)[0]
    artists = []
    speeds = result.speeds
    if result.band_min is not None:
        for j, label in enumerate(result.mode_labels):
            artists.append(ax.fill_between(speeds, result.band_min[:, j], result.band_max[:, j],
                                           color=f"C{j % 10}", alpha=0.25, lw=0))
            artists += ax.plot(speeds, result.band_mean[:, j], color=f"C{j % 10}", label=label)
        artists += ax.plot(np.repeat(speeds, result.characteristic.shape[1]),
                           result.characteristic.reshape(-1), ".", color="k", ms=2,
                           label="Floquet characteristic")
        # Show the range the harmonics reach (where resonances can occur) and at least the lowest
        # mode; higher modes (e.g. axial) would squash the interesting part.
        top = 1.15 * max(max(result.harmonics) * speeds[-1], np.nanmax(result.band_max[:, 0]))
        for k in result.harmonics:
            artists += ax.plot(speeds, k * speeds, color="0.6", lw=0.7, ls="--")
            ax.annotate(f"{k}x", (speeds[-1], min(k * speeds[-1], top)), fontsize="x-small")
        ax.set_ylim(0.0, top)
        ax.legend(fontsize="x-small", loc="upper left")
    ax.set_xlabel("crank speed (rad/s)")
    ax.set_ylabel("frequency (rad/s)")
    # The error of the characteristic frequencies drawn (an unresolved axial mode far above the
    # plotted range would otherwise set it).
    error = float("nan")
    if result.characteristic_error is not None:
        shown = np.asarray(result.characteristic) <= ax.get_ylim()[1]
        error = _largest(np.where(shown, result.characteristic_error, np.nan))
    ax.set_title(f"{result.problem}: Campbell diagram\n" + _cost(
        f"characteristic frequencies shown to {error:.2g} rad/s", result.run_time),
        fontsize="small")
    return artists


def plot_chart(result: Any, *, ax: Any = None) -> list:
    """Spectral radius map (colour) with the boundary |mu| = 1 (black contour)."""
    ax = ax if ax is not None else _axes(1, None, height=4.8)[0]
    radius = np.asarray(result.spectral_radius, dtype=float)
    mesh = ax.pcolormesh(result.first, result.second, radius.T, shading="nearest", cmap="viridis",
                         vmin=np.nanmin(radius), vmax=max(np.nanmax(radius), 1.0 + 1e-3))
    artists = [mesh]
    level = 1.0 + result.stability_tol
    if np.nanmin(radius) < level < np.nanmax(radius) and min(radius.shape) > 1:
        artists.append(ax.contour(result.first, result.second, radius.T, levels=[level], colors="k",
                                  linewidths=1.0))
    ax.figure.colorbar(mesh, ax=ax, label="spectral radius |mu|max")
    ax.set_xlabel(_label(result.parameters[0], result.parameter_units[0]))
    ax.set_ylabel(_label(result.parameters[1], result.parameter_units[1]))
    ax.set_title(f"{result.problem}: stability chart (black: |mu| = 1)\n" + _cost(
        f"spectral radius to {_largest(result.spectral_radius_error):.2g}", result.run_time),
        fontsize="small")
    return artists


def plot_nonlinear(result: Any, *, axes: Any = None) -> dict[str, list]:
    """Nonlinear run from the linear state (and from rest) against the linear periodic solution."""
    specs = list(result.linear)
    axes = _axes(len(specs), axes)
    period = result.t_linear[-1]
    artists: dict[str, list] = {}
    for ax, spec in zip(axes, specs):
        repeats = int(round(result.t[-1] / period))
        t_lin = np.concatenate([result.t_linear[:-1] + p * period for p in range(repeats)] + [[result.t[-1]]])
        y_lin = np.concatenate([result.linear[spec][:-1]] * repeats + [[result.linear[spec][-1]]])
        lines = ax.plot(result.t, result.nonlinear[spec], color="C0", label="nonlinear from linear state")
        lines += ax.plot(t_lin, y_lin, "--", color="C1", label="linear periodic")
        if result.rest:
            lines += ax.plot(result.t_rest, result.rest[spec], color="0.6", lw=0.6, label="nonlinear from rest")
        ax.set_xlabel("time (s)")
        ax.set_ylabel(_label(spec, result.units[spec]))
        ax.set_title(f"{spec}: max difference {result.difference[spec]:.2g} "
                     f"({100 * result.relative_difference[spec]:.2g} % of peak to peak)\n"
                     f"estimated errors: linear {result.linear_error.get(spec, float('nan')):.2g}, "
                     f"nonlinear {result.nonlinear_error.get(spec, float('nan')):.2g}; run time "
                     f"linear {result.linear_run_time:.3g} s, nonlinear "
                     f"{result.nonlinear_run_time:.3g} s", fontsize="small")
        ax.legend(fontsize="x-small")
        artists[spec] = lines
    return artists


def plot_error_cost(result: Any, *, ax: Any = None) -> list:
    """Relative error of each observable against run time, one line per resolution."""
    ax = ax if ax is not None else _axes(1, None, height=4.8)[0]
    artists = []
    for spec in result.error:
        for i, level in enumerate(result.resolutions):
            name = f"{spec}" + (f", {result.resolution_parameter} = {level:g}" if result.resolution_parameter else "")
            artists += ax.loglog(result.run_time[i], result.error[spec][i], "o-", label=name)
            for n, x, y in zip(result.n_steps, result.run_time[i], result.error[spec][i]):
                ax.annotate(f"N={n}", (x, y), fontsize="x-small")
    ax.set_xlabel("run time (s)")
    ax.set_ylabel("relative error (1)")
    ax.legend(fontsize="x-small")
    return artists
