"""Noise sources: deterministic per seed, independent of block size, with the requested spectra."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.signal
import scipy.stats
from hypothesis import given, settings
from hypothesis import strategies as st

from simhw.noise import FlickerNoise, Lines, RandomWalk, TelegraphJumps, WhiteNoise, knee_excess
from simhw.simulator import ac_knee

DT = 1e-3
PICKOFF_LINES = [(70.6, 3.0), (71.4, 3.0), (102.0, 4.0), (187.0, 2.0)]

#: name -> factory(rng) for each source, with parameters that exercise its internals
#: (several decimation groups for the flicker bank, several lines).
SOURCES = {
    "white": lambda rng: WhiteNoise(rng, 2.5, DT),
    "flicker": lambda rng: FlickerNoise(rng, 0.7, 1e-3, 80.0, DT),
    # a fitted bank with the sharp knee's low-pass (its filter state carries across blocks)
    "flicker_knee": lambda rng: FlickerNoise(
        rng, 0.7, 1e-3, 80.0, DT, corner_hz=3.0, knee=0.2, slope=1.2
    ),
    "random_walk": lambda rng: RandomWalk(rng, 0.3, DT),
    "lines": lambda rng: Lines(rng, PICKOFF_LINES, DT),
    "telegraph": lambda rng: TelegraphJumps(rng, 5.0, 0.05, DT),
}


def _make(name, seed=1234):
    return SOURCES[name](np.random.default_rng(seed))


def _welch(x, dt, nperseg):
    return scipy.signal.welch(x, fs=1.0 / dt, nperseg=nperseg)  # one-sided density


# --------------------------------------------------------------------------- block-size invariance
@settings(max_examples=60, deadline=None)
@given(
    name=st.sampled_from(sorted(SOURCES)),
    sizes=st.lists(st.integers(1, 700), min_size=1, max_size=12),
    seed=st.integers(0, 2**32 - 1),
)
def test_samples_do_not_depend_on_how_the_run_is_cut_into_blocks(name, sizes, seed):
    whole = _make(name, seed).take(sum(sizes))
    src = _make(name, seed)
    pieces = np.concatenate([src.take(n) for n in sizes])
    assert pieces.shape == whole.shape
    np.testing.assert_array_equal(pieces, whole)


def test_random_walk_is_bit_exact_across_block_boundaries():
    whole = RandomWalk(np.random.default_rng(0), 0.3, DT).take(3)
    src = RandomWalk(np.random.default_rng(0), 0.3, DT)
    np.testing.assert_array_equal(np.concatenate([src.take(1), src.take(2)]), whole)


@pytest.mark.parametrize("name", sorted(SOURCES))
def test_same_seed_gives_same_samples_and_other_seed_differs(name):
    a, b, c = _make(name, 7).take(3000), _make(name, 7).take(3000), _make(name, 8).take(3000)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


@pytest.mark.parametrize("name", ["white", "flicker", "flicker_knee", "lines"])
def test_an_empty_block_is_empty_and_changes_nothing(name):
    whole = _make(name).take(500)
    src = _make(name)
    assert src.take(0).shape == (0,)
    np.testing.assert_allclose(
        np.concatenate([src.take(200), src.take(0), src.take(300)]), whole, rtol=0, atol=1e-12
    )


@pytest.mark.parametrize("name", ["random_walk", "telegraph"])
def test_an_empty_block_is_empty_for_stateful_sources(name):
    src = _make(name)
    src.take(10)
    assert src.take(0).shape == (0,)


@pytest.mark.parametrize(
    "source",
    [
        WhiteNoise(np.random.default_rng(0), 0.0, DT),
        FlickerNoise(np.random.default_rng(0), 0.0, 1e-3, 10.0, DT),
        FlickerNoise(
            np.random.default_rng(0), 0.0, 1e-3, 10.0, DT, corner_hz=3.0, knee=0.0, slope=0.8
        ),
        FlickerNoise(
            np.random.default_rng(0), 1.0, 1e-3, 10.0, DT, corner_hz=0.0, knee=0.0, slope=0.8
        ),
        RandomWalk(np.random.default_rng(0), 0.0, DT),
        Lines(np.random.default_rng(0), [], DT),
        TelegraphJumps(np.random.default_rng(0), 0.0, 10.0, DT),
    ],
    ids=[
        "white",
        "flicker",
        "flicker_knee",
        "flicker_no_corner",
        "random_walk",
        "lines",
        "telegraph",
    ],
)
def test_zero_level_source_gives_zeros(source):
    np.testing.assert_array_equal(source.take(257), np.zeros(257))


# --------------------------------------------------------------------------- white noise
@pytest.mark.parametrize("psd, dt", [(2.5, 1e-3), (3e-12, 1 / 2000), (1.0, 1 / 200)])
def test_white_noise_has_the_requested_one_sided_psd(psd, dt):
    x = WhiteNoise(np.random.default_rng(42), psd, dt).take(2**17)
    f, p = _welch(x, dt, 1024)
    band = p[1:-1]  # leave out DC and Nyquist (half-weight bins)
    assert np.mean(band) == pytest.approx(psd, rel=0.03)
    # Flat: the low and high thirds of the band agree with the level too.
    third = len(band) // 3
    assert np.mean(band[:third]) == pytest.approx(psd, rel=0.1)
    assert np.mean(band[-third:]) == pytest.approx(psd, rel=0.1)


def test_white_noise_variance_is_psd_times_nyquist_bandwidth():
    psd, dt = 4.0, 1 / 500
    x = WhiteNoise(np.random.default_rng(3), psd, dt).take(100_000)
    assert np.var(x) == pytest.approx(psd / (2 * dt), rel=0.03)


# --------------------------------------------------------------------------- flicker noise
def _log_binned(f, p, lo, hi, nbins):
    edges = np.geomspace(lo, hi, nbins + 1)
    fc, pc = [], []
    for a, b in zip(edges[:-1], edges[1:]):
        m = (f >= a) & (f < b)
        fc.append(math.exp(np.mean(np.log(f[m]))))
        pc.append(np.mean(p[m]))
    return np.array(fc), np.array(pc)


@pytest.fixture(scope="module")
def flicker_spectrum():
    dt, level = 1 / 200, 2.0
    x = FlickerNoise(np.random.default_rng(2024), level, 1e-3, 50.0, dt).take(2**18)
    f, p = _welch(x, dt, 2**14)
    return f, p, level


def test_flicker_noise_psd_falls_as_one_over_f(flicker_spectrum):
    f, p, _ = flicker_spectrum
    fc, pc = _log_binned(f, p, 0.05, 5.0, 10)
    slope, _ = np.polyfit(np.log(fc), np.log(pc), 1)
    assert slope == pytest.approx(-1.0, abs=0.15)


def test_flicker_noise_level_at_1_hz_is_the_requested_level(flicker_spectrum):
    f, p, level = flicker_spectrum
    m = (f > 0.8) & (f < 1.25)
    assert np.mean(p[m] * f[m]) == pytest.approx(level, rel=0.2)


def test_flicker_noise_rolls_off_above_its_top_corner():
    # Above f_hi the bank rolls off (first-order lags): far below the 1/f extension.
    dt, level = 1 / 1000, 1.0
    x = FlickerNoise(np.random.default_rng(5), level, 1e-2, 5.0, dt).take(2**17)
    f, p = _welch(x, dt, 2**12)
    m = (f > 100) & (f < 200)
    assert np.mean(p[m] * f[m]) < 0.2 * level


# --------------------------------------------------------------------------- the autocollimator's knee
def test_the_1_over_f_bank_is_pinned_and_the_plain_knee_takes_its_path():
    # Pinned (same seed, same samples) so a change of the bank is seen; the default knee and
    # slope, with any corner, take the same path. Re-pinned in issue 38, when the bank became
    # 1/f across its band (``test_the_1_over_f_bank_is_1_over_f_across_its_band``): the samples
    # before (4.1607..., 1.5020..., -5.8879..., -2.1265..., 1.0773...; sum -3610.14) were of a
    # bank 23-36 % short of 1/f in its band's top half.
    for kw in ({}, {"corner_hz": 4.0, "knee": 1.0, "slope": 1.0}):
        x = FlickerNoise(np.random.default_rng(2024), 2.0, 1e-3, 50.0, 1 / 200, **kw).take(10000)
        # to rounding: the filters' last bits move with the numpy/scipy build and the CPU (an
        # AMD EPYC moved sample 4096, -0.65 where the terms summed are ~5, by 1.5e-9: atol on
        # the samples' scale, not rtol on a small one); another path or seed differs in the
        # first digit
        np.testing.assert_allclose(
            x[[0, 1, 4095, 4096, 9999]],
            [
                2.459735779625351,
                2.332992001614816,
                -4.75557027865546,
                -0.6456960629034945,
                -8.818697547440227,
            ],
            rtol=1e-9,
            atol=1e-8,
        )
        assert float(np.sum(x)) == pytest.approx(-54509.16758902176, rel=1e-9)


#: (f_lo, f_hi, dt) of the rig's 1/f banks (the autocollimators' at the 2 kHz internal rate, the
#: azimuth's, the gyro's flicker drift) and of a band reaching a quarter of the step rate
RIG_BANKS = [
    (1e-4, 100.0, 1 / 2000),
    (1e-4, 200.0, 1 / 2000),
    (1e-5, 1.0, 1 / 2000),
    (1e-4, 50.0, 1 / 2000),
]


@pytest.mark.parametrize("f_lo, f_hi, dt", RIG_BANKS + [(1e-3, 50.0, 1 / 200)])
def test_the_1_over_f_bank_is_1_over_f_across_its_band(f_lo, f_hi, dt):
    """Issue 38: the bank's exact spectrum (as the plant sees it) is level / f from f_lo to f_hi,
    within 0.1 % up to 0.1 / dt and 1 % up to 0.25 / dt (FlickerNoise's docstring). The bank of
    2.5 lags a decade from f_lo to f_hi it replaced gave 64 % at either end, 77 % at 0.6 f_hi."""
    level = 0.7
    src = FlickerNoise(np.random.default_rng(0), level, f_lo, f_hi, dt)
    f = np.geomspace(f_lo, f_hi, 4000)
    rel = src.spectrum(f, dt) * f / level - 1.0
    tol = 1e-3 if f_hi <= 0.1 / dt else 1e-2
    assert np.max(np.abs(rel)) < tol, (f[np.argmax(np.abs(rel))], np.max(np.abs(rel)))


def test_a_long_simulation_of_the_1_over_f_bank_has_psd_level_over_f():
    """Issue 38: the PSD of a long generated record (2^22 steps at 2 kHz of the autocollimator's
    bank, 1e-4..100 Hz) against level / f from 2 Hz to 100 Hz, in 6 log bins of the Welch
    estimate (2^14-point segments): each bin's mean of p f / level within 6 % of 1 (over seeds
    0-9 the bins scattered 1.8 % (the lowest) to 0.3 % (the highest), none beyond 3.4 %; the
    replaced bank read 0.77 at 30 Hz and 0.64 at 50 Hz)."""
    dt, level = 1 / 2000, 0.7
    x = FlickerNoise(np.random.default_rng(38), level, 1e-4, 100.0, dt).take(2**22)
    f, p = _welch(x, dt, 2**14)
    _, pc = _log_binned(f, p * f / level, 2.0, 100.0, 6)
    np.testing.assert_allclose(pc, 1.0, atol=0.06)


@pytest.mark.parametrize("knee", [0.0, 0.3, 1.0])
@pytest.mark.parametrize("slope", [0.5, 0.8, 1.0, 1.2, 2.0])
def test_knee_excess_is_ac_knee_less_one(knee, slope):
    f = np.geomspace(1e-3, 500.0, 300)
    np.testing.assert_allclose(
        knee_excess(f, 3.0, knee, slope), ac_knee(f, 3.0, knee, slope) - 1.0, rtol=1e-12, atol=1e-12
    )


def test_ac_knee_spans_the_nominal_envelope():
    # DESIGN.md section 8: between max(1, fc/f) (knee 0) and 1 + fc/f (knee 1)
    f = np.geomspace(0.01, 100.0, 200)
    np.testing.assert_allclose(ac_knee(f, 3.0, 0.0, 1.0), np.maximum(1.0, 3.0 / f), rtol=1e-12)
    np.testing.assert_allclose(ac_knee(f, 3.0, 1.0, 1.0), 1.0 + 3.0 / f, rtol=1e-12)
    mid = ac_knee(f, 3.0, 0.4, 1.0)
    assert np.all(mid >= np.maximum(1.0, 3.0 / f)) and np.all(mid <= 1.0 + 3.0 / f)


#: How closely a bank follows W (K - 1), relative to W K, by knee, at the nominal unit's slopes
#: (0.8-1.2): a sum of first-order lags cannot follow max(1, fc/f)'s sharp corner (their
#: f^2 S(f) never falls), so the knee's lags pass a low-pass, which leaves a few per cent at
#: the corner (``simhw.noise._fitted_bank``).
KNEE_ACCURACY = {0.0: 0.045, 0.5: 0.016, 1.0: 0.01}
#: ... and above 2.5 corners, the white band a white level is measured in, by far closer: the
#: knee's sharp part and its power law are fitted apart, so the low-pass keeps the sharp
#: part's error out of it (fitted together, knee 0.2 left 1.5 % there)
WHITE_BAND_ACCURACY = 0.005


@pytest.mark.parametrize("knee", sorted(KNEE_ACCURACY))
@pytest.mark.parametrize("slope", [0.8, 1.2])
@pytest.mark.parametrize("corner", [1.5, 3.0, 5.0, 10.0, 50.0])
def test_the_bank_s_exact_spectrum_follows_the_knee_from_1e_3_hz_to_its_top(knee, slope, corner):
    dt = 1 / 2000
    src = FlickerNoise(
        np.random.default_rng(0),
        corner,
        1e-4,
        max(50.0, 10 * corner),
        dt,
        corner_hz=corner,
        knee=knee,
        slope=slope,
    )  # white level W = 1
    f = np.geomspace(1e-3, min(src.f_hi, 0.2 / dt), 3000)
    k = ac_knee(f, corner, knee, slope)
    assert np.max(np.abs(src.spectrum(f, dt) - (k - 1.0)) / k) < KNEE_ACCURACY[knee]


@pytest.mark.parametrize("knee", [0.0, 0.2, 0.5, 0.8])
@pytest.mark.parametrize("slope", [0.8, 1.0, 1.2])
@pytest.mark.parametrize("corner", [1.5, 3.0, 5.0, 10.0])
def test_above_the_knee_the_bank_leaves_the_white_level_alone(knee, slope, corner):
    dt = 1 / 2000
    src = FlickerNoise(
        np.random.default_rng(0),
        corner,
        1e-4,
        max(100.0, 10 * corner),
        dt,
        corner_hz=corner,
        knee=knee,
        slope=slope,
    )  # white level W = 1, the simulator's band (to the NEA band's 100 Hz at least)
    f = np.geomspace(2.5 * corner, min(src.f_hi, 0.2 / dt), 500)
    k = ac_knee(f, corner, knee, slope)
    assert np.max(np.abs(src.spectrum(f, dt) - (k - 1.0)) / k) < WHITE_BAND_ACCURACY


def _welch_bands(x, dt, nperseg, edges):
    """Band means of the Welch density (Hann, no overlap) and each band's bins' frequencies;
    and the relative standard deviation of a band mean: each bin is chi^2 with 2 M degrees of
    freedom over M segments, and Hann bins j apart correlate by rho_j (|DFT of w^2|^2)."""
    f, p = scipy.signal.welch(x, fs=1 / dt, window="hann", nperseg=nperseg, noverlap=0)
    m = len(x) // nperseg
    w2 = scipy.signal.get_window("hann", nperseg) ** 2
    rho = np.abs(np.fft.rfft(w2)[:4]) ** 2 / w2.sum() ** 2
    out = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        sel = (f >= lo) & (f < hi)
        b = int(sel.sum())
        var = sum((b - abs(j)) * rho[abs(j)] for j in range(-3, 4) if abs(j) < b) / (m * b * b)
        out.append((f[sel], p[sel], math.sqrt(var)))
    return out


def _chi2(bands, expected):
    """sum over bands of ((mean of P/E) - 1)^2 / sigma^2: chi^2 with one degree per band."""
    return sum(((np.mean(p / expected(fb)) - 1.0) / s) ** 2 for fb, p, s in bands)


@pytest.fixture(scope="module")
def knee_records():
    """The autocollimator's angle noise, white W plus its 1/f bank, for knee 0 and 1 and slope
    0.8 and 1.2 (corner 3 Hz), 2.9 h at 100 Hz each: Welch bands from 0.05 to 10 Hz."""
    dt, corner, n, nperseg = 1 / 100, 3.0, 2**20, 2**14
    edges = np.geomspace(0.05, 10.0, 13)
    out = {}
    for knee in (0.0, 1.0):
        for slope in (0.8, 1.2):
            rng = np.random.default_rng(int(100 * knee + 10 * slope))
            bank = FlickerNoise(
                rng, corner, 1e-4, 50.0, dt, corner_hz=corner, knee=knee, slope=slope
            )
            x = WhiteNoise(rng, 1.0, dt).take(n) + bank.take(n)
            out[knee, slope] = (
                _welch_bands(x, dt, nperseg, edges),
                lambda f, bank=bank: 1.0 + bank.spectrum(f, dt),
            )
    return corner, out


@pytest.mark.parametrize("knee", [0.0, 1.0])
@pytest.mark.parametrize("slope", [0.8, 1.2])
def test_generated_noise_has_the_psd_w_times_the_knee(knee_records, knee, slope):
    corner, records = knee_records
    bands, made = records[knee, slope]
    limit = scipy.stats.chi2.ppf(1 - 1e-4, len(bands))  # fails once in 10^4 seeds if right
    assert _chi2(bands, made) < limit  # the bank's exact spectrum (what the model-gap reads)
    assert _chi2(bands, lambda f: ac_knee(f, corner, knee, slope)) < limit
    # and the test tells the knees and the slopes apart
    assert _chi2(bands, lambda f: ac_knee(f, corner, 1.0 - knee, slope)) > 10 * limit
    assert _chi2(bands, lambda f: ac_knee(f, corner, knee, 2.0 - slope)) > 10 * limit


# --------------------------------------------------------------------------- random walk
@pytest.mark.parametrize("k, dt", [(0.3, 1e-3), (2e-5, 1 / 2000), (5.0, 0.1)])
def test_random_walk_increments_have_std_k_sqrt_dt(k, dt):
    w = RandomWalk(np.random.default_rng(11), k, dt).take(40_000)
    steps = np.diff(np.concatenate([[0.0], w]))  # the walk starts from zero
    assert np.std(steps) == pytest.approx(k * math.sqrt(dt), rel=0.02)
    assert abs(np.mean(steps)) < 4 * k * math.sqrt(dt) / math.sqrt(len(steps))


# --------------------------------------------------------------------------- lines
@pytest.mark.parametrize("freq_bin, amp", [(300, 3.0), (17, 0.25), (1900, 1e-6)])
def test_single_line_amplitude_and_frequency_are_recovered_by_fft(freq_bin, amp):
    n, dt = 4096, 1e-3
    freq = freq_bin / (n * dt)  # on an FFT bin: no leakage
    x = Lines(np.random.default_rng(9), [(freq, amp)], dt).take(n)
    spec = np.abs(np.fft.rfft(x)) * 2 / n
    assert int(np.argmax(spec)) == freq_bin
    assert spec[freq_bin] == pytest.approx(amp, rel=1e-9)
    assert np.max(np.delete(spec, freq_bin)) < 1e-9 * amp


def test_lines_are_sines_of_the_drawn_phase_at_every_step():
    dt, lines = 1 / 2000, [(70.6, 3.0), (187.0, 2.0)]
    src = Lines(np.random.default_rng(4), lines, dt)
    got = np.concatenate([src.take(1000), src.take(1), src.take(2999)])
    k = np.arange(4000)
    expected = sum(a * np.sin(2 * np.pi * f * dt * k + ph) for (f, a), ph in zip(lines, src.phase))
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-10)


def test_lines_phases_are_uniform_draws_in_0_2pi():
    src = Lines(np.random.default_rng(0), [(1.0, 1.0)] * 500, DT)
    assert np.all((src.phase >= 0) & (src.phase < 2 * np.pi))
    assert np.mean(src.phase) == pytest.approx(np.pi, rel=0.1)


# --------------------------------------------------------------------------- telegraph jumps
def test_telegraph_jumps_only_take_plus_or_minus_the_amplitude():
    src = TelegraphJumps(np.random.default_rng(2), 3.5, 0.02, DT)
    x = np.concatenate([src.take(n) for n in (1, 999, 5000)])
    assert set(np.unique(x)) == {-3.5, 3.5}


@pytest.mark.parametrize("mean_interval_s, dt", [(1.0, 0.01), (60.0, 0.5), (0.05, 1e-3)])
def test_telegraph_mean_switching_interval_is_the_requested_one(mean_interval_s, dt):
    n = int(4000 * mean_interval_s / dt)  # about 4000 switches
    x = TelegraphJumps(np.random.default_rng(8), 1.0, mean_interval_s, dt).take(n)
    switches = np.count_nonzero(np.diff(x))
    assert n * dt / switches == pytest.approx(mean_interval_s, rel=0.1)


def test_telegraph_level_carries_across_blocks():
    src = TelegraphJumps(np.random.default_rng(3), 1.0, 1e6, DT)  # switches almost never
    a, b = src.take(50), src.take(50)
    assert np.all(a == a[0]) and np.all(b == a[-1])
