"""Log-axis tick labels as plain text ("10⁻³", "2×10¹"), not mathtext.

matplotlib labels a log axis ``$\\mathdefault{10^{-3}}$``: each label goes through the mathtext
parser (pyparsing), and its parses are cached per renderer, which is new with every figure, so a
report parsed every label of every figure again: 17 % of saving the survey's figures after
``daq.plot_layout`` (issue 39). The same label in Unicode superscripts is ordinary text in the
same font (DejaVu Sans has the glyphs), measured and drawn without the parser.
``plain_log_labels`` swaps matplotlib's own log formatters for ``PlainLogFormatter`` and leaves
any formatter a plot chose alone.
"""

from __future__ import annotations

import math
import re

from matplotlib.figure import Figure
from matplotlib.ticker import LogFormatterSciNotation, LogLocator

__all__ = ["PlainLogFormatter", "plain_log_labels", "sparse_log_minors", "unmath"]

#: the minor ticks of a log axis spanning more than a decade: at 2 and 5 times each power of ten
SPARSE_SUBS = (2.0, 5.0)

_SUPER = str.maketrans("0123456789-", "⁰¹²³⁴⁵⁶⁷⁸⁹⁻")
_MATH = re.compile(r"^\$\\mathdefault\{(.*)\}\$$")
_POWER = re.compile(r"^(?:(?P<m>[^\\]*)\\times)?(?P<b>\d+)\^\{(?P<e>-?\d+)\}$")


def unmath(label: str) -> str:
    """``$\\mathdefault{2\\times10^{-1}}$`` -> ``2×10⁻¹``; a label of another form as it is."""
    m = _MATH.match(label)
    if m is None:
        return label
    body = m.group(1)
    p = _POWER.match(body)
    if p is None:
        return label if "\\" in body or "^" in body or "{" in body else body
    mant = f"{p.group('m')}×" if p.group("m") else ""
    return f"{mant}{p.group('b')}{p.group('e').translate(_SUPER)}"


class PlainLogFormatter(LogFormatterSciNotation):
    """``LogFormatterSciNotation``'s labels (the same ticks labelled, the same numbers) in plain
    text: ``unmath`` of each."""

    def __call__(self, x: float, pos: int | None = None) -> str:
        return unmath(super().__call__(x, pos))


def plain_log_labels(fig: Figure) -> None:
    """Make every matplotlib log formatter (``LogFormatterSciNotation``, major or minor) on
    ``fig``'s axes a ``PlainLogFormatter``: the same object, its settings kept."""
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            for f in (axis.get_major_formatter(), axis.get_minor_formatter()):
                if type(f) is LogFormatterSciNotation:
                    f.__class__ = PlainLogFormatter  # the same formatter, its settings kept


def sparse_log_minors(fig: Figure) -> None:
    """Minor ticks (and their grid lines) at 2 and 5 times each power of ten on every log axis
    of ``fig`` that spans more than a decade and has matplotlib's own minor locator (subs
    "auto": all of 2..9 below ten decades), instead of eight a decade. Each tick is three lines
    and two texts, made again for every figure: on a report's Bode plots (three log axes, 4-5
    decades) eight a decade were a quarter of saving the figure. Below a decade the default is
    kept (matplotlib labels its minor ticks there, and 2 and 5 may be all the labels)."""
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            loc = axis.get_minor_locator()
            if axis.get_scale() != "log" or type(loc) is not LogLocator:
                continue
            subs = getattr(loc, "_subs", None)  # "auto", or what a plot chose
            if not (isinstance(subs, str) and subs == "auto"):
                continue
            lo, hi = sorted(abs(v) for v in axis.get_view_interval())
            if lo > 0 and math.log10(hi / lo) > 1.0:
                loc.set_params(subs=SPARSE_SUBS)
