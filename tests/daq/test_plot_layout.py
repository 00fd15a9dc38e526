"""``daq.plot_layout.place_axes``: margins from the text, measured without a layout pass.

Each figure is built as the reports build theirs (log axes over many decades and under one,
mathtext tick labels, offset texts, two-line titles, a suptitle, hidden axes in a grid, minor
tick labels, small fonts), laid out, drawn, and then checked against what a layout must give:
every text inside the canvas and no two axes' text overlapping."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from matplotlib.ticker import ScalarFormatter

from daq.plot_layout import place_axes
from daq.plots import new_figure, save_figure


def _loglog(ax, rng):
    f = np.geomspace(0.05, 400, 500)
    ax.loglog(f, 1e-12 * (1 + 3 / f) * rng.uniform(0.5, 2, f.size), label="PSD")
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("PSD (urad²/Hz)")
    ax.set_title("survey.h5, Mode 3, 300 s at 1000 Hz\ngyro_x: PSD, App. A.8 octave-band display")
    ax.legend(loc="best", fontsize=8)


def _response(axes, rng):
    f = np.linspace(0.125, 500, 4000)
    g, p, c = axes.flat
    g.semilogx(f, -20 * np.log10(1 + f), label="measured")
    p.semilogx(f, -180 * f / (1 + f))
    c.semilogx(f, rng.uniform(0, 1, f.size))
    g.set_title("ac_x_ctl -> pa_x via V_Td")
    for ax, lab in zip(axes.flat, ("gain (dB)", "phase (deg)", "coherence")):
        ax.set_ylabel(lab)
        ax.grid(True, which="both")
    c.set_xlabel("frequency (Hz)")


def _small_values(ax, rng):  # an offset text on both axes: "1e-5" above, "+1e4" below
    t = 1e4 + np.linspace(0, 2, 200)
    ax.plot(t, 1e-5 * (3 + rng.normal(size=t.size)))
    ax.set_xlabel("file time (s)")
    ax.set_ylabel("bearing torque (N m)")


def _wide_ticks(ax, rng):
    ax.plot(np.arange(50), -123456.0 + rng.normal(size=50))
    ax.yaxis.set_major_formatter(ScalarFormatter(useOffset=False))
    ax.set_ylabel("counts")
    ax.set_xlabel("sample")


def _short_log(ax, rng):  # a log axis shorter than a decade: its minor ticks are labelled
    x = np.geomspace(6, 47, 12)
    ax.plot(x, 1 + 0.01 * rng.normal(size=x.size), "o-")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.xaxis.set_major_formatter(ScalarFormatter())
    ax.xaxis.set_minor_formatter(ScalarFormatter())
    ax.tick_params(axis="x", which="minor", labelsize=7)
    ax.set_xlabel("angle-path low-pass (Hz)")
    ax.set_ylabel("To / chosen")


def _grid_of_loops(axes, rng, fig):
    for ax in axes.flat[7:]:
        ax.set_visible(False)
    for ax in axes.flat[:7]:
        th = np.linspace(0, 2 * np.pi, 100)
        ax.plot(500 * np.cos(th), 15 * np.sin(th + 0.3), ".", ms=2.5)
        ax.set_title("506 urad, 6 cycles", fontsize=9)
        ax.set_xlabel("angle (urad)", fontsize=8)
        ax.set_ylabel("bearing torque (mN m)", fontsize=8)
        ax.tick_params(labelsize=7)
    fig.suptitle("X gimbal bearing: torque against angle at 0.4 Hz (To 16.1 mN m)", fontsize=10)


CASES = {
    "psd": ((1, 1), (9.0, 5.5), lambda fig, axes, rng: _loglog(axes[0, 0], rng)),
    "response": ((3, 1), (9.0, 8.0), lambda fig, axes, rng: _response(axes, rng)),
    "offsets": ((1, 2), (10.0, 4.2), lambda fig, axes, rng: _small_values(axes[0, 0], rng)),
    "wide": ((2, 2), (10.0, 7.0), lambda fig, axes, rng: [_wide_ticks(a, rng) for a in axes.flat]),
    "short-log": (
        (1, 2),
        (10.0, 3.8),
        lambda fig, axes, rng: [_short_log(a, rng) for a in axes.flat],
    ),
    "loops": ((2, 4), (14.4, 6.4), lambda fig, axes, rng: _grid_of_loops(axes, rng, fig)),
}


def _laid_out(name):
    (rows, cols), size, build = CASES[name]
    fig, axes = new_figure(rows, cols, figsize=size)
    build(fig, axes, np.random.default_rng(7))
    return fig


@pytest.mark.parametrize("name", sorted(CASES))
def test_every_text_inside_the_canvas_and_no_two_axes_overlap(name):
    fig = _laid_out(name)
    assert place_axes(fig)
    renderer = fig.canvas.get_renderer()
    fig.draw(renderer)
    canvas = fig.bbox
    boxes = []
    for ax in fig.axes:
        if not ax.get_visible():
            continue
        bb = ax.get_tightbbox(renderer)
        assert bb.x0 >= canvas.x0 and bb.y0 >= canvas.y0, (name, bb, canvas)
        assert bb.x1 <= canvas.x1 and bb.y1 <= canvas.y1, (name, bb, canvas)
        boxes.append(bb)
    sup = fig.get_suptitle()
    if sup:
        bb = fig._suptitle.get_window_extent(renderer)
        assert canvas.y1 >= bb.y1 and all(bb.y0 >= b.y1 - 1e-6 for b in boxes), name
    for a, b in itertools.combinations(boxes, 2):
        w = min(a.x1, b.x1) - max(a.x0, b.x0)
        h = min(a.y1, b.y1) - max(a.y0, b.y0)
        assert w <= 0 or h <= 0, (name, a, b)


@pytest.mark.parametrize("name", sorted(CASES))
def test_the_axes_get_no_less_room_than_tight_layout_gives_them_less_a_fifth(name):
    """Not a layout that is safe by being wasteful: each axes at least 80 % of its area under
    ``tight_layout``."""
    ours, tight = _laid_out(name), _laid_out(name)
    assert place_axes(ours)
    tight.tight_layout()
    for a, b in zip(ours.axes, tight.axes):
        if a.get_visible():
            pa, pb = a.get_position(), b.get_position()
            assert pa.width * pa.height >= 0.8 * pb.width * pb.height, (name, pa, pb)


def test_a_figure_with_no_room_for_its_text_is_left_to_tight_layout(tmp_path):
    fig, axes = new_figure(3, 3, figsize=(2.0, 1.5))
    for ax in axes.flat:
        ax.set_title("a title longer than the figure is wide\nand two lines")
        ax.set_ylabel("a long y label")
        ax.set_xlabel("a long x label")
    before = [ax.get_position().bounds for ax in fig.axes]
    assert not place_axes(fig)
    assert [ax.get_position().bounds for ax in fig.axes] == before  # nothing changed
    with pytest.warns(UserWarning, match="Tight layout not applied"):  # tight_layout tried it
        assert save_figure(fig, tmp_path / "crowded.png").stat().st_size > 0
