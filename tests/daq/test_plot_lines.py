"""Issue 37 item 11: the PSD plots marked every App. A.8 kept point (3 times its band's average)
as a line, so a filter's roll-off and a resonance's peak were labelled in Hz as if they were
lines. Only the narrow ones are lines now (``daq.plots.narrow_lines``); the rest are drawn apart."""

from __future__ import annotations

import numpy as np

from daq.octave import octave_bands
from daq.plots import narrow_lines, plot_psd


def _spectrum() -> tuple[np.ndarray, np.ndarray]:
    """White noise through a damped resonance (7 Hz, zeta 0.15) and a steep 4-pole roll-off at
    40 Hz, with one line at 71 Hz: Welch-like bins of 1/16 Hz to 250 Hz."""
    f = np.arange(1, 4001) / 16.0
    s = 2j * np.pi * f
    w = 2 * np.pi * 7.0
    res = np.abs(w * w / (s * s + 2 * 0.15 * w * s + w * w)) ** 2
    roll = 1.0 / (1.0 + (f / 40.0) ** 8)
    p = 1e-3 * (1.0 + 3 * res) * roll + 1e-12
    p[np.argmin(np.abs(f - 71.0))] += 5e-4
    return f, p


def test_roll_off_and_resonance_are_kept_points_but_no_lines():
    f, p = _spectrum()
    b = octave_bands(f, p)
    kept = b.kept_f
    broad = kept[np.abs(kept - 71.0) > 0.5]
    assert len(broad) > 0  # the App. A.8 rule keeps them (the side effect daq.octave describes)
    line = narrow_lines(f, p, kept)
    assert list(kept[line]) == [71.0]


def test_a_line_on_a_resonance_is_still_a_line_and_the_plot_is_written(tmp_path):
    f, p = _spectrum()
    i = int(np.argmin(np.abs(f - 7.0)))
    p[i] *= 40.0  # a line on top of the resonance
    assert list(np.asarray(f)[[i]][narrow_lines(f, p, [7.0])]) == [7.0]
    out = plot_psd(tmp_path / "p.png", f, p, channel="x", units="urad", dof=20.0, nperseg=8000)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
