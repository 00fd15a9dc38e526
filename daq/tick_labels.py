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

import re

from matplotlib.figure import Figure
from matplotlib.ticker import LogFormatterSciNotation

__all__ = ["PlainLogFormatter", "plain_log_labels", "unmath"]

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
