"""What the figures of every study share (matplotlib is imported here only; Agg when no display is
set): the :class:`Plot` every ``plot()`` returns, axes, labels, the error-and-run-time line.

Every result's ``plot(*, axes=None) -> Plot`` draws into the given axes (a sequence of the number of
axes the figure has, or one Axes for a one-panel figure) or into a new figure, and returns the
figure, its axes and the artists by name, so users can restyle them (python-control's
``ControlPlot``). The figures themselves live with their study kind (``studies._kinds``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np


@dataclass(frozen=True, eq=False)
class Plot:
    """A drawn figure: ``figure`` (matplotlib Figure, for ``savefig``), ``axes`` (list of Axes, top to
    bottom) and ``artists`` {name: [Artist, ...]} (e.g. ``"spectral_radius"``, an observable's spec),
    to restyle."""

    figure: Any
    axes: list
    artists: dict[str, list]


def _pyplot():
    import matplotlib

    if matplotlib.get_backend().lower() not in ("agg", "svg", "pdf", "module://matplotlib_inline.backend_inline"):
        import os

        if not os.environ.get("DISPLAY"):
            matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def axes_for(n: int, axes: Any, *, width: float = 6.4, height: float = 2.6) -> list:
    """The ``n`` axes to draw into: ``axes`` as given (one Axes or a sequence of ``n``), or a new
    figure of ``n`` axes stacked (each ``width`` x ``height`` inches)."""
    if axes is not None:
        axes = list(np.atleast_1d(axes))
        if len(axes) != n:
            from ._errors import StudiesError

            raise StudiesError(f"axes: expected {n} matplotlib Axes for this figure, got {len(axes)}")
        return axes
    plt = _pyplot()
    figure, created = plt.subplots(n, 1, figsize=(width, height * n), squeeze=False, layout="constrained")
    return list(created[:, 0])


def label(name: str, unit: str) -> str:
    return f"{name} ({unit})" if unit and unit != "1" else name


def largest(values: Any) -> float:
    """Largest finite entry of an array, a mapping of arrays, or None (NaN if there is none)."""
    if values is None:
        return float("nan")
    arrays = values.values() if isinstance(values, Mapping) else [values]
    finite = [np.abs(np.asarray(a, dtype=float))[np.isfinite(np.asarray(a, dtype=float))]
              for a in arrays]
    finite = [a for a in finite if a.size]
    return float(max(a.max() for a in finite)) if finite else float("nan")


_SUPERSCRIPT = str.maketrans("-0123456789", "\u207b\u2070\u00b9\u00b2\u00b3\u2074\u2075\u2076\u2077\u2078\u2079")


def plain(value: float, digits: int = 2) -> str:
    """A number as a person writes it: ``digits`` significant digits, no "3e+02": "300", "0.0012",
    "1.2×10⁻⁵" (a power of ten only below 1e-3 or from 1e6 on); "nan" for a missing number."""
    value = float(value)
    if not math.isfinite(value):
        return str(value)
    if value == 0.0:
        return "0"
    exponent = math.floor(math.log10(abs(float(f"{value:.{digits - 1}e}"))))
    if -3 <= exponent < 6:
        decimals = digits - 1 - exponent
        return f"{round(value, decimals):.{max(decimals, 0)}f}"  # 302 to 2 digits: "300"
    mantissa = f"{value / 10.0**exponent:.{digits - 1}f}"
    return f"{mantissa}×10{str(exponent).translate(_SUPERSCRIPT)}"


def cost_line(error: str, run_time: float) -> str:
    """The line every figure carries: what its error estimate says and the run time that bought it."""
    return f"{error}; run time {plain(run_time)} s"


def plot_multipliers(multipliers: np.ndarray, *, ax: Any, title: str = "") -> list:
    """Multipliers in the complex plane with the unit circle, into ``ax``; returns [circle, points]."""
    angle = np.linspace(0.0, 2.0 * np.pi, 361)
    circle = ax.plot(np.cos(angle), np.sin(angle), color="0.6", lw=0.8, label="|mu| = 1")[0]
    values = np.asarray(multipliers).reshape(-1)
    points = ax.plot(values.real, values.imag, "x", color="C3", label="multipliers")[0]
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("Re mu")
    ax.set_ylabel("Im mu")
    if title:
        ax.set_title(title, fontsize="small")
    return [circle, points]


#: A log axis spans at least this many decades (a narrower one is widened about its middle): below
#: about a decade matplotlib labels its minor ticks, whose labels then overlap.
MIN_LOG_DECADES = 1.2


def tidy_log_axes(ax: Any) -> None:
    """Readable log axes of ``ax``: at least ``MIN_LOG_DECADES`` decades, major ticks at 1, 2 and 5
    times a power of ten (powers of ten alone past 3 decades), labelled; minor ticks unlabelled. Call
    after the data are drawn (the limits come from them)."""
    from matplotlib import ticker

    for axis, get_limits, set_limits in ((ax.xaxis, ax.get_xlim, ax.set_xlim),
                                         (ax.yaxis, ax.get_ylim, ax.set_ylim)):
        if axis.get_scale() != "log":
            continue
        low, high = sorted(get_limits())
        if not (np.isfinite(low) and np.isfinite(high) and low > 0):
            continue
        span = np.log10(high / low)
        if span < MIN_LOG_DECADES:
            pad = 10.0 ** ((MIN_LOG_DECADES - span) / 2)
            low, high = low / pad, high * pad
            set_limits(low, high)
            span = MIN_LOG_DECADES
        axis.set_major_locator(ticker.LogLocator(subs=(1.0, 2.0, 5.0) if span < 3 else (1.0,), numticks=12))
        axis.set_major_formatter(ticker.LogFormatterSciNotation(labelOnlyBase=False))
        axis.set_minor_formatter(ticker.NullFormatter())


def drawn(axes: list, artists: Mapping[str, list]) -> Plot:
    """The :class:`Plot` of artists drawn into ``axes``."""
    return Plot(figure=axes[0].figure, axes=list(axes), artists=dict(artists))


_KIND_WORDS = {"fold": "fold", "period_doubling": "period doubling", "secondary_hopf": "secondary Hopf"}

#: How figures mark a point whose status is not ``ok``: one marker and colour per status (legend).
STATUS_STYLE = {
    "failed": {"marker": "X", "color": "k"},
    "unstable": {"marker": "x", "color": "C3"},
    "outside_linear_range": {"marker": "s", "color": "C4", "mfc": "none"},
    "inaccurate": {"marker": "d", "color": "C1", "mfc": "none"},
    "near_resonance": {"marker": "^", "color": "C6", "mfc": "none"},
    "marginal": {"marker": "o", "color": "C8", "mfc": "none"},
    "unresolved_stiff_mode": {"marker": "v", "color": "0.5", "mfc": "none"},
}


def headline(status: str, kind: str = "") -> str:
    """A status in words for a title: "UNSTABLE (period doubling)", "marginal", "outside linear range"."""
    if status == "unstable":
        return f"UNSTABLE ({_KIND_WORDS.get(kind, kind)})" if kind else "UNSTABLE"
    return str(status).replace("_", " ")


def mark_statuses(ax: Any, x: np.ndarray, y: np.ndarray, status: np.ndarray) -> list:
    """Mark the points whose ``status`` is not ``ok`` (one style per status, labelled "unstable",
    "marginal", ... for the legend) at ``(x, y)`` (same shapes); returns the artists."""
    x, y, status = (np.asarray(a).reshape(-1) for a in (x, y, status))
    artists = []
    for name, style in STATUS_STYLE.items():
        chosen = status == name
        if chosen.any():
            artists += ax.plot(x[chosen], y[chosen], ls="none", ms=7, label=headline(name), **style)
    return artists


#: Rows of labels above an axes (``label_positions``) and the height of one row, points.
LABEL_ROWS = 3
LABEL_ROW_HEIGHT = 9.0


def label_positions(ax: Any, positions: Any, texts: list[str], *, rows: int = LABEL_ROWS,
                    fontsize: str = "x-small") -> tuple[list, int]:
    """Label vertical lines at data ``positions`` (x) above ``ax`` without overlap: labels are taken
    in the given order (most important first) and each goes into the lowest of ``rows`` rows where it
    clears the labels already there; a label that fits nowhere is left out. Returns the labels drawn
    and the number of rows used (to raise the title above them)."""
    figure = ax.figure
    renderer = figure.canvas.get_renderer()
    # constrained layout may still narrow the axes: reserve a quarter more room than measured now
    axes_width = max(ax.get_window_extent(renderer).width, 1.0) * 0.75
    low, high = ax.get_xlim()
    transform = ax.get_xscale() == "log" and np.log10 or (lambda v: v)
    placed: list[list[tuple[float, float]]] = [[] for _ in range(rows)]
    artists = []
    for x, text in zip(positions, texts):
        if not low <= x <= high:
            continue
        probe = ax.text(0, 0, text, fontsize=fontsize)
        half = 0.5 * probe.get_window_extent(renderer).width / axes_width + 0.01
        probe.remove()
        centre = (transform(x) - transform(low)) / (transform(high) - transform(low))
        for row, taken in enumerate(placed):
            if all(abs(centre - other) > half + other_half for other, other_half in taken):
                taken.append((centre, half))
                artists.append(ax.annotate(text, (x, 1.0), xycoords=("data", "axes fraction"),
                                           xytext=(0, 1.0 + row * LABEL_ROW_HEIGHT), textcoords="offset points",
                                           fontsize=fontsize, ha="center", va="bottom"))
                break
    return artists, sum(1 for taken in placed if taken)


def radius_norm(radius: Any):
    """A colour scale for spectral radii that shows |mu| near 1 whatever the largest value: log10 of
    the radius, the stable side (below 1) and the unstable side (above 1) each spread over half the
    colour map, 1 at its centre (a diverging map then shows 1 as its neutral colour). Returns a
    matplotlib ``FuncNorm``."""
    from matplotlib.colors import FuncNorm

    values = np.asarray(radius, dtype=float)
    values = values[np.isfinite(values) & (values > 0)]
    low = min(float(values.min()) if values.size else 0.5, 0.999)
    high = max(float(values.max()) if values.size else 2.0, 1.001)
    below, above = -math.log10(low), math.log10(high)

    def forward(r):
        logs = np.log10(np.clip(np.asarray(r, dtype=float), low, high))
        return np.where(logs < 0, logs / below, logs / above)

    def inverse(f):
        f = np.asarray(f, dtype=float)
        return 10.0 ** np.where(f < 0, f * below, f * above)

    return FuncNorm((forward, inverse), vmin=low, vmax=high)


def quantity(value: float, unit: str, digits: int = 2) -> str:
    """A number with its unit as a title shows it: "4.8×10⁻⁵ m", "0.69" (unit "1" or "" shows none)."""
    shown = plain(value, digits)
    return f"{shown} {unit}" if unit and unit != "1" and math.isfinite(float(value)) else shown


#: A point named in a title at most this long: beyond it the speed alone (a problem that reports all
#: its parameters, such as the Mathieu equation's, says how many it leaves out).
POINT_WORDS_WIDTH = 50


def point_words(parameters: Mapping[str, float] | None, *, digits: int = 4) -> str:
    """A study's point in words: "speed 100 rad/s, links.coupler.thickness 0.002 m" (the units of the
    scene values by their key, as ``MechanismProblem.units`` gives them); "" without parameters."""
    from ._mechanism import _UNITS

    parameters = dict(parameters or {})
    if "speed" in parameters:   # the speed first: what a title of a mechanism's point names
        parameters = {"speed": parameters.pop("speed"), **parameters}
    words = []
    for name, value in parameters.items():
        unit = "rad/s" if name == "speed" else _UNITS.get(str(name).rsplit(".", 1)[-1], "")
        shown = f"{float(value):.{digits}g}"   # 100, not 99.99999999999999 nor 100.0
        shown = plain(float(value), digits) if "e" in shown else shown
        words.append(f"{name} {shown} {unit}".rstrip() if unit != "1" else f"{name} {shown}")
    text = ", ".join(words)
    if len(text) > POINT_WORDS_WIDTH and len(words) > 1:
        text = f"{words[0]} (and {len(words) - 1} more parameters)"
    return text


def scene_and_point(result: Any) -> str:
    """"four_bar_ritz at speed 100 rad/s": the problem a one-point result is of, and its point."""
    where = point_words(getattr(result, "parameters", None))
    return f"{result.problem} at {where}" if where else str(result.problem)


#: Where a legend goes: outside the axes, on their right, so that it never covers data (the figure's
#: constrained layout makes room for it).
LEGEND_OUTSIDE = {"loc": "upper left", "bbox_to_anchor": (1.01, 1.0), "borderaxespad": 0.0}


def legend_outside(ax: Any, **options: Any) -> Any:
    """``ax.legend(...)`` to the right of the axes, never over the data (``LEGEND_OUTSIDE``)."""
    return ax.legend(**{"fontsize": "x-small", **LEGEND_OUTSIDE, **options})
