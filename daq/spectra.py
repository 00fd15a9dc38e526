"""Spectral estimates used across the project (thesis Ch. IV, App. A).

Welch averaging of Hann-windowed segments (App. A.4); one-sided densities, so the power in a
band is the plain integral of the PSD over it (the thesis's plots are two-sided: its areas
are doubled, Ch. V B.2).
"""

from __future__ import annotations

import numpy as np
import scipy.signal


def psd(x: np.ndarray, fs: float, seg_s: float = 8.0) -> tuple[np.ndarray, np.ndarray]:
    """One-sided Welch PSD (units^2/Hz) with Hann windows of ``seg_s`` seconds, 50 % overlap."""
    nperseg = min(len(x), int(round(seg_s * fs)))
    return scipy.signal.welch(x, fs=fs, window="hann", nperseg=nperseg, detrend="linear")


def band_rms(f: np.ndarray, p: np.ndarray, lo: float, hi: float) -> float:
    """rms of the part of a one-sided PSD between ``lo`` and ``hi`` Hz."""
    sel = (f >= lo) & (f <= hi)
    return float(np.sqrt(np.trapezoid(p[sel], f[sel])))


def _smoothed_db(f: np.ndarray, p: np.ndarray, smooth_hz: float) -> np.ndarray:
    k = max(1, int(round(smooth_hz / (f[1] - f[0]))))
    return 10 * np.convolve(np.log10(p), np.ones(k) / k, mode="same")


def dip_frequency(f: np.ndarray, p: np.ndarray, lo: float = 1.0, hi: float = 12.0,
                  smooth_hz: float = 0.5) -> float:
    """Frequency of the deepest minimum of a PSD within ``lo``..``hi`` Hz (Ch. V E.1).

    The PSD is first smoothed in log over ``smooth_hz`` so a single low estimate does not win.
    """
    db = _smoothed_db(f, p, smooth_hz)
    sel = np.nonzero((f >= lo) & (f <= hi))[0]
    return float(f[sel[np.argmin(db[sel])]])


def dip_depth_db(f: np.ndarray, p: np.ndarray, f_dip: float, smooth_hz: float = 0.5) -> float:
    """How far (dB) the PSD at ``f_dip`` lies below the lower of its values at f_dip/2 and
    1.6 f_dip: positive for a true notch, negative where the spectrum merely slopes."""
    db = _smoothed_db(f, p, smooth_hz)

    def at(x: float) -> float:
        return float(db[np.argmin(np.abs(f - x))])

    return min(at(f_dip / 2), at(1.6 * f_dip)) - at(f_dip)
