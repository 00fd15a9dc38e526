"""Offset steps in the time domain: what spectra smear out.

A step of size ``a`` at time ``t0`` changes the difference of the means of the windows just
after and just before ``t0``,

    D(t) = mean(x[t, t + W]) - mean(x[t - W, t]),

by ``g a`` at ``t = t0``, where ``g`` is what the channel's step response leaves of a unit step in
that difference (``template_gain``). Away from steps ``D`` is noise whose scale is estimated
robustly (1.4826 x the median absolute deviation, so a few steps do not inflate it); a step is
declared where ``|D|`` exceeds ``z`` times that scale; its response is then subtracted and the
search repeated (CLEAN). With ``z = 6`` a Gaussian record of 300 s has a false-alarm
probability of order 1e-7.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Step:
    time_s: float
    size: float  # in the units of the data given (divide by the template gain for the input)
    z: float  # |D| over its robust scale


def window_difference(x: np.ndarray, n_win: int, hop: int) -> tuple[np.ndarray, np.ndarray]:
    """D at sample positions ``pos`` (every ``hop``), from cumulative sums."""
    c = np.concatenate([[0.0], np.cumsum(x - x.mean())])
    pos = np.arange(n_win, len(x) - n_win + 1, hop)
    after = (c[pos + n_win] - c[pos]) / n_win
    before = (c[pos] - c[pos - n_win]) / n_win
    return pos, after - before


def robust_scale(d: np.ndarray) -> float:
    return float(1.4826 * np.median(np.abs(d - np.median(d))))


def find_steps(
    x: np.ndarray,
    rate_hz: float,
    *,
    template: np.ndarray | None = None,
    step_at: int = 0,
    window_s: float = 2.0,
    z: float = 6.0,
    max_steps: int = 200,
) -> tuple[list[Step], float]:
    """Steps in ``x`` and the robust scale of D. One at a time, largest first, each found step's
    response is subtracted before looking again (CLEAN), so a response that is not a pure step
    (the gyro's caging loop pulls it back) leaves no ghosts. ``template`` is the channel's
    response to a unit step at sample ``step_at`` (held at its last value beyond its end); sizes
    are then in the step's units. Without it, ideal steps in the data's units."""
    n_win = max(2, int(round(window_s * rate_hz)))
    x = np.asarray(x, float)
    if len(x) < 4 * n_win:
        return [], float("nan")
    hop = max(1, n_win // 20)
    if template is None:
        template, step_at = np.array([0.0, 1.0]), 1
    gain = (
        template_gain(template, rate_hz, step_at=step_at, window_s=window_s)
        if len(template) > 2
        else 1.0
    )
    x = x - x.mean()
    pos, d = window_difference(x, n_win, hop)
    sigma = robust_scale(d)
    if not (sigma > 0 and gain != 0):
        return [], sigma
    steps: list[Step] = []
    while len(steps) < max_steps:
        i = int(np.argmax(np.abs(d)))
        if abs(d[i]) <= z * sigma:
            break
        k = int(pos[i])
        size = float(d[i] / gain)
        steps.append(Step(k / rate_hz, size, float(abs(d[i]) / sigma)))
        _subtract(x, k, size, template, step_at)
        pos, d = window_difference(x, n_win, hop)
    return sorted(steps, key=lambda s: s.time_s), sigma


def _subtract(x: np.ndarray, k: int, size: float, template: np.ndarray, step_at: int) -> None:
    """x -= size * (the template placed with its step at sample k, held beyond its end)."""
    a = k - step_at
    lo, hi = max(0, a), min(len(x), a + len(template))
    if hi > lo:
        x[lo:hi] -= size * template[lo - a : hi - a]
    if a + len(template) < len(x):
        x[max(0, a + len(template)) :] -= size * template[-1]


def template_gain(
    response: np.ndarray, rate_hz: float, *, step_at: int | None = None, window_s: float = 2.0
) -> float:
    """D of a channel's response to a unit step, at the step (sample ``step_at``; default the
    peak of |D|)."""
    n_win = max(2, int(round(window_s * rate_hz)))
    pos, d = window_difference(np.asarray(response, float), n_win, 1)
    if step_at is None:
        return float(d[np.argmax(np.abs(d))])
    return float(d[np.argmin(np.abs(pos - step_at))])


def step_like(response: np.ndarray, rate_hz: float, step_at: int, *, window_s: float = 2.0) -> bool:
    """Whether a response reads as a step in D (a triangle peaked at the step, half height a
    half-window later) rather than a transient (a plateau either side): steps can only be timed
    and sized in the former."""
    n_win = max(2, int(round(window_s * rate_hz)))
    pos, d = window_difference(np.asarray(response, float), n_win, 1)
    at = d[np.argmin(np.abs(pos - step_at))]
    later = d[np.argmin(np.abs(pos - (step_at + n_win // 2)))]
    return abs(at) > 0 and abs(later) <= 0.7 * abs(at) and abs(at) >= 0.5 * np.max(np.abs(d))
