"""The 8-channel coherence matrix: one pass of FFTs against pairwise scipy calls (issue 4).

The acceptance point: the coherence of every pair of 8 channels (8 x 300 s at 1 kHz, Hann
segments of 4096 samples, 50 % overlap, constant detrend: the analyst's everyday case) from
``daq.spectral.welch_csd_matrix`` + ``coherence`` against the 28 pairwise
``scipy.signal.coherence`` calls on the same data. Target: at least 5x faster, with equal
results.

How it is measured, all in this run:

* The data: 8 channels of Gaussian noise, the first four sharing a common component so the
  coherences span 0 .. ~1 (their agreement is then checked where it matters, not only on
  noise-level values). float64, C-contiguous, generated once.
* Both sides include everything from the raw (8, n) array to the 28 (or 8 x 8) coherences:
  segmenting, detrending, windowing, FFTs, products, averaging and the final division.
* Each side is run once to warm up (FFT plans, allocator, page faults), then timed
  ``--repeat`` times; the best and the median are reported and the ratio is taken of the
  medians (the best is printed too). Timing is wall time on however many cores numpy's FFT
  and BLAS use here (both sides alike); the CPU count and load are printed.
* Equality: the largest relative difference between each scipy pair and the matrix entry,
  over all bins and pairs, is printed (1e-13 .. 1e-11: largest at the bins where two
  independent channels happen to be least coherent, since rounding in S_ij is relative to
  sqrt(S_ii S_jj); the tests hold it below 1e-10).

Benchmarks report, they never fail: the exit code is 0 and a missed target prints a
``TARGET MISSED`` line. Usage: ``python bench/coherence_matrix.py [--quick] [--repeat N]``.
"""

from __future__ import annotations

import argparse
import itertools
import os
import statistics
import sys
import time
from collections.abc import Callable

import numpy as np
import scipy
import scipy.signal

from daq.spectral import coherence, welch_csd_matrix

N_CHANNELS = 8
FS = 1000.0
DURATION_S = 300.0
NPERSEG = 4096
NOVERLAP = NPERSEG // 2
TARGET_RATIO = 5.0
SEED = 44


def log(msg: str = "") -> None:
    print(msg, flush=True)


def make_data(duration_s: float) -> np.ndarray:
    """(8, n) noise; channels 0-3 share a common part with gains 2, 1, 0.5, 0.25."""
    rng = np.random.default_rng(SEED)
    n = round(duration_s * FS)
    x = rng.standard_normal((N_CHANNELS, n))
    common = rng.standard_normal(n)
    for ch, g in enumerate((2.0, 1.0, 0.5, 0.25)):
        x[ch] += g * common
    return x


def matrix_way(x: np.ndarray) -> np.ndarray:
    _, S = welch_csd_matrix(
        x, FS, window="hann", nperseg=NPERSEG, noverlap=NOVERLAP, detrend="constant"
    )
    return coherence(S)


def pairwise_way(x: np.ndarray) -> dict[tuple[int, int], np.ndarray]:
    out = {}
    for i, j in itertools.combinations(range(len(x)), 2):
        _, out[(i, j)] = scipy.signal.coherence(
            x[i], x[j], FS, window="hann", nperseg=NPERSEG, noverlap=NOVERLAP, detrend="constant"
        )
    return out


def timed(fn: Callable[[], object], repeat: int) -> tuple[list[float], object]:
    result = fn()  # warm-up
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return times, result


def verdict(ok: bool) -> str:
    return "met" if ok else "missed"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="60 s of data, 2 repeats")
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    duration = 60.0 if args.quick else DURATION_S
    repeat = 2 if args.quick else args.repeat
    log(
        f"coherence_matrix: numpy {np.__version__}, scipy {scipy.__version__}, {os.cpu_count()} CPUs, "
        f"load average {os.getloadavg()[0]:.2f}"
    )
    x = make_data(duration)
    n_pairs = N_CHANNELS * (N_CHANNELS - 1) // 2
    n_seg = (x.shape[1] - NOVERLAP) // (NPERSEG - NOVERLAP)
    log(
        f"  {N_CHANNELS} channels x {duration:.0f} s at {FS:.0f} Hz ({x.shape[1]} samples each), "
        f"Hann nperseg {NPERSEG}, {NOVERLAP} overlap: {n_seg} segments, {NPERSEG // 2 + 1} bins"
    )
    log(
        f"  timing the matrix (1 call) and {n_pairs} scipy.signal.coherence calls, "
        f"1 warm-up + {repeat} repeats each ..."
    )
    t_mat, C = timed(lambda: matrix_way(x), repeat)
    t_pair, pairs = timed(lambda: pairwise_way(x), repeat)

    worst, where = 0.0, None
    for (i, j), ref in pairs.items():
        rel = float(np.max(np.abs(C[:, i, j] - ref) / ref))
        if rel > worst:
            worst, where = rel, (i, j)
    hi = max(float(np.median(pairs[(0, 1)])), 0.0)

    med_mat, med_pair = statistics.median(t_mat), statistics.median(t_pair)
    ratio = med_pair / med_mat
    ok = ratio >= TARGET_RATIO
    log("")
    log("=" * 78)
    log("coherence_matrix summary (issue 4), all figures from this run")
    log("-" * 78)
    log(
        f"welch_csd_matrix + coherence   best {min(t_mat) * 1e3:8.1f} ms   median {med_mat * 1e3:8.1f} ms"
    )
    log(
        f"{n_pairs} x scipy.signal.coherence   best {min(t_pair) * 1e3:8.1f} ms   median {med_pair * 1e3:8.1f} ms "
        f"({med_pair / n_pairs * 1e3:.1f} ms per pair)"
    )
    log(
        f"max relative difference over all pairs and bins: {worst:.2e} (pair {where}); "
        f"median coherence of the coupled pair (0, 1): {hi:.3f}"
    )
    log(
        f"speed ratio (medians) {ratio:6.1f} x   (bests {min(t_pair) / min(t_mat):.1f} x)   "
        f"target >= {TARGET_RATIO:.0f}: {verdict(ok)}"
    )
    if worst > 1e-10:
        log(f"RESULTS DIFFER: max relative difference {worst:.2e} > 1e-10")
    if not ok:
        log(f"TARGET MISSED: speed ratio {ratio:.1f}x < {TARGET_RATIO:.0f}x")
    log("=" * 78)
    return 0


if __name__ == "__main__":
    sys.exit(main())
