"""Text labels on a plot that never overlap: keep them in priority order, drop the rest.

Each candidate label's extent is measured with the figure's renderer
(``Text.get_window_extent`` after a draw, in display pixels); a label is kept when it lies
inside its axes and its box, grown by :data:`PAD_PX`, touches neither a label kept before
it nor an occupied artist (the legend); otherwise it is removed from the figure. Call it
after the layout is final (``tight_layout``) and save at the figure's own dpi, so that the
saved file has the geometry that was measured.
"""

from __future__ import annotations

from collections.abc import Sequence

from matplotlib.artist import Artist
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.text import Text
from matplotlib.transforms import Bbox

PAD_PX: float = 2.0
"""Clearance (display pixels) kept around every label."""


def _grown(box: Bbox, pad: float) -> Bbox:
    return Bbox.from_extents(box.x0 - pad, box.y0 - pad, box.x1 + pad, box.y1 + pad)


def keep_non_overlapping(fig: Figure, ax: Axes, labels: Sequence[Text],
                         occupied: Sequence[Artist] = ()) -> list[Text]:
    """Remove every label of ``labels`` (highest priority first) that would overlap a kept
    label or an ``occupied`` artist, or that leaves ``ax``; return the labels kept."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()  # type: ignore[attr-defined]
    inside = ax.get_window_extent(renderer)
    taken = [a.get_window_extent(renderer) for a in occupied if a.get_visible()]
    kept: list[Text] = []
    for label in labels:
        box = _grown(label.get_window_extent(renderer), PAD_PX)
        within = (box.x0 >= inside.x0 and box.x1 <= inside.x1 and box.y0 >= inside.y0
                  and box.y1 <= inside.y1)
        if within and not any(box.overlaps(t) for t in taken):
            taken.append(box)
            kept.append(label)
        else:
            label.remove()
    return kept


__all__ = ["PAD_PX", "keep_non_overlapping"]
