"""``daq.tick_labels``: log-axis labels in plain text, the same numbers as matplotlib's."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from matplotlib.ticker import LogFormatterSciNotation, LogLocator, ScalarFormatter

from daq.plots import new_figure
from daq.tick_labels import PlainLogFormatter, plain_log_labels, sparse_log_minors, unmath

_FROM_SUPER = str.maketrans("⁰¹²³⁴⁵⁶⁷⁸⁹⁻", "0123456789-")


def _value(plain: str) -> float:
    """The number a plain label shows: '2×10⁻¹' -> 0.2, '10³' -> 1000, '1' -> 1."""
    mant, _, power = plain.rpartition("×")
    if power.startswith("10") and len(power) > 2:  # 10 and its exponent in superscripts
        e = int(power[2:].translate(_FROM_SUPER))
        return float(mant or 1) * 10.0**e
    return float(plain)


@given(
    exponent=st.integers(-15, 15),
    mantissa=st.sampled_from([1, 2, 3, 4, 5, 6, 7, 8, 9]),
    only_base=st.booleans(),
)
def test_a_plain_label_shows_the_number_matplotlibs_shows(exponent, mantissa, only_base):
    fig, axes = new_figure()
    ax = axes[0, 0]
    ax.set_xscale("log")
    lo, hi = 10.0 ** (exponent - 1), 10.0 ** (exponent + 1)
    ax.set_xlim(lo, hi)
    x = mantissa * 10.0**exponent
    ref = LogFormatterSciNotation(labelOnlyBase=only_base)
    ref.set_axis(ax.xaxis)
    plain = PlainLogFormatter(labelOnlyBase=only_base)
    plain.set_axis(ax.xaxis)
    want = ref(x)
    got = plain(x)
    assert "$" not in got and "\\" not in got
    if want == "":
        assert got == ""
    else:
        assert np.isclose(_value(got), x, rtol=1e-9), (want, got)


def test_forms_it_does_not_know_are_left_as_matplotlib_wrote_them():
    assert unmath("$\\mathdefault{10^{1.5}}$") == "$\\mathdefault{10^{1.5}}$"
    assert unmath("$\\alpha$") == "$\\alpha$"
    assert unmath("0.5") == "0.5"
    assert unmath("$\\mathdefault{0.5}$") == "0.5"


def test_log_axes_become_plain_and_a_chosen_formatter_is_left_alone():
    fig, axes = new_figure(1, 2)
    a, b = axes.flat
    a.loglog([0.05, 400], [1e-12, 1e-3])
    b.set_xscale("log")
    b.xaxis.set_major_formatter(ScalarFormatter())
    b.plot([6, 47], [1, 2])
    plain_log_labels(fig)
    assert isinstance(a.xaxis.get_major_formatter(), PlainLogFormatter)
    assert isinstance(a.yaxis.get_minor_formatter(), PlainLogFormatter)
    assert type(b.xaxis.get_major_formatter()) is ScalarFormatter
    assert isinstance(b.xaxis.get_minor_formatter(), PlainLogFormatter)
    fig.canvas.draw()
    labels = [t.get_text() for t in a.get_xticklabels() + a.get_yticklabels()]
    assert labels and not any("$" in t for t in labels)
    assert "10⁻¹²" in labels and "10²" in labels


def test_minor_ticks_are_2_and_5_a_decade_over_a_decade_and_a_plots_own_are_kept():
    fig, axes = new_figure(1, 3)
    wide, narrow, chosen = axes.flat
    wide.loglog([0.05, 400], [1e-12, 1e-3])
    narrow.semilogx([2.0, 9.0], [1, 2])
    chosen.semilogx([0.1, 1000.0], [1, 2])
    chosen.xaxis.set_minor_locator(LogLocator(subs=(3.0,)))
    before = {ax: ax.xaxis.get_minorticklocs() for ax in (narrow, chosen)}
    sparse_log_minors(fig)
    minors = wide.xaxis.get_minorticklocs()
    mant = minors / 10.0 ** np.floor(np.log10(minors) + 1e-9)
    assert len(minors) and set(np.round(mant, 6)) <= {2.0, 5.0}
    assert 0.2 in np.round(minors, 9) and 200.0 in np.round(minors, 9)
    for ax, locs in before.items():  # under a decade, or the plot's own: as they were
        assert np.array_equal(ax.xaxis.get_minorticklocs(), locs)
