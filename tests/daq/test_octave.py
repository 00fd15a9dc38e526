"""Octave-band display of spectra (Klinger 1974, App. A.8).

Proved here: bands start at the first non-zero bin and double in width (bins 1, 2-3, 4-7,
... on a uniform grid, DC in none); each band's average is the plain mean of its bins; a
single-bin spectral line that the band average would swallow survives as a kept point,
and exactly the points above factor x their band's average are kept; the EDOF of a band
average matches a Monte Carlo of Welch estimates (Hann bins are correlated, boxcar's not).
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal
from hypothesis import given, settings
from hypothesis import strategies as st

from daq.octave import EDGE_RTOL, band_average_dof, octave_bands
from daq.spectral import equivalent_dof


def _reference_bands(n_bins: int) -> dict[int, list[int]]:
    """Bin indices n = 1 .. n_bins - 1 grouped by band, in integers: band = floor(log2 n)."""
    out: dict[int, list[int]] = {}
    for n in range(1, n_bins):
        out.setdefault(n.bit_length() - 1, []).append(n)
    return out


def test_a_single_bin_line_survives_the_band_average():
    df = 0.05
    f = np.arange(1025) * df
    rng = np.random.default_rng(3)
    p = rng.uniform(0.8, 1.2, f.size)
    p[300] = 50.0  # a line in band 8 (bins 256..511)
    b = octave_bands(f, p)
    band = 8
    assert b.band_index[300] == band
    avg = np.mean(p[256:512])
    assert b.average[band] == pytest.approx(avg, rel=1e-12)
    assert avg < 1.5  # the average alone would hide the line...
    np.testing.assert_array_equal(b.kept_f, [f[300]])  # ...the kept point shows it
    np.testing.assert_array_equal(b.kept_p, [50.0])
    np.testing.assert_array_equal(b.kept_band, [band])


def test_bands_double_and_averages_are_the_mean_of_their_bins():
    df = 0.1220703125
    n_bins = 1000  # last band partial: bins 512..999
    f = np.arange(n_bins) * df
    rng = np.random.default_rng(0)
    p = rng.exponential(1.0, n_bins) / np.maximum(f, df)
    p[0] = 1e9  # DC: in no band, so it changes nothing
    b = octave_bands(f, p)
    ref = _reference_bands(n_bins)
    assert b.n_bands == len(ref) == 10
    assert b.f1 == df and b.f_lo[0] == df
    np.testing.assert_allclose(b.f_hi, 2 * b.f_lo, rtol=0)
    np.testing.assert_allclose(b.f_lo[1:], b.f_hi[:-1], rtol=0)
    np.testing.assert_allclose(b.f_hi - b.f_lo, df * 2.0 ** np.arange(10), rtol=1e-15)
    assert b.band_index[0] == -1
    for k, bins in ref.items():
        assert b.count[k] == len(bins)
        assert b.average[k] == pytest.approx(np.mean(p[bins]), rel=1e-12)
        assert b.f_center[k] == pytest.approx(np.mean(f[bins]), rel=1e-12)
    assert list(b.count[:9]) == [1, 2, 4, 8, 16, 32, 64, 128, 256] and b.count[9] == 488


def test_factor_is_configurable_and_nan_is_never_kept():
    f = np.arange(64) * 1.0
    p = np.ones(64)
    p[40] = 2.5  # band 5: bins 32..63
    p[50] = np.nan
    assert octave_bands(f, p).kept_f.size == 0  # 2.5 < 3 x ~1.05
    b = octave_bands(f, p, factor=2.0)
    np.testing.assert_array_equal(b.kept_f, [40.0])
    assert b.count[5] == 32 and b.average[5] == pytest.approx((31 + 1.5) / 31)


def test_bad_input_is_refused():
    with pytest.raises(ValueError, match="1-D"):
        octave_bands(np.arange(4.0), np.ones(5))
    with pytest.raises(ValueError, match="no positive frequency"):
        octave_bands(np.zeros(3), np.ones(3))
    with pytest.raises(ValueError, match="factor"):
        octave_bands(np.arange(4.0), np.ones(4), factor=0)


@settings(max_examples=150, deadline=None)
@given(
    n_bins=st.integers(2, 5000),
    df=st.floats(1e-4, 1e4),
    seed=st.integers(0, 2**32 - 1),
    factor=st.floats(1.1, 20.0),
    rfft_grid=st.booleans(),
)
def test_property_every_bin_in_one_band_and_kept_points_exceed(n_bins, df, seed, factor, rfft_grid):
    rng = np.random.default_rng(seed)
    if rfft_grid:  # the grid as the estimators make it
        nfft = 2 * (n_bins - 1)
        f = np.fft.rfftfreq(nfft, 1.0 / (df * nfft))
    else:
        f = np.arange(n_bins) * df
    p = rng.lognormal(0.0, 2.0, n_bins)
    b = octave_bands(f, p, factor=factor)
    idx = b.band_index
    assert idx[0] == -1 and np.all(idx[1:] >= 0) and np.all(idx[1:] < b.n_bands)
    # the band of bin n is floor(log2 n), whatever rounding the grid has
    np.testing.assert_array_equal(idx[1:], [n.bit_length() - 1 for n in range(1, n_bins)])
    assert b.count.sum() == n_bins - 1 and np.all(b.count > 0)
    for k in range(b.n_bands):
        members = p[idx == k]
        assert b.average[k] == pytest.approx(members.mean(), rel=1e-9)
    above = np.zeros(n_bins, dtype=bool)
    above[1:] = p[1:] > factor * b.average[idx[1:]]
    np.testing.assert_array_equal(b.kept_f, f[above])  # all of them, and only them
    assert np.all(b.kept_p > factor * b.average[b.kept_band])


@settings(max_examples=100, deadline=None)
@given(f=st.lists(st.floats(1e-3, 1e6), min_size=1, max_size=300), seed=st.integers(0, 1000))
def test_property_irregular_grid_bins_fall_inside_their_band(f, seed):
    f = np.asarray(f)
    p = np.random.default_rng(seed).uniform(0, 1, f.size)
    b = octave_bands(f, p)
    idx = b.band_index
    assert np.all(idx >= 0)
    lo, hi = b.f_lo[idx] * (1 - EDGE_RTOL), b.f_hi[idx] * (1 - EDGE_RTOL)
    assert np.all((lo <= f) & (f < hi))
    assert b.count.sum() == f.size


def test_band_average_dof_closed_forms():
    # boxcar without zero padding: bins independent, the mean of m has m times the EDOF
    np.testing.assert_allclose(
        band_average_dof(10.0, [1, 7, 1000], window="boxcar", nperseg=2048),
        [10.0, 70.0, 10000.0],
        rtol=1e-9,
    )
    # Hann: rho(1) = (2/3)^2 = 4/9, rho(2) = (1/6)^2 = 1/36, zero beyond
    m = 1000
    denom = m + 2 * ((m - 1) * 4 / 9 + (m - 2) / 36)
    assert band_average_dof(10.0, m, window="hann", nperseg=4096) == pytest.approx(
        10 * m * m / denom, rel=1e-9
    )
    assert band_average_dof(10.0, 1, window="hann", nperseg=512) == pytest.approx(10.0)
    with pytest.raises(ValueError, match="does not fit"):
        band_average_dof(10.0, 300, window="hann", nperseg=512)


def test_band_average_dof_matches_a_monte_carlo_of_welch_band_means():
    rng = np.random.default_rng(7)
    nperseg, K, m, trials = 256, 4, 32, 2000
    n = nperseg * (K + 1) // 2
    x = rng.standard_normal((trials, n))
    _, p = scipy.signal.welch(x, 1.0, "hann", nperseg, detrend=False)
    means = p[:, 40 : 40 + m].mean(axis=1)  # a band well inside 0 .. Nyquist
    nu_mc = 2 * means.mean() ** 2 / means.var()
    nu_bin = equivalent_dof("hann", nperseg, nperseg // 2, K)
    nu = band_average_dof(nu_bin, m, window="hann", nperseg=nperseg)
    assert nu_mc == pytest.approx(nu, rel=0.1)
    assert nu_mc < 0.7 * nu_bin * m  # the correlation matters (m x nu_bin is wrong)
