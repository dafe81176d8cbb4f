"""``flexvib animate``: the deformed mechanism of a steady state over one period, as a GIF (Pillow)
or an MP4 (ffmpeg), its elastic deflection magnified by a stated factor."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from .._drawing import draw_mechanism, frame_points
from .._errors import StudiesError
from .._plots import _pyplot, headline, plain, scene_and_point

#: An animation shows at most this many frames (every k-th sample of the period beyond it), so a
#: GIF stays a few MB; 10 frames per second: a period lasts a few seconds on screen.
MAX_FRAMES = 72
FRAMES_PER_SECOND = 10
SUFFIXES = (".gif", ".mp4")


def frame_samples(n_steps: int, max_frames: int = MAX_FRAMES) -> np.ndarray:
    """The samples (0 .. n_steps - 1) an animation of one period shows: every ``stride``-th, with
    ``stride = ceil(n_steps / max_frames)`` (the last sample is the first one again)."""
    stride = max(math.ceil(n_steps / max_frames), 1)
    return np.arange(0, n_steps, stride)


def drawable(results: Mapping[str, Any], study: str | None = None) -> tuple[str, Any]:
    """``(name, result)`` of the study to animate: ``study`` (its name in the file), or the first
    study that holds a mechanism drawing (a steady state of a mechanism scene)."""
    if study is not None:
        if study not in results:
            raise StudiesError(f"--study: no study {study!r} in the file (studies: {', '.join(results)})")
        if not getattr(results[study], "outlines", None):
            raise StudiesError(f"--study: study {study!r} holds no mechanism drawing (expected a "
                               f"steady_state of a mechanism scene, got {type(results[study]).__name__})")
        return study, results[study]
    for name, result in results.items():
        if getattr(result, "outlines", None):
            return name, result
    raise StudiesError(f"no study in the file holds a mechanism drawing (expected a steady_state of a "
                       f"mechanism scene; studies: {', '.join(results) or 'none'})")


def _writer(path: Path):
    from matplotlib import animation

    if path.suffix == ".gif":
        return animation.PillowWriter(fps=FRAMES_PER_SECOND)
    if path.suffix == ".mp4":
        if not animation.writers.is_available("ffmpeg"):
            raise StudiesError(f"--out {str(path)!r}: an .mp4 needs ffmpeg, which is not installed here; "
                               f"write a .gif instead (Pillow) or install ffmpeg")
        return animation.FFMpegWriter(fps=FRAMES_PER_SECOND)
    raise StudiesError(f"--out: expected a file name ending in {' or '.join(SUFFIXES)}, got {str(path)!r}")


def _limits(result: Any, samples: np.ndarray, magnification: float) -> tuple[tuple[float, float], ...]:
    """Axis limits holding every point of every frame, with a 5 % margin."""
    points = []
    for k in samples:
        outlines, plates, joints = frame_points(result, int(k), magnification)
        points += list(outlines.values()) + list(plates.values()) + [np.atleast_2d(p) for p in joints.values()]
    cloud = np.concatenate(points)
    low, high = cloud.min(axis=0), cloud.max(axis=0)
    margin = 0.05 * max(float((high - low).max()), 1e-12)
    return (low[0] - margin, high[0] + margin), (low[1] - margin, high[1] + margin)


def animate(result: Any, path: str | Path, *, magnification: float | None = None,
            max_frames: int = MAX_FRAMES) -> tuple[Path, int]:
    """Write the mechanism of a steady state (``SteadyStateResult`` with ``outlines``) over one period
    to ``path`` (.gif with Pillow, .mp4 with ffmpeg), the elastic deflection magnified
    ``magnification`` times (default: the result's, which makes the largest deflection a tenth of
    the longest link) and said in the title. Returns ``(path, number of frames)``."""
    path = Path(path)
    writer = _writer(path)
    if magnification is not None:
        if not (isinstance(magnification, (int, float)) and math.isfinite(magnification) and magnification >= 0):
            raise StudiesError(f"--magnification: expected a number >= 0, got {magnification!r}")
        if magnification != result.magnification and not result.rigid_outlines:
            raise StudiesError("--magnification: this result file was written before steady states kept "
                               "the undeformed outlines; rerun 'flexvib run' to choose the magnification")
    shown = result.magnification if magnification is None else float(magnification)
    plt = _pyplot()
    from matplotlib import animation

    samples = frame_samples(next(iter(result.outlines.values())).shape[0] - 1, max_frames)
    figure, ax = plt.subplots(figsize=(6.4, 4.8), layout="constrained")
    artists = draw_mechanism(ax, result, int(samples[0]), magnification=shown)
    (xmin, xmax), (ymin, ymax) = _limits(result, samples, shown)
    ax.set_xlim(xmin, xmax)
    ax.set_ylim(ymin, ymax)
    ax.set_aspect("equal", adjustable="box")  # the limits above hold every frame: keep them
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.legend(fontsize="x-small", loc="upper left", bbox_to_anchor=(1.01, 1.0))
    abscissa, what = result.abscissa()
    title = ax.set_title("", fontsize="small")
    period = float(result.t[-1] - result.t[0])

    def update(k: int) -> list:
        outlines, plates, joints = frame_points(result, int(k), shown)
        for name, points in outlines.items():
            if name in plates:
                artists[name][0].set_xy(plates[name])
            else:
                artists[name][0].set_data(points[:, 0], points[:, 1])
        for name, position in joints.items():
            artists[f"joint {name}"][0].set_data([position[0]], [position[1]])
        where = f"{what.split(' (')[0]} {abscissa[k]:.0f} deg" if what.endswith("(deg)") \
            else f"t = {abscissa[k]:.3g} s of {period:.3g} s"
        title.set_text(f"{scene_and_point(result)}: deflection magnified x {plain(shown)}, {headline(result.status)}\n"
                       f"{where}")
        return []

    movie = animation.FuncAnimation(figure, update, frames=[int(k) for k in samples], blit=False,
                                    repeat=False)
    try:
        movie.save(str(path), writer=writer, dpi=100)
    finally:
        plt.close(figure)
    return path, int(samples.size)
