"""The pickoff lines as the measured unit has them: frequencies found in the data.

DESIGN.md section 3 gives the gyro pickoff's discrete lines only roughly ("a 71 Hz pair 0.8 Hz
apart, 102 Hz, 187 Hz"), and another gyro's sit a fraction of a hertz away: with the data
sheet's frequencies a line lands a few bins off in the model and reads as a departure of
ten or twenty dB. They are unit-to-unit variation, not physics the model lacks, so each line's
frequency is read off the measured gyro channel (the strongest first, each within
``SEARCH_HZ`` of its data-sheet value and clear of the lines already placed), and its power
is a nuisance scale fitted with the noise levels (``model.line_part``).

The frequency is the Hann periodogram's peak bin refined by a parabola through the logarithm
of the peak and its two neighbours (Gaussian interpolation: [Gasior and Gonzalez 2004] give
its bias for the Hann window as under 2 % of a bin).
"""

from __future__ import annotations

import logging

import numpy as np

from procedures.analysis.gap.grid import Grid
from procedures.analysis.lines import LINE_NARROWNESS, MeasuredLine, refine_line
from simhw.params import SimConfig

__all__ = ["LINE_NARROWNESS", "MeasuredLine", "found_pickoff_lines", "refine_line"]

log = logging.getLogger(__name__)

#: how far from its data-sheet frequency a line is looked for (unit-to-unit spread +-0.5 Hz)
SEARCH_HZ = 0.75
#: two lines are not placed closer than this (the 71 Hz pair is ~0.8 Hz apart)
MIN_SEPARATION_HZ = 0.35
#: a peak must stand this far above the median of its search window to be taken as the line
MIN_PROMINENCE = 10.0


def found_pickoff_lines(cfg: SimConfig, axis: str, channels: tuple[str, ...], p_bins: np.ndarray,
                        grid: Grid) -> SimConfig:
    """A copy of ``cfg`` with the axis gyro's pickoff lines at the frequencies found in the
    measured ``gyro_<axis>`` channel's periodogram ``p_bins`` (bins of ``grid``); a line the
    data do not show (no gyro channel, beyond the analysed band, no prominent peak) keeps its
    data-sheet frequency."""
    name = f"gyro_{axis.lower()}"
    lines = [list(map(float, ln)) for ln in cfg.gyro[axis].pickoff_lines]
    if name not in channels or not lines:
        return cfg
    f, p, df = grid.f, p_bins[channels.index(name)], grid.df
    placed: list[float] = []
    for k in sorted(range(len(lines)), key=lambda i: -lines[i][1]):
        f0 = lines[k][0]
        sel = np.abs(f - f0) <= SEARCH_HZ
        for fp in placed:
            sel &= np.abs(f - fp) > MIN_SEPARATION_HZ
        idx = np.flatnonzero(sel)
        if len(idx) < 3:
            continue
        j = idx[np.argmax(p[idx])]
        if not (0 < j < len(p) - 1) or p[j] < MIN_PROMINENCE * np.median(p[idx]):
            continue
        y0, y1, y2 = np.log(p[j - 1:j + 2])
        curve = y0 - 2 * y1 + y2
        delta = float(np.clip(0.5 * (y0 - y2) / curve, -0.5, 0.5)) if curve < 0 else 0.0
        lines[k][0] = float(f[j] + delta * df)
        placed.append(lines[k][0])
    out = cfg.copy()
    out.gyro[axis].pickoff_lines = lines
    moved = [f"{a[0]:.2f} -> {b[0]:.3f} Hz" for a, b in zip(cfg.gyro[axis].pickoff_lines, lines) if a[0] != b[0]]
    if moved:
        log.info("pickoff lines of gyro %s found in the data: %s", axis, ", ".join(moved))
    return out
