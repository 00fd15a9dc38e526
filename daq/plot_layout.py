"""Subplot margins from the text the axes carry, measured without laying out their ticks.

matplotlib's layout engines (``tight_layout``, ``layout="constrained"``) find a figure's margins
by laying out every tick of every axes - minor ticks and their labels included - before it is
drawn: nearly as much work as the drawing (the survey's eleven report figures took 9.8 s to
save with them, 5.8 s with this module; the baseline's four 4.6 -> 3.1 s, the hysteresis
sweep's 3.9 -> 2.9 s, the excitation's 3.9 -> 2.8 s; issue 39). What sits outside an axes is
known before any tick exists: its title, its axis labels, the axis offset texts and the tick
labels, whose strings the axis's locator and formatter give from the view limits.
``place_axes`` measures those strings (with a kept renderer, so matplotlib's caches of text
metrics and parsed mathtext serve every figure) and sets the grid's margins and gaps in inches,
as ``tight_layout`` would:

    left   = edge pad + y label + label pad + widest y tick label + tick + tick pad
    bottom = edge pad + x label + label pad + tallest x tick label + tick + tick pad
    top    = edge pad + suptitle + title (+ the y axis's offset text, "1e-5", if it has one)
    right  = edge pad + half the widest x tick label (the last is centred on the axes' edge)

and the gaps between neighbouring axes likewise (the lower one's title above the upper one's
x labels). Minor tick labels are measured too where they are not blank (a log axis shorter
than a decade labels them). It lays out one grid of axes from ``Figure.subplots``; a figure it
cannot (no grid, or no room for the margins) is left to ``tight_layout``.
"""

from __future__ import annotations

import functools
from collections.abc import Iterable

from matplotlib import rcParams
from matplotlib.axes import Axes
from matplotlib.axis import Axis, XAxis
from matplotlib.backends.backend_agg import RendererAgg
from matplotlib.figure import Figure
from matplotlib.font_manager import FontProperties
from matplotlib.text import Text

__all__ = ["place_axes"]

PT = 1.0 / 72.0  # inch
#: the space kept between the outermost text and the figure's edge, and between neighbours
EDGE_PAD_IN = 6 * PT


@functools.lru_cache(maxsize=8)
def _renderer(dpi: float) -> RendererAgg:
    """A canvas-less renderer to measure text with, one per resolution and kept: matplotlib
    caches text metrics and parsed mathtext per renderer, and a figure's own is new with it
    (measured with it, the layout took 165 ms a figure, most of it parsing "10^-1" again)."""
    return RendererAgg(1, 1, dpi)


def _extent_in(fig: Figure, texts: Iterable[Text]) -> tuple[float, float]:
    """The widest and the tallest of ``texts`` (blank ones skipped), in inches."""
    renderer = _renderer(fig.dpi)
    w = h = 0.0
    for t in texts:
        if not t.get_visible() or not t.get_text():
            continue
        bb = t.get_window_extent(renderer)
        w, h = max(w, bb.width), max(h, bb.height)
    return w / fig.dpi, h / fig.dpi


def _rc(axis: Axis) -> tuple[float | str, float, float]:
    """The rc tick-label size, tick length and tick pad (points) of ``axis``'s kind."""
    if isinstance(axis, XAxis):
        r = rcParams["xtick.labelsize"], rcParams["xtick.major.size"], rcParams["xtick.major.pad"]
    else:
        r = rcParams["ytick.labelsize"], rcParams["ytick.major.size"], rcParams["ytick.major.pad"]
    return r[0], float(r[1]), float(r[2])


def _tick_texts(fig: Figure, axis: Axis) -> list[Text]:
    """The axis's tick labels as the draw will make them, as free ``Text``s: the locator's
    places inside the view, the formatter's strings, the tick-label font; no tick artist made."""
    shown = "labelbottom" if isinstance(axis, XAxis) else "labelleft"
    lo, hi = sorted(axis.get_view_interval())
    out: list[Text] = []
    for p, locator, formatter in (
        (axis.get_tick_params(which="major"), axis.get_major_locator(), axis.get_major_formatter()),
        (axis.get_tick_params(which="minor"), axis.get_minor_locator(), axis.get_minor_formatter()),
    ):
        if not p.get(shown, True):
            continue
        locs = [v for v in locator() if lo <= v <= hi]
        font = FontProperties(size=p.get("labelsize", _rc(axis)[0]))
        out += [
            Text(0, 0, s, fontproperties=font, figure=fig)
            for s in (formatter.format_ticks(locs) if locs else [])
            if s
        ]
    return out


def _tick_space_in(axis: Axis) -> float:
    """Tick length and the pad between tick and label, in inches (the major ticks')."""
    p = axis.get_tick_params(which="major")
    _, size, pad = _rc(axis)
    return (float(p.get("length", size)) + float(p.get("pad", pad))) * PT


def _needs_in(fig: Figure, ax: Axes) -> dict[str, float]:
    """The inches ``ax``'s text takes outside it on each side."""
    xt_w, xt_h = _extent_in(fig, _tick_texts(fig, ax.xaxis))
    yt_w, _ = _extent_in(fig, _tick_texts(fig, ax.yaxis))
    _, xl_h = _extent_in(fig, [ax.xaxis.label])
    yl_w, _ = _extent_in(fig, [ax.yaxis.label])
    _, title_h = _extent_in(fig, [ax.title])  # the figures here title the centre only
    x_off = ax.xaxis.get_major_formatter().get_offset()
    y_off = ax.yaxis.get_major_formatter().get_offset()
    font = FontProperties(size=_rc(ax.yaxis)[0])
    _, off_h = _extent_in(fig, [Text(0, 0, y_off, fontproperties=font, figure=fig)])
    bottom = _tick_space_in(ax.xaxis) + xt_h + (ax.xaxis.labelpad * PT + xl_h if xl_h else 0.0)
    if x_off:  # below the right end of the tick labels
        bottom = max(bottom, _tick_space_in(ax.xaxis) + 2 * xt_h)
    left = _tick_space_in(ax.yaxis) + yt_w + (ax.yaxis.labelpad * PT + yl_w if yl_w else 0.0)
    top = (rcParams["axes.titlepad"] * PT + title_h if title_h else 0.0) + (off_h + 2 * PT)
    right = 0.5 * xt_w
    return {"left": left, "right": right, "bottom": bottom, "top": top}


def place_axes(fig: Figure) -> bool:
    """Set the margins and gaps of ``fig``'s grid of axes from their text (module docstring).
    Returns False, changing nothing, where the figure is not one grid of axes or has no room for
    the margins (the caller lays it out some other way)."""
    axes = [ax for ax in fig.axes if ax.get_visible()]
    specs = [ax.get_subplotspec() for ax in axes]
    if not axes or any(s is None for s in specs):
        return False
    grid = specs[0].get_gridspec()  # type: ignore[union-attr]
    if any(s.get_gridspec() is not grid for s in specs):  # type: ignore[union-attr]
        return False
    nrows, ncols = grid.get_geometry()
    needs = [_needs_in(fig, ax) for ax in axes]
    left = [0.0] * ncols
    right = [0.0] * ncols
    top = [0.0] * nrows
    bottom = [0.0] * nrows
    for s, n in zip(specs, needs):
        rows, cols = s.rowspan, s.colspan  # type: ignore[union-attr]
        left[cols.start] = max(left[cols.start], n["left"])
        right[cols.stop - 1] = max(right[cols.stop - 1], n["right"])
        top[rows.start] = max(top[rows.start], n["top"])
        bottom[rows.stop - 1] = max(bottom[rows.stop - 1], n["bottom"])
    sup = getattr(fig, "_suptitle", None)  # matplotlib gives its string, not its Text
    _, sup_h = _extent_in(fig, [sup] if isinstance(sup, Text) else [])
    width, height = fig.get_size_inches()
    m_left = EDGE_PAD_IN + left[0]
    m_right = EDGE_PAD_IN + right[-1]
    m_top = EDGE_PAD_IN + top[0] + (sup_h + EDGE_PAD_IN if sup_h else 0.0)
    m_bottom = EDGE_PAD_IN + bottom[-1]
    gap_w = max((right[c] + left[c + 1] + EDGE_PAD_IN for c in range(ncols - 1)), default=0.0)
    gap_h = max((bottom[r] + top[r + 1] + EDGE_PAD_IN for r in range(nrows - 1)), default=0.0)
    ax_w = (width - m_left - m_right - (ncols - 1) * gap_w) / ncols
    ax_h = (height - m_top - m_bottom - (nrows - 1) * gap_h) / nrows
    if ax_w < 0.25 * width / ncols or ax_h < 0.25 * height / nrows:
        return False
    fig.subplots_adjust(
        left=m_left / width,
        right=1.0 - m_right / width,
        bottom=m_bottom / height,
        top=1.0 - m_top / height,
        wspace=gap_w / ax_w if ncols > 1 else None,
        hspace=gap_h / ax_h if nrows > 1 else None,
    )
    return True
