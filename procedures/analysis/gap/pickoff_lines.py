"""The pickoff lines as the measured unit has them: frequencies found in the data.

DESIGN.md section 3 gives the gyro pickoff's discrete lines only roughly ("a 71 Hz pair 0.8 Hz
apart, 102 Hz, 187 Hz"), and another gyro's sit a fraction of a hertz away: with the data
sheet's frequencies a line lands a few bins off in the model and reads as a departure of
ten or twenty dB. They are unit-to-unit variation (a nominal unit's lines sit within +-1 Hz,
DESIGN.md section 8), not physics the model lacks, so each line's frequency is read off the
measured gyro channel (within ``SEARCH_HZ`` of its data-sheet value; lines whose windows
overlap, the 71 Hz pair, found together and assigned in frequency order), and its power is a
nuisance scale fitted with the noise levels (``model.line_part``, x0.25 .. x4).

The frequency is the Hann periodogram's peak bin refined by a parabola through the logarithm
of the peak and its two neighbours (Gaussian interpolation: [Gasior and Gonzalez 2004] give
its bias for the Hann window as under 2 % of a bin).
"""

from __future__ import annotations

import logging

import numpy as np

from procedures.analysis.gap.grid import Grid
from procedures.analysis.lines import LINE_NARROWNESS, MeasuredLine, refine_line
from simhw.config import SimConfig

__all__ = ["LINE_NARROWNESS", "MeasuredLine", "found_pickoff_lines", "refine_line"]

log = logging.getLogger(__name__)

#: how far from its data-sheet frequency a line is looked for: a nominal unit's lines sit
#: within +-1 Hz (DESIGN.md section 8), and the interpolated peak of a line at the window's edge
#: must still be found
SEARCH_HZ = 1.25
#: two lines are not placed closer than this (the 71 Hz pair is ~0.8 Hz apart)
MIN_SEPARATION_HZ = 0.35
#: a peak must stand this far above the median of its search window to be taken as the line
MIN_PROMINENCE = 10.0


def _clusters(freqs: list[float]) -> list[list[int]]:
    """Indices of the lines whose search windows overlap, grouped (the 71 Hz pair is one group:
    a unit whose pair moved by most of a hertz has its lower line where the data sheet puts the
    upper one, so the pair is found together and assigned in frequency order)."""
    order = sorted(range(len(freqs)), key=lambda i: freqs[i])
    groups: list[list[int]] = []
    for i in order:
        if groups and freqs[i] - freqs[groups[-1][-1]] <= 2 * SEARCH_HZ:
            groups[-1].append(i)
        else:
            groups.append([i])
    return groups


def _peak(f: np.ndarray, p: np.ndarray, j: int, df: float) -> float:
    """The peak bin's frequency refined by Gaussian interpolation."""
    y0, y1, y2 = np.log(p[j - 1 : j + 2])
    curve = y0 - 2 * y1 + y2
    delta = float(np.clip(0.5 * (y0 - y2) / curve, -0.5, 0.5)) if curve < 0 else 0.0
    return float(f[j] + delta * df)


def found_pickoff_lines(
    cfg: SimConfig, axis: str, channels: tuple[str, ...], p_bins: np.ndarray, grid: Grid
) -> SimConfig:
    """A copy of ``cfg`` with the axis gyro's pickoff lines at the frequencies found in the
    measured ``gyro_<axis>`` channel's periodogram ``p_bins`` (bins of ``grid``); a line the
    data do not show (no gyro channel, beyond the analysed band, no prominent peak) keeps its
    data-sheet frequency. Lines whose windows overlap are found together: the strongest
    peaks of their joint window, kept apart, assigned in frequency order."""
    name = f"gyro_{axis.lower()}"
    lines = [list(map(float, ln)) for ln in cfg.gyro[axis].pickoff_lines]
    if name not in channels or not lines:
        return cfg
    f, p, df = grid.f, p_bins[channels.index(name)], grid.df
    for group in _clusters([ln[0] for ln in lines]):
        lo = min(lines[i][0] for i in group) - SEARCH_HZ
        hi = max(lines[i][0] for i in group) + SEARCH_HZ
        idx = np.flatnonzero((f >= lo) & (f <= hi))
        if len(idx) < 3:
            continue
        floor = float(np.median(p[idx]))
        found: list[float] = []
        avail = np.ones(len(idx), bool)
        while len(found) < len(group) and avail.any():
            k = int(np.flatnonzero(avail)[np.argmax(p[idx][avail])])
            j = int(idx[k])
            if not (0 < j < len(p) - 1) or p[j] < MIN_PROMINENCE * floor:
                break
            fj = _peak(f, p, j, df)
            found.append(fj)
            avail &= np.abs(f[idx] - fj) > MIN_SEPARATION_HZ
        if not found:
            continue
        members = sorted(group, key=lambda i: lines[i][0])
        if len(found) == len(members):
            for i, fj in zip(members, sorted(found)):
                lines[i][0] = fj
        else:  # fewer peaks than lines: each to the nearest line not yet placed
            free = list(members)
            for fj in found:
                i = min(free, key=lambda m: abs(lines[m][0] - fj))
                lines[i][0] = fj
                free.remove(i)
    out = cfg.copy()
    out.gyro[axis].pickoff_lines = lines
    moved = [
        f"{a[0]:.2f} -> {b[0]:.3f} Hz"
        for a, b in zip(cfg.gyro[axis].pickoff_lines, lines)
        if a[0] != b[0]
    ]
    if moved:
        log.info("pickoff lines of gyro %s found in the data: %s", axis, ", ".join(moved))
    return out
