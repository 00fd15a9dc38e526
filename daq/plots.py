"""Spectral plots as the thesis draws them (App. A.8), written straight to PNG files.

* ``plot_psd``: log-log PSD of one channel, shown as octave-band averages (bands each
  twice as wide as the one below) with the points greater than three times their band's
  average drawn as well, so discrete lines are not averaged away (App. A.8); a shaded
  chi-square 95 % interval of the band averages from Welch's EDOF (App. A.4).
* ``plot_coherence``: magnitude-squared coherence of a pair (eq. 4.44) on a linear 0..1
  axis against log frequency, raw and octave-band averaged, with the level below which
  the estimate is consistent with zero coherence.

Matplotlib is used through ``matplotlib.figure.Figure`` and the Agg canvas only: no
``pyplot``, so nothing is left in a global figure registry and no GUI backend is touched.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Literal

import numpy as np
from matplotlib import rc_context
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from daq.octave import OctaveBands, band_average_dof, octave_bands
from daq.plot_layout import place_axes
from daq.spectral import psd_confidence
from daq.tick_labels import plain_log_labels, sparse_log_minors

__all__ = [
    "coherence_significance",
    "narrow_lines",
    "new_figure",
    "plot_coherence",
    "plot_psd",
    "psd_units_label",
    "save_figure",
]

log = logging.getLogger(__name__)

FIGSIZE = (9.0, 5.5)
DPI = 120
#: the procedures' report figures
REPORT_DPI = 110


def psd_units_label(units: str, scaling: str = "density") -> str:
    """``'V'`` -> ``'V²/Hz'``; compound units are bracketed: ``'m/s'`` -> ``'(m/s)²/Hz'``."""
    u = units.strip() or "unit"
    sq = f"({u})²" if any(c in u for c in "/*· ^") else f"{u}²"
    return f"{sq}/Hz" if scaling == "density" else sq


def coherence_significance(n_segments: float, alpha: float = 0.05) -> float:
    r"""The magnitude-squared coherence that an estimate from ``n_segments`` independent
    segments of two incoherent Gaussian signals exceeds with probability ``alpha``:
    :math:`1 - \alpha^{1/(K-1)}` (from :math:`P(\hat\gamma^2 > c) = (1 - c)^{K-1}`, [BP]).
    1 for a single segment, where the estimate is identically 1 (eq. 4.50)."""
    if n_segments <= 1:
        return 1.0
    return float(1.0 - alpha ** (1.0 / (n_segments - 1.0)))


def _strongest_distinct(
    f: np.ndarray, p: np.ndarray, n: int = 3, spacing: float = 0.25
) -> list[tuple[float, float]]:
    """The ``n`` largest points whose frequencies differ from every stronger one chosen by
    more than the fraction ``spacing`` (one label per line or cluster, so labels do not overlap)."""
    out: list[tuple[float, float]] = []
    for i in np.argsort(p)[::-1]:
        if all(abs(f[i] - g) > spacing * g for g, _ in out):
            out.append((float(f[i]), float(p[i])))
            if len(out) == n:
                break
    return out


#: a kept point is a line when it stands this many times above the median of its neighbours
LINE_FACTOR = 10.0


def narrow_lines(
    f, p, candidates, *, factor: float = LINE_FACTOR, guard_bins: int = 3
) -> np.ndarray:
    """Which of the ``candidates`` (frequencies of the spectrum ``p(f)``, e.g. the App. A.8 points
    kept above 3 times their band's average) are narrow lines: points more than ``factor`` times
    the median of their neighbours between ``max(guard_bins bins, 5 % of f)`` and ``max(4
    guard_bins bins, 20 % of f)`` away on either side. A filter's roll-off (where the octave
    rule keeps a band's lowest bins, ``daq.octave``) and a damped resonance's peak are as high
    as their neighbours there, so they are kept points but no lines."""
    f = np.asarray(f, dtype=float)
    p = np.asarray(p, dtype=float)
    out = np.zeros(len(candidates), dtype=bool)
    if len(f) < 3:
        return out
    df = float(np.median(np.diff(f)))
    for j, fk in enumerate(np.asarray(candidates, dtype=float)):
        i = int(np.argmin(np.abs(f - fk)))
        d = np.abs(f - f[i])
        near = max(guard_bins * df, 0.05 * f[i])
        far = max(4 * guard_bins * df, 0.2 * f[i])
        sel = (d >= near) & (d <= far) & np.isfinite(p)
        if sel.any():
            out[j] = bool(p[i] > factor * np.median(p[sel]))
    return out


def new_figure(
    nrows: int = 1,
    ncols: int = 1,
    figsize: tuple[float, float] = (9.0, 5.5),
    layout: Literal["constrained", "compressed", "tight"] | None = None,
) -> tuple[Figure, np.ndarray]:
    """A figure on the Agg canvas with an (nrows, ncols) array of axes; no pyplot, no GUI."""
    fig = Figure(figsize=figsize, layout=layout)
    FigureCanvasAgg(fig)
    with rc_context({"axes.titley": 1.0}):
        axes = np.atleast_1d(fig.subplots(nrows, ncols, squeeze=False))
    return fig, axes


def save_figure(fig: Figure, path: str | Path, dpi: float = REPORT_DPI) -> Path:
    """Write the PNG and free the figure; returns the path. Log axes are labelled in plain text,
    their minor ticks at 2 and 5 a decade where they span more (``daq.tick_labels``); a figure
    without a layout engine is laid out by ``daq.plot_layout.place_axes`` (its text measured,
    not its ticks laid out), or by ``tight_layout`` where that cannot."""
    try:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        plain_log_labels(fig)
        sparse_log_minors(fig)
        if fig.get_layout_engine() is None and not place_axes(fig):
            fig.tight_layout()
        fig.savefig(path, dpi=dpi, format="png", pil_kwargs={"compress_level": 1})
        log.debug("wrote %s", path)
        return path
    finally:
        fig.clear()


def _new_figure() -> tuple[Figure, Axes]:
    fig, axes = new_figure(figsize=FIGSIZE)
    return fig, axes[0, 0]


def _finish(fig: Figure, ax: Axes, out: str | Path) -> Path:
    """Grid the axes, write the PNG and free the figure; returns the path."""
    ax.grid(True, which="major", alpha=0.5)
    ax.grid(True, which="minor", alpha=0.15)
    return save_figure(fig, out, dpi=DPI)


def plot_psd(
    out: str | Path,
    f,
    p,
    *,
    channel: str,
    units: str,
    dof: float,
    window="hann",
    nperseg: int,
    nfft: int | None = None,
    title: str = "",
    factor: float = 3.0,
    level: float = 0.95,
    scaling: str = "density",
    bands: OctaveBands | None = None,
) -> Path:
    """Write the App. A.8 log-log PSD plot of one channel to ``out`` (PNG); returns the path.

    ``f``, ``p``: the one-sided Welch PSD; ``dof``: its per-bin EDOF
    (``spectra.equivalent_dof``); ``window``, ``nperseg``, ``nfft``: the Welch options, for
    the EDOF of a band average (``octave.band_average_dof``); ``title``: the first title
    line (file, rate, segments...). ``bands`` may be passed if already computed with the
    same ``factor``. Pass the bins to display: ``fbs spectra`` leaves out the unpaired
    Nyquist bin of an even FFT length (one-sided, it holds half its neighbours' density).
    """
    f = np.asarray(f, dtype=float)
    p = np.asarray(p, dtype=float)
    b = bands if bands is not None else octave_bands(f, p, factor=factor)
    fig, ax = _new_figure()
    ok = np.isfinite(b.average) & (b.average > 0)
    if ok.any():
        nu = band_average_dof(dof, b.count[ok], window=window, nperseg=nperseg, nfft=nfft)
        lo, hi = psd_confidence(b.average[ok], nu, level)
        ax.fill_between(
            b.f_center[ok],
            lo,
            hi,
            color="C0",
            alpha=0.2,
            linewidth=0,
            label=f"{level:.0%} χ² interval of the band average (EDOF ν = {dof:.0f} per bin)",
        )
        ax.loglog(
            b.f_center[ok],
            b.average[ok],
            "o-",
            color="C0",
            markersize=4,
            label="octave-band average (bands double in width)",
        )
        kept = b.kept_p > 0
        # App. A.8 keeps every point above 3 times its band's average; only the narrow ones are
        # lines: a filter's roll-off or a resonance's peak is kept too, and is marked apart
        line = narrow_lines(f, p, b.kept_f[kept])
        kf, kp = b.kept_f[kept], b.kept_p[kept]
        ax.loglog(
            kf[~line],
            kp[~line],
            "v",
            color="0.45",
            markersize=4,
            linestyle="none",
            label=f"points > {factor:g} × band average, broad (roll-off, resonance): no line "
            f"({int((~line).sum())})",
        )
        ax.loglog(
            kf[line],
            kp[line],
            "^",
            color="C3",
            markersize=5,
            linestyle="none",
            label=f"narrow lines: > {factor:g} × band average and > {LINE_FACTOR:g} × their neighbours "
            f"({int(line.sum())})",
        )
        for fk, pk in _strongest_distinct(kf[line], kp[line]):
            ax.annotate(
                f"{fk:.4g} Hz",
                (fk, pk),
                textcoords="offset points",
                xytext=(4, 4),
                fontsize=8,
                color="C3",
            )
        ax.legend(loc="best", fontsize=8)
    else:
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.text(0.5, 0.5, "no positive PSD values to plot", transform=ax.transAxes, ha="center")
    ax.set_xlabel("frequency (Hz)")
    what = "PSD" if scaling == "density" else "power spectrum"
    ax.set_ylabel(f"{what} ({psd_units_label(units, scaling)})")
    ax.set_title(
        f"{title}\n{channel}: {what}, App. A.8 octave-band display"
        if title
        else f"{channel}: {what}",
        fontsize=10,
    )
    return _finish(fig, ax, out)


def plot_coherence(
    out: str | Path,
    f,
    coh,
    *,
    pair: tuple[str, str],
    n_segments: int,
    title: str = "",
    alpha: float = 0.05,
) -> Path:
    """Write the coherence plot of one pair to ``out`` (PNG); returns the path.

    Linear 0..1 against log frequency: the raw estimate faintly, its octave-band average
    (App. A.8) with markers, and the ``1 - alpha`` significance level for zero coherence
    with ``n_segments`` averaged (``coherence_significance``). With overlapped segments
    (Welch, 50 %) the segments are not quite independent, so this level is a little low.
    """
    f = np.asarray(f, dtype=float)
    coh = np.asarray(coh, dtype=float)
    pos = f > 0
    b = octave_bands(f, coh)
    fig, ax = _new_figure()
    ax.semilogx(
        f[pos], coh[pos], "-", color="0.55", linewidth=0.6, alpha=0.6, label="coherence (per bin)"
    )
    ok = np.isfinite(b.average)
    ax.semilogx(
        b.f_center[ok], b.average[ok], "o-", color="C0", markersize=4, label="octave-band average"
    )
    sig = coherence_significance(n_segments, alpha)
    ax.axhline(
        sig,
        color="C3",
        linestyle="--",
        linewidth=1.0,
        label=f"{1 - alpha:.0%} significance of zero coherence, K = {n_segments}: {sig:.3f}",
    )
    ax.set_ylim(0.0, 1.03)  # a coherence of 1 stays visible above the frame's top
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel(f"coherence γ² {pair[0]}–{pair[1]} (dimensionless)")
    ax.legend(loc="best", fontsize=8)
    ax.set_title(
        f"{title}\ncoherence {pair[0]} – {pair[1]} (eq. 4.44)"
        if title
        else f"coherence {pair[0]} – {pair[1]}",
        fontsize=10,
    )
    return _finish(fig, ax, out)
