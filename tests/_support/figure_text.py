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
