"""Welch cross-spectral matrix straight from a run file (thesis App. A.4; DESIGN.md section 6).

Proved here: on a gap-free file the bounded-memory walk over the file equals
``welch_csd_matrix`` of the whole record (whatever the read and batch sizes, so group
boundaries change nothing); segments touching lost samples (NaN) are skipped, counted, and
the result is the average over the remaining segments computed by hand; the EDOF accounts
for the segments left out; errors are clear; memory stays a small fraction of the file.
"""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from daq.filespectra import run_csd_matrix, used_segments_dof
from daq.reader import RunFile
from daq.runfile import RunWriter
from daq.spectral import equivalent_dof, n_segments, welch_csd_matrix

FS = 250.0
RTOL = 1e-12
EMPTY = 1e-24  # bins below this fraction of the peak hold only rounding (see test_spectra)


def _assert_close(S, ref, rtol=RTOL):
    peak = np.max(np.abs(ref))
    np.testing.assert_allclose(S, ref, rtol=rtol, atol=EMPTY * peak)


def _noise(n_ch, n, seed):
    """Correlated channels with offsets and trends (so detrending and cross-terms matter)."""
    rng = np.random.default_rng(seed)
    x = rng.standard_normal((n_ch, n)) + 0.7 * rng.standard_normal(n)
    t = np.arange(n) / n
    return x + rng.normal(0, 3, (n_ch, 1)) + rng.normal(0, 2, (n_ch, 1)) * t


def _write(path, x, names=("a", "b", "c")):
    with RunWriter(
        path,
        rig="test",
        mode=3,
        rate_hz=FS,
        channels={c: "V" for c in names[: len(x)]},
        overwrite=True,
    ) as w:
        w.append(x.T)
    return path


@pytest.fixture(scope="module")
def gap_free(tmp_path_factory):
    x = _noise(3, 50_123, seed=1)
    return _write(tmp_path_factory.mktemp("fs") / "gapfree.h5", x), x


@pytest.mark.parametrize(
    "nperseg, noverlap, detrend",
    [(1000, None, "linear"), (1024, 0, "constant"), (777, 600, False), (4096, 2048, "linear")],
)
@pytest.mark.parametrize("read_bytes, batch_bytes", [(8 << 20, 1 << 20), (100_000, 30_000), (1, 1)])
def test_gap_free_file_equals_welch_of_the_whole_record(
    gap_free, nperseg, noverlap, detrend, read_bytes, batch_bytes
):
    path, x = gap_free
    res = run_csd_matrix(
        path,
        ["a", "b", "c"],
        nperseg=nperseg,
        noverlap=noverlap,
        detrend=detrend,
        read_bytes=read_bytes,
        batch_bytes=batch_bytes,
    )
    f, S = welch_csd_matrix(x, FS, nperseg=nperseg, noverlap=noverlap, detrend=detrend)
    np.testing.assert_array_equal(res.f, f)
    _assert_close(res.S, S)
    noverlap = nperseg // 2 if noverlap is None else noverlap
    K = n_segments(x.shape[1], nperseg, noverlap)
    assert (res.segments_used, res.segments_skipped, res.segments_total) == (K, 0, K)
    assert res.dof == pytest.approx(equivalent_dof("hann", nperseg, noverlap, K), rel=1e-14)
    assert res.resolution_hz == FS / nperseg


def test_channel_order_and_subset(gap_free):
    path, x = gap_free
    res = run_csd_matrix(path, ["c", "a"], nperseg=512, read_bytes=50_000)
    _, S = welch_csd_matrix(x[[2, 0]], FS, nperseg=512, detrend="linear")
    _assert_close(res.S, S)
    assert res.channels == ("c", "a") and res.units == ("V", "V")
    np.testing.assert_array_equal(res.psd("a"), res.S[:, 1, 1].real)
    _assert_close(res.psd("a"), S[:, 1, 1].real)


def _by_hand(x, used, nperseg, step):
    """The average over the used segments of each one's own periodogram matrix."""
    parts = [
        welch_csd_matrix(
            x[:, k * step : k * step + nperseg], FS, nperseg=nperseg, detrend="linear"
        )[1]
        for k in np.flatnonzero(used)
    ]
    return np.mean(parts, axis=0)


def test_segments_touching_a_gap_are_skipped_and_the_rest_averaged(tmp_path):
    nperseg, step = 512, 256
    x1, x2 = _noise(2, 10_000, seed=2), _noise(2, 7_000, seed=3)
    gap = 300
    path = tmp_path / "gap.h5"
    with RunWriter(path, rig="test", mode=3, rate_hz=FS, channels={"a": "V", "b": "V"}) as w:
        w.append(x1.T)
        w.append_missing(gap)
        w.append(x2.T)
    full = np.concatenate([x1, np.full((2, gap), np.nan), x2], axis=1)
    n = full.shape[1]
    K = n_segments(n, nperseg, nperseg - step)
    starts = np.arange(K) * step
    expect_used = (starts + nperseg <= 10_000) | (starts >= 10_000 + gap)
    res = run_csd_matrix(path, ["a", "b"], nperseg=nperseg, read_bytes=40_000, batch_bytes=20_000)
    np.testing.assert_array_equal(res.used, expect_used)
    # a 300-sample gap touches the segments starting within 511 samples before it or inside it
    assert res.segments_skipped == int((~expect_used).sum()) == 3
    assert res.segments_used == K - 3
    assert np.all(np.isfinite(res.S))
    _assert_close(res.S, _by_hand(full, expect_used, nperseg, step), rtol=1e-11)


def test_a_nan_in_one_channel_skips_the_segments_only_if_that_channel_is_asked_for(tmp_path):
    x = _noise(2, 5_000, seed=4)
    x[1, 2_600] = np.nan  # one lost sample in b only
    path = _write(tmp_path / "nan_b.h5", x)
    both = run_csd_matrix(path, ["a", "b"], nperseg=1000)
    assert both.segments_skipped == 2  # segments starting at 2000 and 2500
    assert not both.used[4] and not both.used[5] and both.used[3] and both.used[6]
    only_a = run_csd_matrix(path, ["a"], nperseg=1000)
    assert only_a.segments_skipped == 0
    _assert_close(only_a.S, welch_csd_matrix(x[:1], FS, nperseg=1000, detrend="linear")[1])


def test_edof_of_separated_runs_of_segments():
    """Two runs of K1 and K2 consecutive segments far apart: the variances add with
    weights (K_i / K)^2, so nu = K^2 / (K1^2 / nu1 + K2^2 / nu2)."""
    nperseg, noverlap = 256, 128
    win = np.hanning(nperseg + 1)[:-1]  # scipy's periodic Hann
    used = np.zeros(40, dtype=bool)
    used[:10] = True
    used[20:35] = True
    nu1, nu2 = (
        equivalent_dof(win, nperseg, noverlap, 10),
        equivalent_dof(win, nperseg, noverlap, 15),
    )
    expect = 25**2 / (10**2 / nu1 + 15**2 / nu2)
    assert used_segments_dof(win, nperseg, noverlap, used) == pytest.approx(expect, rel=1e-12)
    # and more than one run of 25 consecutive segments would have (fewer overlapping pairs)
    assert expect > equivalent_dof(win, nperseg, noverlap, 25)


def test_errors_are_clear(tmp_path, gap_free):
    path, _ = gap_free
    with pytest.raises(ValueError, match=r"fewer than one segment of 60000"):
        run_csd_matrix(path, ["a"], nperseg=60_000)
    with pytest.raises(ValueError, match=r"no channel 'zz' \(its channels: a, b, c\)"):
        run_csd_matrix(path, ["a", "zz"], nperseg=256)
    with pytest.raises(ValueError, match="twice"):
        run_csd_matrix(path, ["a", "a"], nperseg=256)
    holes = _noise(1, 4_000, seed=5)
    holes[0, ::700] = np.nan  # every 1000-sample segment holds one
    with pytest.raises(ValueError, match="every one of the 7 segments .* lost samples"):
        run_csd_matrix(_write(tmp_path / "holes.h5", holes), ["a"], nperseg=1000)


def test_memory_stays_a_small_fraction_of_a_100_MB_file(tmp_path):
    path = tmp_path / "big.h5"
    n, rng = 6_250_000, np.random.default_rng(6)  # 2 channels x 6.25 M samples x 8 B = 100 MB
    with RunWriter(path, rig="test", mode=3, rate_hz=1000.0, channels={"a": "V", "b": "V"}) as w:
        for i in range(0, n, 1 << 20):
            w.append(rng.standard_normal((min(1 << 20, n - i), 2)))
    size = path.stat().st_size
    assert size > 100e6
    with RunFile(path) as run:
        tracemalloc.start()
        try:
            res = run_csd_matrix(run, ["a", "b"], nperseg=4096)
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
    assert res.segments_used == n_segments(n, 4096, 2048)
    assert np.median(res.psd("a")[1:-1]) == pytest.approx(2 / 1000.0, rel=0.02)  # unit white noise
    assert peak < 0.25 * size, f"peak {peak / 1e6:.1f} MB for a {size / 1e6:.0f} MB file"


def test_a_span_of_the_file_gives_the_welch_matrix_of_that_slice(tmp_path):
    """start/stop: a procedure's record is one span of a file that also holds its setup."""
    rng = np.random.default_rng(3)
    x = rng.standard_normal((2, 5000))
    x[1] += 0.5 * x[0]
    path = tmp_path / "r.h5"
    with RunWriter(path, rig="test", mode=3, rate_hz=100.0, channels={"a": "V", "b": "V"}) as w:
        w.append({"a": x[0], "b": x[1]})
    with RunFile(path) as rf:
        got = run_csd_matrix(rf, ["a", "b"], nperseg=256, start=1234, stop=4321)
    f, S = welch_csd_matrix(x[:, 1234:4321], 100.0, nperseg=256, detrend="linear")
    np.testing.assert_allclose(got.f, f)
    np.testing.assert_allclose(got.S, S, rtol=1e-10, atol=1e-14)
