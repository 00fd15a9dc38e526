"""The spectral toolkit (issue 4, point 4; Klinger 1974 Ch. IV D-I, App. A).

Proved here: the Welch PSD and the N x N cross-spectral matrix equal scipy.signal's welch /
csd / coherence in every supported option; the thesis's coherence illustration (Ch. IV I)
comes out as it did; chi-square intervals from Welch's equivalent degrees of freedom cover
the true PSD at their stated rate (and a wrong DOF visibly does not); H1 recovers a known
filter's gain and phase; the quantization floor is q^2 dt / 12 (App. A.7).
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
import scipy.signal
import scipy.stats
from hypothesis import example, given, settings
from hypothesis import strategies as st

from daq.spectral import (
    coherence,
    coherence_pair,
    equivalent_dof,
    gain,
    n_segments,
    phase_deg,
    psd,
    psd_confidence,
    quantization_floor,
    transfer_h1,
    welch_csd_matrix,
)

RTOL = 1e-10
#: Bins whose reference autospectrum is below this fraction of its peak hold nothing but
#: rounding (a boxcar window after detrending leaves exactly nothing at DC: ~1e-30 of the
#: peak); there both implementations return rounding noise, compared absolutely at this
#: fraction of the peak. Every bin above it (amplitudes above 1e-12 of the peak's) is
#: compared at RTOL.
EMPTY = 1e-24
WINDOWS = ["hann", "hamming", "boxcar", "blackman"]
DETRENDS = ["constant", "linear", False]


def _noise(n_channels, n, seed=0, common=0.7):
    """Channels of noise sharing a common part (so cross-spectra are not all noise), each
    with its own offset and trend (so detrending matters)."""
    rng = np.random.default_rng(seed)
    x = rng.standard_normal((n_channels, n)) + common * rng.standard_normal(n)
    t = np.arange(n) / n
    return x + rng.normal(0, 3, (n_channels, 1)) + rng.normal(0, 2, (n_channels, 1)) * t


def _noverlap(kind, nperseg):
    return {"zero": 0, "default": None, "three_quarters": (3 * nperseg) // 4}[kind]


def _assert_close(S, ref, rtol=RTOL):
    """Elementwise relative agreement at ``rtol``; rounding-level bins absolutely (EMPTY)."""
    S, ref = np.asarray(S), np.asarray(ref)
    assert S.shape == ref.shape
    peak = np.max(np.abs(ref))
    np.testing.assert_allclose(S, ref, rtol=rtol, atol=EMPTY * peak)


def _scipy_matrix(x, fs, sides, **kw):
    """scipy.signal.csd of every ordered pair, (n_freq, N, N): csd broadcasts rows i x j."""
    f, R = scipy.signal.csd(
        x[:, None, :], x[None, :, :], fs, return_onesided=sides == "onesided", **kw
    )
    return f, np.moveaxis(R, -1, 0)


# ============================================================================ B: equal to scipy
@pytest.mark.parametrize("nperseg", [128, 127])
@pytest.mark.parametrize("detrend", DETRENDS)
@pytest.mark.parametrize("sides", ["onesided", "twosided"])
@pytest.mark.parametrize("scaling", ["density", "spectrum"])
@pytest.mark.parametrize("overlap", ["zero", "default", "three_quarters"])
@pytest.mark.parametrize("window", WINDOWS)
def test_psd_equals_scipy_welch(window, overlap, scaling, sides, detrend, nperseg):
    """psd (1-D and row-wise 2-D) equals scipy.signal.welch, frequencies exactly, values to
    1e-10 relative, for even and odd segments (the Nyquist bin is doubled only for odd)."""
    x = _noise(2, 1500, seed=nperseg)
    kw = dict(
        window=window,
        nperseg=nperseg,
        noverlap=_noverlap(overlap, nperseg),
        detrend=detrend,
        scaling=scaling,
    )
    f_ref, p_ref = scipy.signal.welch(x, 50.0, return_onesided=sides == "onesided", **kw)
    f, p = psd(x, 50.0, sides=sides, **kw)
    np.testing.assert_array_equal(f, f_ref)
    _assert_close(p, p_ref)
    f1, p1 = psd(x[1], 50.0, sides=sides, **kw)
    np.testing.assert_array_equal(f1, f_ref)
    _assert_close(p1, p_ref[1])


@settings(max_examples=25, deadline=None)
@given(
    window=st.sampled_from(WINDOWS),
    detrend=st.sampled_from(DETRENDS),
    scaling=st.sampled_from(["density", "spectrum"]),
    sides=st.sampled_from(["onesided", "twosided"]),
    nperseg=st.integers(8, 160),
    overlap_frac=st.floats(0.0, 0.95),
    n_extra=st.integers(0, 400),
    pad=st.sampled_from([0, 0, 1, 37]),
    seed=st.integers(0, 2**31),
)
# rounding at the channels' scale (CROSS): a cross term cancelled to 2e-6 of it, a DC bin left at 1e-11
@example(
    window="hann",
    detrend="linear",
    scaling="spectrum",
    sides="onesided",
    nperseg=93,
    overlap_frac=0.609375,
    n_extra=357,
    pad=0,
    seed=7772727,
)
@example(
    window="blackman",
    detrend="constant",
    scaling="density",
    sides="onesided",
    nperseg=8,
    overlap_frac=0.0,
    n_extra=4,
    pad=1,
    seed=134217729,
)
def _matrix_case(
    n_channels, window, detrend, scaling, sides, nperseg, overlap_frac, n_extra, pad, seed
):
    x = _noise(n_channels, nperseg + n_extra, seed=seed)
    kw = dict(
        window=window,
        nperseg=nperseg,
        noverlap=min(nperseg - 1, int(overlap_frac * nperseg)),
        nfft=nperseg + pad,
        detrend=detrend,
        scaling=scaling,
    )
    f_ref, R = _scipy_matrix(x, 20.0, sides, **kw)
    f, S = welch_csd_matrix(x, 20.0, sides=sides, **kw)
    np.testing.assert_array_equal(f, f_ref)
    assert S.shape == (len(f), n_channels, n_channels)
    _assert_matrix_close(S, R)


@pytest.mark.parametrize("n_channels", range(1, 9))
def test_csd_matrix_equals_scipy_csd_for_every_pair(n_channels):
    """S[:, i, j] equals scipy.signal.csd(x[i], x[j]) (X_i^* X_j, eq. 4.41) for N = 1..8
    channels over random segment lengths, overlaps, zero padding, windows, detrending,
    scaling and sides."""
    _matrix_case(n_channels)


def test_csd_matrix_entries_equal_separate_scipy_calls():
    """The broadcast reference above is scipy's csd pair by pair: check one case explicitly,
    with the diagonal also against welch and coherence_pair against scipy's coherence."""
    x = _noise(3, 2000, seed=3)
    kw = dict(window="hamming", nperseg=200, noverlap=50, detrend="linear")
    f, S = welch_csd_matrix(x, 100.0, **kw)
    for i, j in itertools.product(range(3), repeat=2):
        fr, r = scipy.signal.csd(x[i], x[j], 100.0, **kw)
        np.testing.assert_array_equal(f, fr)
        _assert_close(S[:, i, j], r)
    for i in range(3):
        _assert_close(S[:, i, i].real, scipy.signal.welch(x[i], 100.0, **kw)[1])
        assert np.all(S[:, i, i].imag == 0.0)
    fc, c = coherence_pair(x[0], x[2], 100.0, **kw)
    fr, cr = scipy.signal.coherence(x[0], x[2], 100.0, **kw)
    np.testing.assert_array_equal(fc, fr)
    _assert_close(c, cr)


#: a bin's rounding is set by its channels' power, not by its own size: a cross term cancelled to
#: 2e-6 of sqrt(S_ii S_jj) (1.9e-10 relative to itself, once in ~10^4 hypothesis cases), or a
#: DC bin a constant detrend left at 1e-11 of the peak, keeps the absolute error of the
#: channels' scale. Measured worst: 5.9e-18 against a scale of 1.7e-2, 1.6 eps
CROSS = 1e-13


def _assert_matrix_close(S, ref, rtol=RTOL):
    """A (f, N, N) matrix against ``ref``: each entry at ``rtol`` of itself, or within CROSS of
    sqrt(P_i P_j), P_i the peak of channel i's autospectrum over frequency."""
    S, ref = np.asarray(S), np.asarray(ref)
    assert S.shape == ref.shape
    peak = np.max(np.abs(np.einsum("fii->fi", ref)), axis=0)
    tol = rtol * np.abs(ref) + CROSS * np.sqrt(peak[:, None] * peak[None, :])[None, :, :]
    bad = np.abs(S - ref) > tol
    assert not bad.any(), (
        f"{int(bad.sum())} entries differ beyond tolerance; worst excess "
        f"{float(np.max((np.abs(S - ref) - tol)[bad])):.3g} at {np.argwhere(bad)[:5].tolist()}"
    )


def test_complex_data_two_sided_equals_scipy():
    """Complex channels (two-sided only) equal scipy's csd; one-sided is refused."""
    rng = np.random.default_rng(9)
    z = rng.standard_normal((3, 900)) + 1j * rng.standard_normal((3, 900))
    f_ref, R = _scipy_matrix(z, 1.0, "twosided", nperseg=64)
    f, S = welch_csd_matrix(z, 1.0, nperseg=64, sides="twosided")
    np.testing.assert_array_equal(f, f_ref)
    _assert_matrix_close(S, R)
    with pytest.raises(ValueError, match="one-sided"):
        welch_csd_matrix(z, 1.0, nperseg=64)


@pytest.mark.parametrize("detrend", DETRENDS)
@pytest.mark.parametrize("overlap", ["zero", "default", "three_quarters"])
@pytest.mark.parametrize("window", WINDOWS)
def test_coherence_matrix_equals_scipy_coherence(window, overlap, detrend):
    """coherence(S) equals scipy.signal.coherence for all 6 pairs of 4 channels (eq. 4.49),
    is 1 on the diagonal and lies in [0, 1]."""
    x = _noise(4, 2000, seed=11)
    kw = dict(window=window, nperseg=256, noverlap=_noverlap(overlap, 256), detrend=detrend)
    f, S = welch_csd_matrix(x, 200.0, **kw)
    C = coherence(S)
    auto = np.real(np.diagonal(S, axis1=1, axis2=2))
    live = np.all(auto > EMPTY * auto.max(axis=0), axis=1)  # bins not emptied by detrending
    for i, j in itertools.combinations(range(4), 2):
        fr, cr = scipy.signal.coherence(x[i], x[j], 200.0, **kw)
        np.testing.assert_array_equal(f, fr)
        np.testing.assert_allclose(C[live, i, j], cr[live], rtol=RTOL)
        np.testing.assert_allclose(C[live, j, i], cr[live], rtol=RTOL)
    np.testing.assert_allclose(np.diagonal(C[live], axis1=1, axis2=2), 1.0, rtol=1e-12)
    assert np.all((C[live] >= 0) & (C[live] <= 1 + 1e-12))


def test_each_matrix_is_hermitian_and_positive_semidefinite():
    """S(f) = (c/K) X^* X^T is a Gram matrix: Hermitian, eigenvalues >= 0 (so |S_ij|^2 <=
    S_ii S_jj, the bound 0 <= gamma^2 <= 1 under eq. 4.44)."""
    x = _noise(8, 4000, seed=5)
    _, S = welch_csd_matrix(x, 1.0, nperseg=128)
    np.testing.assert_allclose(
        S, np.conj(np.swapaxes(S, 1, 2)), rtol=0, atol=1e-14 * np.abs(S).max()
    )
    ev = np.linalg.eigvalsh(S)
    assert ev.min() >= -1e-12 * ev.max()


def test_one_segment_gives_coherence_one():
    """Eq. 4.50: from a single record the coherence estimate is identically 1, whatever
    the data; averaging is what makes it informative."""
    x = _noise(3, 512, seed=2, common=0.0)
    _, S = welch_csd_matrix(x, 1.0, nperseg=512)
    np.testing.assert_allclose(coherence(S)[1:-1], 1.0, rtol=1e-9)


@pytest.mark.parametrize("n", [1000, 1001])
def test_one_sided_density_integrates_to_the_mean_square(n):
    """Parseval with the one-sided doubling (eq. 4.15): for one boxcar segment without
    detrending, the one-sided density summed times df is the mean square exactly, for even
    and odd lengths (the Nyquist bin is not doubled); the two-sided density likewise."""
    x = np.random.default_rng(n).standard_normal(n) + 0.3
    for sides in ("onesided", "twosided"):
        _, p = psd(x, 10.0, window="boxcar", nperseg=n, detrend=False, sides=sides)
        assert p.sum() * 10.0 / n == pytest.approx(np.mean(x * x), rel=1e-12)


def test_psd_defaults_are_the_projects_previous_ones():
    """psd(x, fs[, seg_s]) is unchanged for its callers: Hann segments of seg_s seconds (cut
    to the record), half overlap, linear detrend, one-sided density."""
    x = np.random.default_rng(1).standard_normal(30_000)
    for seg_s, nperseg in ((8.0, 8000), (4.0, 4000), (60.0, 30_000)):
        f, p = psd(x, 1000.0, seg_s)
        fr, pr = scipy.signal.welch(x, 1000.0, window="hann", nperseg=nperseg, detrend="linear")
        np.testing.assert_array_equal(f, fr)
        _assert_close(p, pr)


# ============================================================================ C: thesis Ch. IV I
def test_thesis_illustration_coherence_of_a_common_sinusoid():
    """Ch. IV I (Figs. 30-31): y_k = sin(2 pi 10 t) + n_k, n_1 and n_2 independent white
    noises of variance 51.2 sampled at 51.2 Hz (two-sided PSD 1 up to 25.6 Hz), forty 10 s
    records (df = 0.1 Hz) averaged, Hann windowed (App. A.2). The thesis found the coherence
    0.35 at 10 Hz and near zero elsewhere; the cross-spectrum level of the noise attenuated
    by an average factor 6.3 against the power spectra (Fig. 31d).

    For a Hann window the sinusoid's one-sided density at its bin is (1/2) / (1.5 df) =
    3.33 over a noise density of 2, so the expected coherence is (3.33 / 5.33)^2 = 0.39;
    the noise bins' coherence is Beta(1, 39) distributed (mean 1/40). The line must stand
    above every bin outside its main lobe (its two neighbours carry Hann leakage of the same
    sinusoid; DC and Nyquist rest on real-valued terms only and are left out too).
    """
    fs, rec = 51.2, 512
    t = np.arange(40 * rec) / fs
    rng = np.random.default_rng(1974)
    y = np.sin(2 * np.pi * 10.0 * t) + math.sqrt(51.2) * rng.standard_normal((2, t.size))
    f, S = welch_csd_matrix(y, fs, window="hann", nperseg=rec, noverlap=0)
    assert f[1] == pytest.approx(0.1)
    C = coherence(S)[:, 0, 1]
    k = int(np.argmin(np.abs(f - 10.0)))
    assert f[k] == pytest.approx(10.0)
    others = np.ones(len(f), bool)
    others[[0, -1, k - 1, k, k + 1]] = False

    assert 0.25 < C[k] < 0.6  # the thesis: 0.35; expected ~0.39
    assert C[k] > 1.3 * C[others].max()  # clearly above every other bin
    assert np.median(C[others]) < 0.04  # "near zero elsewhere" (Beta(1,39) median 0.018)
    # Fig. 31d: the noise in the cross-spectrum is attenuated ~6.3x (E|gamma| ~ 0.14 for K = 40).
    cross = np.abs(S[others, 0, 1])
    auto = np.sqrt(S[others, 0, 0].real * S[others, 1, 1].real)
    assert 5.0 < auto.mean() / cross.mean() < 9.0
    # The PSDs: the line's bin stands out (Figs. 31b, c), the noise floor is the one-sided 2.
    assert np.mean(S[others, 0, 0].real) == pytest.approx(2.0, rel=0.05)


# ============================================================================ D: confidence
def _ar1(n_records, n, a, fs, seed):
    """AR(1) records x[k] = a x[k-1] + e[k], e ~ N(0, 1), stationary (burn-in dropped), and
    the true one-sided PSD 2 dt / |1 - a exp(-j 2 pi f dt)|^2."""
    burn = 300
    e = np.random.default_rng(seed).standard_normal((n_records, n + burn))
    x = scipy.signal.lfilter([1.0], [1.0, -a], e, axis=-1)[:, burn:]

    def true(f):
        return 2.0 / fs / np.abs(1.0 - a * np.exp(-2j * np.pi * f / fs)) ** 2

    return x, true


def _coverage(P, true_p, dof, level=0.95):
    lo, hi = psd_confidence(P, dof, level)
    return float(np.mean((lo <= true_p) & (true_p <= hi)))


@pytest.mark.parametrize(
    "window,nperseg,noverlap", [("hann", 64, 32), ("hann", 64, 48), ("boxcar", 64, 0)]
)
def test_confidence_intervals_cover_the_true_psd_at_their_rate(window, nperseg, noverlap):
    """Over 2000 independent AR(1) records (a = 0.6: 12 dB of colour) and ten bins each, the
    95 % chi-square intervals with Welch's EDOF contain the analytic PSD in a fraction of the
    20000 trials within the binomial 99.99 % band around 0.95. Bins are 3 apart (for Hann,
    periodogram values 3 bins apart are uncorrelated, so the trials are independent) and
    away from DC and Nyquist (fewer degrees of freedom there).

    The test can fail: the same intervals with the DOF doubled (too narrow) or halved (too
    wide) fall far outside the band.
    """
    fs, K, R = 100.0, 12, 2000
    n = nperseg + (nperseg - noverlap) * (K - 1)
    x, true = _ar1(R, n, 0.6, fs, seed=nperseg + noverlap)
    f, P = psd(x, fs, window=window, nperseg=nperseg, noverlap=noverlap, detrend=False)
    assert n_segments(n, nperseg, noverlap) == K
    sel = np.arange(2, len(f) - 2, 3)
    Psel, tsel = P[:, sel], true(f[sel])
    dof = equivalent_dof(window, nperseg, noverlap, K)

    trials = Psel.size
    lo_n, hi_n = scipy.stats.binom.interval(0.9999, trials, 0.95)
    band = (lo_n / trials, hi_n / trials)
    cov = _coverage(Psel, tsel, dof)
    assert band[0] <= cov <= band[1], (cov, band, dof)
    assert _coverage(Psel, tsel, 2 * dof) < band[0] - 0.05  # doubled DOF: ~0.83
    assert _coverage(Psel, tsel, dof / 2) > band[1] + 0.02  # halved DOF: ~0.99


def test_equivalent_dof_matches_the_spread_of_overlapped_estimates():
    """Welch's EDOF is what the estimates show: 2 E^2 / Var of P/P_true over 4000 records
    agrees with the formula to sampling error (~3 %). At 75 % Hann overlap that is far from
    the naive 2K (13.0 against 24): overlapped segments are not independent."""
    fs, L, D, K = 100.0, 64, 16, 12
    n = L + D * (K - 1)
    x, true = _ar1(4000, n, 0.6, fs, seed=3)
    f, P = psd(x, fs, nperseg=L, noverlap=L - D, detrend=False)
    r = (P / true(f))[:, np.arange(2, len(f) - 2, 3)]
    empirical = 2 * r.mean() ** 2 / r.var()
    nu = equivalent_dof("hann", L, L - D, K)
    assert nu == pytest.approx(13.02, abs=0.01)
    assert empirical == pytest.approx(nu, rel=0.06)
    assert abs(empirical - 2 * K) > 0.3 * empirical


@pytest.mark.parametrize("window", WINDOWS)
@pytest.mark.parametrize("K", [1, 2, 7, 40])
def test_equivalent_dof_without_overlap_is_2K(window, K):
    """Non-overlapping segments are independent: k = 2M (App. A.4), for every window."""
    assert equivalent_dof(window, 128, 0, K) == 2 * K


@pytest.mark.parametrize("K", [2, 5, 100])
def test_equivalent_dof_hann_half_overlap_closed_form(K):
    """Periodic Hann at 50 %: the halves correlate by sum sin^2 cos^2 / sum sin^4 = 1/6, so
    rho(1) = 1/36 and nu = 2K / (1 + (1 - 1/K) / 18); an array window gives the same."""
    expected = 2 * K / (1 + (1 - 1 / K) / 18)
    assert equivalent_dof("hann", 256, 128, K) == pytest.approx(expected, rel=1e-12)
    w = scipy.signal.get_window("hann", 256)
    assert equivalent_dof(w, 256, 128, K) == pytest.approx(expected, rel=1e-12)


@settings(max_examples=50, deadline=None)
@given(dof=st.floats(1.0, 500.0), level=st.floats(0.5, 0.999), p=st.floats(1e-12, 1e6))
def test_confidence_interval_is_the_chi_square_quantiles(dof, level, p):
    """lower = nu P / chi2(1 - a/2), upper = nu P / chi2(a/2): brackets P, and the chance
    that chi2_nu / nu puts P inside is ``level`` exactly."""
    lo, hi = psd_confidence(p, dof, level)
    assert lo < p < hi
    a = 1 - level
    assert lo == pytest.approx(dof * p / scipy.stats.chi2.ppf(1 - a / 2, dof), rel=1e-12)
    # P_hat = P_true chi2/nu lies in [lo, hi] around P_true iff chi2 in [q(a/2), q(1-a/2)]
    q = scipy.stats.chi2.cdf(dof * p / lo, dof) - scipy.stats.chi2.cdf(dof * p / hi, dof)
    assert q == pytest.approx(level, rel=1e-9)


# ============================================================================ H1
def test_h1_recovers_gain_and_phase_of_a_known_filter():
    """y = h * x + output noise, h a 2nd-order Butterworth (10 Hz at 100 Hz) behind a
    3-sample delay: where the coherence exceeds 0.99, |H1| is within 3 % of |H(f)| and its
    phase within 2 deg, the delay's -3 * 360 f / fs included (so the sign convention
    S_xy = E[X^* Y] gives angle H, eq. 4.38). Where output noise lowers the coherence to
    0.3-0.7, H1 stays unbiased, while sqrt(S_yy / S_xx) (eq. 4.40) reads high by about
    1 / gamma (the thesis's remark after eq. 4.48)."""
    fs, n = 100.0, 30_000
    rng = np.random.default_rng(3)
    b, a = scipy.signal.butter(2, 10.0, fs=fs)
    b = np.concatenate([np.zeros(3), b])
    x = rng.standard_normal(n)
    y = scipy.signal.lfilter(b, a, x) + 0.02 * rng.standard_normal(n)
    f, S = welch_csd_matrix(np.stack([x, y]), fs, nperseg=256)
    H = transfer_h1(S, 0, 1)
    C = coherence(S)[:, 0, 1]
    _, Ht = scipy.signal.freqz(b, a, worN=f, fs=fs)

    high = C > 0.99
    assert high.sum() > 30 and f[high].max() > 15.0
    np.testing.assert_allclose(gain(H[high]), np.abs(Ht[high]), rtol=0.03)
    dphase = (phase_deg(H[high]) - np.degrees(np.angle(Ht[high])) + 180.0) % 360.0 - 180.0
    assert np.abs(dphase).max() < 2.0
    assert phase_deg(H[high], unwrap=True)[-1] < -180.0  # past -180: unwrapped

    mid = (C > 0.3) & (C < 0.7)
    assert mid.sum() >= 5
    assert np.mean(gain(H[mid]) / np.abs(Ht[mid])) == pytest.approx(1.0, abs=0.05)
    ratio_est = np.sqrt(S[mid, 1, 1].real / S[mid, 0, 0].real) / np.abs(Ht[mid])
    assert np.mean(ratio_est) == pytest.approx(np.mean(1 / np.sqrt(C[mid])), rel=0.05)
    assert np.mean(ratio_est) > 1.25


def test_h1_for_several_outputs_at_once():
    """transfer_h1 with a list of outputs gives one column per output, equal to the single
    calls; the input against itself is exactly 1."""
    x = _noise(4, 3000, seed=8)
    _, S = welch_csd_matrix(x, 1.0, nperseg=128)
    H = transfer_h1(S, 1, [0, 2, 3])
    assert H.shape == (S.shape[0], 3)
    for col, j in enumerate([0, 2, 3]):
        np.testing.assert_array_equal(H[:, col], transfer_h1(S, 1, j))
    np.testing.assert_allclose(transfer_h1(S, 2, 2), 1.0, rtol=1e-15)


# ============================================================================ quantization
def test_quantization_floor_value():
    """App. A.7: q = 2 range / 2^bits, two-sided P = q^2 dt / 12; one-sided twice that."""
    q = 20.0 / 65536
    assert quantization_floor(10.0, 16, 1000.0, "twosided") == pytest.approx(
        q * q / 12 / 1000.0, rel=1e-15
    )
    assert quantization_floor(10.0, 16, 1000.0) == pytest.approx(q * q / 6 / 1000.0, rel=1e-15)
    # 16 bits on +-10 V at 1 kHz: 0.305 mV steps, 3.94 uV/sqrt(Hz) one-sided
    assert math.sqrt(quantization_floor(10.0, 16, 1000.0)) == pytest.approx(3.94e-6, rel=1e-3)


def test_quantization_floor_is_the_psd_of_roundoff():
    """Widrow's model (App. A.7): rounding a busy signal to a 12-bit, +-10 V grid adds white
    noise whose one-sided Welch PSD sits on quantization_floor (mean over bins within 2 %),
    and whose variance is q^2 / 12."""
    fs, bits, rng_V = 1000.0, 12, 10.0
    q = 2 * rng_V / 2**bits
    v = np.random.default_rng(12).normal(0.0, 2.0, 200_000)
    err = np.round(v / q) * q - v
    assert np.var(err) == pytest.approx(q * q / 12, rel=0.01)
    _, p = psd(err, fs, nperseg=1000, detrend=False)
    assert np.mean(p[1:-1]) == pytest.approx(quantization_floor(rng_V, bits, fs), rel=0.02)
    _, p2 = psd(err, fs, nperseg=1000, detrend=False, sides="twosided")
    assert np.mean(p2) == pytest.approx(quantization_floor(rng_V, bits, fs, "twosided"), rel=0.02)


# ============================================================================ argument checks
def test_bad_arguments_are_refused():
    x = np.zeros((2, 100))
    with pytest.raises(ValueError, match="noverlap"):
        welch_csd_matrix(x, 1.0, nperseg=32, noverlap=32)
    with pytest.raises(ValueError, match="nfft"):
        welch_csd_matrix(x, 1.0, nperseg=32, nfft=16)
    with pytest.raises(ValueError, match="detrend"):
        welch_csd_matrix(x, 1.0, nperseg=32, detrend="quadratic")
    with pytest.raises(ValueError, match="scaling"):
        welch_csd_matrix(x, 1.0, nperseg=32, scaling="power")
    with pytest.raises(ValueError, match="window"):
        welch_csd_matrix(x, 1.0, window=np.ones(200))
    with pytest.raises(ValueError, match="n_channels, n_samples"):
        welch_csd_matrix(np.zeros((2, 2, 100)), 1.0)
    with pytest.warns(UserWarning, match="greater than the record"):
        _, S = welch_csd_matrix(x, 1.0, nperseg=256)
    assert S.shape == (51, 2, 2)
