"""Welch cross-spectral matrix of a run file, in bounded memory (thesis App. A.4).

Run files may be larger than memory (DESIGN.md section 6), so ``run_csd_matrix`` never
holds a whole channel. It walks the Welch segments of the file in order (segment k covers
samples ``k D .. k D + nperseg - 1``, ``D = nperseg - noverlap``, as ``scipy.signal``):

* reads groups of whole segments, aligned to segment starts (about ``read_bytes`` = 8 MiB
  per read, so HDF5 is called rarely; consecutive groups re-read their ``noverlap`` shared
  samples);
* transforms each group in batches of about ``batch_bytes`` (1 MiB) of segment samples
  with ``daq.spectral``'s own segmentation, detrending, window and FFT;
* skips every segment holding a lost sample (NaN, written by ``RunWriter.append_missing``;
  any non-finite value counts): a gap is never spliced over, the segments on either side
  of it are simply averaged without the ones it touches;
* accumulates the sum over segments of :math:`X_i^* X_j` (eq. 4.41) and scales it once at
  the end, exactly as ``spectra.welch_csd_matrix``.

Peak memory is one read plus a few batches (about 15 MiB with the defaults for any file
size, unless a single segment is larger). On a file without gaps the result equals
``welch_csd_matrix`` of the whole record to rounding (~1e-15 relative).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from daq.reader import LOST_SAMPLES_NOTE, RunFile, lost_text
from daq.spectral import (
    Scaling,
    _double_one_sided,
    _scale,
    _segment_ffts,
    _window_and_sizes,
    coherence,
    equivalent_dof,
    n_segments,
)

__all__ = ["RunCsd", "run_csd_matrix", "used_segments_dof"]

log = logging.getLogger(__name__)

READ_BYTES = 8 << 20
BATCH_BYTES = 1 << 20


@dataclass(frozen=True)
class RunCsd:
    """The Welch cross-spectral matrix of some channels of a run file.

    ``S[f, i, j]`` is the one-sided cross-spectrum of ``channels[i]`` and ``channels[j]``
    (``E[conj(X_i) X_j]``, ``daq.spectral``'s convention), averaged over ``segments_used``
    segments; ``used[k]`` says whether segment k was (False: it held lost samples).
    ``dof`` is the equivalent degrees of freedom of each autospectrum bin between DC and
    Nyquist (Welch's, for the segments actually used: ``used_segments_dof``).
    """

    path: Path
    channels: tuple[str, ...]
    units: tuple[str, ...]
    fs: float
    n_samples: int
    f: np.ndarray
    S: np.ndarray
    window: object
    nperseg: int
    noverlap: int
    nfft: int
    detrend: object
    scaling: str
    used: np.ndarray
    dof: float

    @property
    def segments_used(self) -> int:
        return int(self.used.sum())

    @property
    def segments_skipped(self) -> int:
        return int(self.used.size - self.used.sum())

    @property
    def segments_total(self) -> int:
        return int(self.used.size)

    @property
    def resolution_hz(self) -> float:
        """Bin spacing fs / nfft (Hz)."""
        return self.fs / self.nfft

    @property
    def segment_s(self) -> float:
        return self.nperseg / self.fs

    def index(self, channel: str) -> int:
        try:
            return self.channels.index(channel)
        except ValueError:
            raise ValueError(f"{channel!r} is not one of {', '.join(self.channels)}") from None

    def psd(self, channel: str) -> np.ndarray:
        """The autospectrum of ``channel`` (real)."""
        i = self.index(channel)
        return self.S[:, i, i].real.copy()

    def coherence(self) -> np.ndarray:
        """Magnitude-squared coherence of every pair, ``(n_freq, N, N)`` (eq. 4.44)."""
        return coherence(self.S)


def _good_segments(buf: np.ndarray, n_seg: int, step: int, nperseg: int) -> np.ndarray:
    """For segments k = 0 .. n_seg - 1 of ``buf`` (starting at k * step): no non-finite sample?"""
    bad = ~np.isfinite(buf).all(axis=0)
    if not bad.any():
        return np.ones(n_seg, dtype=bool)
    c = np.concatenate(([0], np.cumsum(bad, dtype=np.int64)))
    starts = np.arange(n_seg) * step
    return (c[starts + nperseg] - c[starts]) == 0


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of each run of consecutive True in ``mask``."""
    d = np.diff(np.concatenate(([0], mask.astype(np.int8), [0])))
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist()))


def used_segments_dof(window, nperseg: int, noverlap: int, used: np.ndarray) -> float:
    r"""Welch's equivalent degrees of freedom for an average over a subset of the segments.

    ``spectra.equivalent_dof`` is the case of K consecutive segments. With segments left
    out (lost samples), only the used pairs that overlap correlate: with :math:`c_j` the
    number of used pairs ``j`` segments apart and :math:`\rho(j)` as there,

    .. math:: \nu = \frac{2K^2}{K + 2\sum_{j \ge 1} c_j\,\rho(j)},

    which is ``equivalent_dof`` when the K used segments are consecutive (:math:`c_j = K - j`).
    """
    used = np.asarray(used, dtype=bool)
    K = int(used.sum())
    if K < 1:
        raise ValueError("no segment used")
    if used.size == K:
        return equivalent_dof(window, nperseg, noverlap, K)
    w = np.asarray(window, dtype=float)
    step = nperseg - noverlap
    ww = float(w @ w)
    acc = 0.0
    j = 1
    while j * step < nperseg and j < used.size:
        lag = j * step
        rho = (float(w[:-lag] @ w[lag:]) / ww) ** 2
        acc += int(np.count_nonzero(used[:-j] & used[j:])) * rho
        j += 1
    return 2.0 * K * K / (K + 2.0 * acc)


def run_csd_matrix(
    run: RunFile | str | Path,
    channels: Sequence[str],
    *,
    nperseg: int,
    noverlap: int | None = None,
    nfft: int | None = None,
    window="hann",
    detrend="linear",
    scaling: Scaling = "density",
    start: int = 0,
    stop: int | None = None,
    read_bytes: int = READ_BYTES,
    batch_bytes: int = BATCH_BYTES,
) -> RunCsd:
    """Welch cross-spectral matrix of ``channels`` of a run file (samples ``start .. stop``,
    default all), in bounded memory.

    The options are those of ``spectra.welch_csd_matrix`` (one-sided; ``noverlap``
    defaults to ``nperseg // 2``, ``nfft`` to ``nperseg``) except that ``detrend``
    defaults to ``'linear'`` (``spectra.psd``'s default). Segments holding a lost sample
    (NaN) are skipped and counted. ``run`` is an open ``RunFile`` or a path.

    Raises ``ValueError`` for an unknown or repeated channel, a file shorter than one
    segment, or one whose every segment holds lost samples.
    """
    if not isinstance(run, RunFile):
        with RunFile(run) as opened:
            return run_csd_matrix(
                opened,
                channels,
                nperseg=nperseg,
                noverlap=noverlap,
                nfft=nfft,
                window=window,
                detrend=detrend,
                scaling=scaling,
                start=start,
                stop=stop,
                read_bytes=read_bytes,
                batch_bytes=batch_bytes,
            )
    channels = tuple(channels)
    if not channels:
        raise ValueError("no channels given")
    missing = [c for c in channels if c not in run.channels]
    if missing:
        raise ValueError(
            f"{run.path} has no channel {', '.join(repr(c) for c in missing)} "
            f"(its channels: {', '.join(run.channels)})"
        )
    if len(set(channels)) != len(channels):
        raise ValueError(f"channels {', '.join(channels)} name one channel twice")
    if scaling not in ("density", "spectrum"):
        raise ValueError(f"scaling={scaling!r} must be 'density' or 'spectrum'")
    if detrend not in ("constant", "linear", False, None):
        raise ValueError(f"detrend={detrend!r} must be 'constant', 'linear' or False")
    fs = run.rate_hz
    start, stop = int(start), run.n_samples if stop is None else min(int(stop), run.n_samples)
    if not 0 <= start <= stop:
        raise ValueError(
            f"samples {start}..{stop} are not a span of {run.path} ({run.n_samples} samples)"
        )
    n = stop - start
    nperseg = int(nperseg)
    if nperseg < 1:
        raise ValueError(f"nperseg={nperseg} is not a positive integer")
    if n < nperseg:
        raise ValueError(
            f"{run.path} holds {n} samples ({n / fs:g} s at {fs:g} Hz), fewer than one "
            f"segment of {nperseg} ({nperseg / fs:g} s): use shorter segments"
        )
    win, nperseg, noverlap, nfft = _window_and_sizes(window, nperseg, noverlap, nfft, n)
    step = nperseg - noverlap
    n_ch = len(channels)
    K = n_segments(n, nperseg, noverlap)
    per_read = max(1, (int(read_bytes) // (8 * n_ch) - nperseg) // step + 1)
    per_batch = max(1, int(batch_bytes) // (8 * n_ch * nperseg))
    used = np.zeros(K, dtype=bool)
    acc: np.ndarray | None = None
    f = None
    for g0 in range(0, K, per_read):
        g1 = min(K, g0 + per_read)
        buf = run.read(channels, start + g0 * step, start + (g1 - 1) * step + nperseg)
        good = _good_segments(buf, g1 - g0, step, nperseg)
        used[g0:g1] = good
        for s, e in _runs(good):
            for b0 in range(s, e, per_batch):
                b1 = min(e, b0 + per_batch)
                f, X = _segment_ffts(
                    buf[:, b0 * step : (b1 - 1) * step + nperseg],
                    fs,
                    win,
                    nperseg,
                    noverlap,
                    nfft,
                    detrend,
                    "onesided",
                )
                Xf = np.ascontiguousarray(X.transpose(2, 0, 1))  # (n_freq, N, k)
                del X
                part = np.matmul(Xf.conj(), Xf.transpose(0, 2, 1))  # eq. 4.41 summed over segments
                if acc is None:
                    acc = part
                else:
                    acc += part
                del Xf, part
        del buf
    k_used = int(used.sum())
    if k_used == 0 or acc is None:
        lost = []
        for c in channels:  # where they are (the error path only: a second pass over the file)
            spans = run.lost_spans(c, start, stop)
            if spans:
                lost.append(lost_text(c, spans, fs))
        raise ValueError(
            f"every one of the {K} segments of {nperseg} samples ({nperseg / fs:g} s) in "
            f"{run.path} holds lost samples (NaN): nothing to average; try shorter segments. "
            f"{'; '.join(lost)} ({LOST_SAMPLES_NOTE})"
        )
    assert f is not None  # set together with acc
    S = acc
    S *= _scale(win, fs, scaling) / k_used
    _double_one_sided(S, nfft)
    idx = np.arange(n_ch)
    S[:, idx, idx] = S[:, idx, idx].real
    dof = used_segments_dof(win, nperseg, noverlap, used)
    if k_used < K:
        log.info("%s: %d of %d segments skipped: they hold lost samples", run.path, K - k_used, K)
    log.debug(
        "%s: Welch CSD of %s, %d segments of %d samples, EDOF %.1f",
        run.path,
        ",".join(channels),
        k_used,
        nperseg,
        dof,
    )
    return RunCsd(
        path=run.path,
        channels=channels,
        units=tuple(run.units[c] for c in channels),
        fs=fs,
        n_samples=n,
        f=f,
        S=S,
        window=window,
        nperseg=nperseg,
        noverlap=noverlap,
        nfft=nfft,
        detrend=detrend,
        scaling=scaling,
        used=used,
        dof=dof,
    )
