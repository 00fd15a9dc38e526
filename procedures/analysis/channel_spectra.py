"""The spectra of a run file (``fbs spectra``, DESIGN.md section 7).

PSD of each channel and coherence of each pair, from a run file of any size (Welch in
bounded memory, lost samples never spliced over: ``daq.filespectra``), drawn as the thesis
draws them (log-log, octave-band averages plus the points above three times their band's
average, App. A.8; ``daq.plots``), and the numbers in ``spectra.csv`` so they can be checked.
"""

from __future__ import annotations

import itertools
import logging
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from daq.runfile import make_folder

# The analysis stack (scipy, h5py, matplotlib: ~1.5 s to import) is imported when the command
# runs, not when the `fbs` parser is built, so every other subcommand starts as fast as before.
if TYPE_CHECKING:
    from daq.filespectra import RunCsd
    from daq.octave import OctaveBands

__all__ = ["SpectraResult", "choose_nperseg", "default_out_dir", "spectra_command"]

log = logging.getLogger(__name__)

TARGET_SEG_S = 10.0  # default segment length (s), rounded to a power of two of samples
MIN_SEGMENTS = 8  # ... kept only if the run holds at least this many (50 % overlap)
MIN_NPERSEG = 256
KEEP_FACTOR = 3.0  # App. A.8: points above three times their band's average are shown


@dataclass
class SpectraResult:
    """What ``spectra_command`` computed and wrote."""

    path: Path
    out_dir: Path
    csd: RunCsd
    bands: dict[str, OctaveBands]
    psd_png: dict[str, Path]
    coherence_png: dict[tuple[str, str], Path]
    csv: Path
    files: list[Path] = field(default_factory=list)

    def lines(self) -> list[str]:
        """Summary for the terminal: segments, resolution, and the lines kept per channel."""
        from daq.plots import psd_units_label

        c = self.csd
        skipped = (
            f", {c.segments_skipped} skipped (lost samples)"
            if c.segments_skipped
            else ", none skipped"
        )
        out = [
            f"{self.path.name}: {', '.join(c.channels)} at {c.fs:g} Hz, {c.n_samples} samples "
            f"({c.n_samples / c.fs:g} s)",
            f"  Welch: {c.nperseg}-sample segments ({c.segment_s:g} s, {c.noverlap} overlap), "
            f"resolution {c.resolution_hz:.4g} Hz; {c.segments_used} of {c.segments_total} segments "
            f"averaged{skipped}; EDOF {c.dof:.1f} per bin",
        ]
        for ch in c.channels:
            b = self.bands[ch]
            order = np.argsort(b.kept_p)[::-1][:5]
            peaks = ", ".join(f"{b.kept_f[i]:.4g}" for i in order)
            units = psd_units_label(c.units[c.index(ch)], c.scaling)
            out.append(
                f"  {ch}: {b.n_bands} octave bands; {len(b.kept_f)} point(s) > {b.factor:g}x band "
                f"average"
                + (f" (strongest at {peaks} Hz)" if len(b.kept_f) else "")
                + f"; PSD in {units}"
            )
        return out


def choose_nperseg(n_samples: int, fs: float, seg_s: float | None = None) -> int:
    """Segment length in samples.

    With ``seg_s``: that many seconds, rounded to a sample. By default the power of two
    nearest ``TARGET_SEG_S`` (10 s) when the run holds at least ``MIN_SEGMENTS`` (8) such
    segments at 50 % overlap; otherwise the largest power of two that still gives 8 (so
    the average keeps about 15 EDOF, App. A.4); never below ``MIN_NPERSEG`` (256) samples.
    """
    if seg_s is not None:
        if not (math.isfinite(seg_s) and seg_s > 0):
            raise ValueError(f"segment length seg_s = {seg_s!r} s must be a positive number")
        if seg_s * fs < 1.5:
            raise ValueError(
                f"segment length seg_s = {seg_s:g} s at {fs:g} Hz holds {round(seg_s * fs)} sample(s): "
                f"it must hold at least 2 (>= {2 / fs:g} s)"
            )
        if seg_s * fs > n_samples:
            raise ValueError(
                f"segment length seg_s = {seg_s:g} s is longer than the record ({n_samples} samples, "
                f"{n_samples / fs:g} s at {fs:g} Hz): use shorter segments"
            )
        return int(round(seg_s * fs))
    from daq.spectral import n_segments

    nperseg = 2 ** max(0, round(math.log2(TARGET_SEG_S * fs)))
    if n_segments(n_samples, nperseg, nperseg // 2) < MIN_SEGMENTS:
        # K = 2 n / nperseg - 1 at 50 % overlap: K >= 8 needs nperseg <= 2 n / 9
        nperseg = 2 ** max(0, math.floor(math.log2(max(1.0, 2.0 * n_samples / (MIN_SEGMENTS + 1)))))
    return max(MIN_NPERSEG, int(nperseg))


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]", "_", name)


def _write_csv(path: Path, csd: RunCsd, pairs: list[tuple[str, str]]) -> Path:
    coh = csd.coherence()
    cols = [csd.f] + [csd.psd(c) for c in csd.channels]
    cols += [coh[:, csd.index(a), csd.index(b)] for a, b in pairs]
    header = ",".join(
        ["f_hz"] + [f"psd_{c}" for c in csd.channels] + [f"coherence_{a}_{b}" for a, b in pairs]
    )
    np.savetxt(path, np.column_stack(cols), delimiter=",", header=header, comments="", fmt="%.10g")
    return path


def spectra_command(
    path: str | Path, channels: list[str], out_dir: str | Path, *, seg_s: float | None = None
) -> SpectraResult:
    """PSD and coherence plots and ``spectra.csv`` of ``channels`` of the run file ``path``.

    Writes ``psd_<channel>.png`` per channel, ``coherence_<a>_<b>.png`` per pair and
    ``spectra.csv`` (``f_hz``, ``psd_<channel>`` in units^2/Hz one-sided, and
    ``coherence_<a>_<b>``, one row per bin) into ``out_dir`` (created). Segment length:
    ``choose_nperseg``; Hann window, 50 % overlap, a line removed from each segment. The
    plots (and ``bands``) leave out DC and the unpaired Nyquist bin of an even FFT length.
    Raises ``ValueError`` (unknown channel, naming the file's; too short a file; every
    segment with lost samples) or ``RunFileError`` (not a readable run file).
    """
    from daq.filespectra import run_csd_matrix
    from daq.octave import octave_bands
    from daq.plots import plot_coherence, plot_psd
    from daq.reader import RunFile

    path = Path(path)
    channels = [c.strip() for c in channels if c.strip()]
    if not channels:
        raise ValueError("no channels given (--channels a,b)")
    with RunFile(path) as run:
        missing = [c for c in channels if c not in run.channels]
        if missing:
            raise ValueError(
                f"{path} has no channel {', '.join(missing)}; its channels are "
                f"{', '.join(run.channels)}"
            )
        nperseg = choose_nperseg(run.n_samples, run.rate_hz, seg_s)
        csd = run_csd_matrix(run, channels, nperseg=nperseg)
    out_dir = Path(out_dir)
    make_folder(out_dir)
    head = (
        f"{path.name}   fs {csd.fs:g} Hz, nperseg {csd.nperseg} ({csd.segment_s:g} s, Δf "
        f"{csd.resolution_hz:.3g} Hz), {csd.segments_used} segments averaged"
        + (f" ({csd.segments_skipped} skipped)" if csd.segments_skipped else "")
        + f", EDOF {csd.dof:.1f}"
    )
    # the display leaves out the unpaired Nyquist bin of an even nfft: one-sided, it holds half
    # the density of its neighbours (it is not doubled) with half their EDOF, and would draw a
    # band of its own as a false drop at fs/2; spectra.csv keeps every bin
    sel = slice(None, -1) if csd.nfft % 2 == 0 else slice(None)
    f = csd.f[sel]
    bands: dict[str, OctaveBands] = {}
    psd_png: dict[str, Path] = {}
    for i, ch in enumerate(csd.channels):
        p = csd.psd(ch)[sel]
        bands[ch] = octave_bands(f, p, factor=KEEP_FACTOR)
        psd_png[ch] = plot_psd(
            out_dir / f"psd_{_safe(ch)}.png",
            f,
            p,
            channel=ch,
            units=csd.units[i],
            dof=csd.dof,
            window=csd.window,
            nperseg=csd.nperseg,
            nfft=csd.nfft,
            title=head,
            factor=KEEP_FACTOR,
            scaling=csd.scaling,
            bands=bands[ch],
        )
    pairs = list(itertools.combinations(csd.channels, 2))
    coh = csd.coherence()
    coherence_png: dict[tuple[str, str], Path] = {}
    for a, b in pairs:
        coherence_png[(a, b)] = plot_coherence(
            out_dir / f"coherence_{_safe(a)}_{_safe(b)}.png",
            f,
            coh[sel, csd.index(a), csd.index(b)],
            pair=(a, b),
            n_segments=csd.segments_used,
            title=head,
        )
    csv = _write_csv(out_dir / "spectra.csv", csd, pairs)
    files = [*psd_png.values(), *coherence_png.values(), csv]
    log.info("%s: wrote %d file(s) to %s", path, len(files), out_dir)
    return SpectraResult(
        path=path,
        out_dir=out_dir,
        csd=csd,
        bands=bands,
        psd_png=psd_png,
        coherence_png=coherence_png,
        csv=csv,
        files=files,
    )


def default_out_dir(path: str | Path) -> Path:
    """Next to the file: ``FILE`` stem + ``_spectra``."""
    path = Path(path)
    return path.with_name(path.stem + "_spectra")
