"""Text of a matplotlib figure that overlaps other text or leaves the figure (a test helper)."""

from __future__ import annotations

import itertools


def text_problems(figure, *, tolerance: float = 1.0) -> list[str]:
    """Draw ``figure`` and list every visible, non-empty text artist (titles, labels, tick labels,
    annotations, legend entries, colour-bar labels) that reaches more than ``tolerance`` pixels
    outside the figure or comes closer than ``tolerance`` pixels to another one (touching labels
    such as "4:1" and "3:1" side by side read as "4:13:1"); [] when the figure is clean."""
    from matplotlib.text import Text

    figure.canvas.draw()
    renderer = figure.canvas.get_renderer()
    page = figure.bbox
    # matplotlib keeps tick objects for ticks outside the view and does not draw them: keep the
    # labels of the ticks it draws (Axis._update_ticks, what Axis.draw uses) and no other tick label
    tick_labels, drawn_labels = set(), set()
    for ax in figure.axes:
        for axis in (ax.xaxis, ax.yaxis):
            for tick in axis.majorTicks + axis.minorTicks:
                tick_labels.update({id(tick.label1), id(tick.label2)})
            for tick in axis._update_ticks():
                drawn_labels.update({id(tick.label1), id(tick.label2)})
    boxes = []
    for text in figure.findobj(Text):
        if not text.get_visible() or not text.get_text().strip():
            continue
        if id(text) in tick_labels and id(text) not in drawn_labels:
            continue
        box = text.get_window_extent(renderer)
        if box.width == 0 or box.height == 0:
            continue
        boxes.append((text.get_text(), box))
    problems = []
    for label, box in boxes:
        if box.x0 < page.x0 - tolerance or box.y0 < page.y0 - tolerance or box.x1 > page.x1 + tolerance \
                or box.y1 > page.y1 + tolerance:
            problems.append(f"{label!r} outside the figure ({box.bounds} in {page.bounds})")
    for (a, box_a), (b, box_b) in itertools.combinations(boxes, 2):
        width = min(box_a.x1, box_b.x1) - max(box_a.x0, box_b.x0)
        height = min(box_a.y1, box_b.y1) - max(box_a.y0, box_b.y0)
        if width > -tolerance and height > -tolerance:
            problems.append(f"{a!r} overlaps {b!r}")
    return problems


def legend_problems(figure, *, samples: int = 8) -> list[str]:
    """Every legend of ``figure`` (of an axes or of the figure) that covers drawn data: a point of a
    line (its vertices and ``samples`` points along each segment, so a line crossing the legend
    between two vertices counts), a marker or a scatter point of any axes, inside the axes' box and
    the legend's; [] when no legend covers data."""
    import numpy as np

    figure.canvas.draw()
    renderer = figure.canvas.get_renderer()
    legends = [ax.get_legend() for ax in figure.axes if ax.get_legend() is not None] + list(figure.legends)
    problems = []
    for legend in legends:
        box = legend.get_window_extent(renderer)
        for ax in figure.axes:
            inside_axes = ax.get_window_extent(renderer)
            clipped = [box.x0 >= inside_axes.x1, box.x1 <= inside_axes.x0, box.y0 >= inside_axes.y1,
                       box.y1 <= inside_axes.y0]
            if any(clipped):
                continue  # the legend is beside this axes, not over it
            points = []
            for line in ax.get_lines():
                xy = np.asarray(line.get_transform().transform(np.asarray(line.get_xydata(), dtype=float)))
                if len(xy) > 1 and line.get_linestyle() not in ("None", "none", " ", ""):
                    fractions = np.linspace(0.0, 1.0, samples, endpoint=False)
                    along = xy[:-1, None, :] + fractions[None, :, None] * np.diff(xy, axis=0)[:, None, :]
                    xy = np.concatenate([along.reshape(-1, 2), xy[-1:]])
                points.append((line.get_label(), xy))
            for collection in ax.collections:
                offsets = np.asarray(collection.get_offsets(), dtype=float)
                if offsets.size and collection.get_offset_transform() is not None:
                    points.append((collection.get_label(), collection.get_offset_transform().transform(offsets)))
            for name, xy in points:
                xy = xy[np.isfinite(xy).all(axis=1)]
                within = ((xy[:, 0] > box.x0) & (xy[:, 0] < box.x1) & (xy[:, 1] > box.y0) & (xy[:, 1] < box.y1)
                          & (xy[:, 0] >= inside_axes.x0) & (xy[:, 0] <= inside_axes.x1)
                          & (xy[:, 1] >= inside_axes.y0) & (xy[:, 1] <= inside_axes.y1))
                if within.any():
                    problems.append(f"legend {[t.get_text() for t in legend.get_texts()]} covers {name!r} "
                                    f"({int(within.sum())} points)")
    return problems
