"""Offset steps in the time domain: what spectra smear out.

A step of size ``a`` at time ``t0`` changes the difference of the means of the windows just
after and just before ``t0``,

    D(t) = mean(x[t, t + W]) - mean(x[t - W, t]),

by ``g a`` at ``t = t0``, where ``g`` is what the channel's step response leaves of a unit step in
that difference (``template_gain``). Away from steps ``D`` is noise whose scale is estimated
robustly (1.4826 x the median absolute deviation, so a few steps do not inflate it); a step is
declared where ``|D|`` exceeds ``z`` times that scale, one per ``W``. With ``z = 6`` a Gaussian
record of 300 s has a false-alarm probability of order 1e-7.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Step:
    time_s: float
    size: float      # in the units of the data given (divide by the template gain for the input)
    z: float         # |D| over its robust scale


def window_difference(x: np.ndarray, n_win: int, hop: int) -> tuple[np.ndarray, np.ndarray]:
    """D at sample positions ``pos`` (every ``hop``), from cumulative sums."""
    c = np.concatenate([[0.0], np.cumsum(x - x.mean())])
    pos = np.arange(n_win, len(x) - n_win + 1, hop)
    after = (c[pos + n_win] - c[pos]) / n_win
    before = (c[pos] - c[pos - n_win]) / n_win
    return pos, after - before


def robust_scale(d: np.ndarray) -> float:
    return float(1.4826 * np.median(np.abs(d - np.median(d))))


def find_steps(x: np.ndarray, rate_hz: float, *, window_s: float = 2.0, z: float = 6.0) -> tuple[list[Step], float]:
    """Steps in ``x`` and the robust scale of D (for the channel's detection limit)."""
    n_win = max(2, int(round(window_s * rate_hz)))
    if len(x) < 4 * n_win:
        return [], float("nan")
    hop = max(1, n_win // 20)
    pos, d = window_difference(np.asarray(x, float), n_win, hop)
    sigma = robust_scale(d)
    if not sigma > 0:
        return [], sigma
    over = np.abs(d) > z * sigma
    steps: list[Step] = []
    order = np.argsort(-np.abs(d))
    taken = np.zeros(len(d), bool)
    guard = max(1, n_win // hop)
    for i in order:
        if not over[i]:
            break
        if taken[i]:
            continue
        taken[max(0, i - guard): i + guard + 1] = True
        steps.append(Step(pos[i] / rate_hz, float(d[i]), float(abs(d[i]) / sigma)))
    return sorted(steps, key=lambda s: s.time_s), sigma


def template_gain(response: np.ndarray, rate_hz: float, *, window_s: float = 2.0) -> float:
    """The peak of D over a channel's response to a unit step applied at ``window_s`` into
    ``response`` (which must cover at least two windows after it)."""
    n_win = max(2, int(round(window_s * rate_hz)))
    pos, d = window_difference(np.asarray(response, float), n_win, 1)
    return float(d[np.argmax(np.abs(d))])
