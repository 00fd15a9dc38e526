"""The recording chain: anti-alias Butterworth at 0.3 fs, decimation, clipped ADC (App. A.5, A.7)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from simhw.sampling import ADC_RANGES_V, RangeError, SamplingChain, check_range, quantize

FAST = settings(max_examples=150, deadline=None)
ranges_s = st.sampled_from(ADC_RANGES_V)
bits_s = st.integers(8, 24)
any_float_arrays = hnp.arrays(
    np.float64,
    st.integers(1, 40),
    elements=st.floats(allow_nan=True, allow_infinity=True, width=64),
)


def _lsb(range_V, bits):
    return 2.0 * range_V / 2**bits


# --------------------------------------------------------------------------- quantize
@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
@FAST
@given(any_float_arrays, ranges_s, bits_s)
def test_quantized_values_lie_on_the_converter_grid_within_the_code_range(v, range_V, bits):
    out, _ = quantize(v, range_V, bits)
    q = _lsb(range_V, bits)
    assert out.shape == v.shape
    assert np.all(np.isfinite(out))
    code = out / q
    np.testing.assert_allclose(code, np.rint(code), rtol=0, atol=1e-6)
    assert np.all(np.rint(code) >= -(2 ** (bits - 1)))
    assert np.all(np.rint(code) <= 2 ** (bits - 1) - 1)


@FAST
@given(st.data(), ranges_s, bits_s)
def test_quantization_error_is_at_most_half_an_lsb_inside_the_range(data, range_V, bits):
    q = _lsb(range_V, bits)
    v = data.draw(
        hnp.arrays(np.float64, st.integers(1, 40), elements=st.floats(-range_V, range_V - q / 2))
    )
    out, over = quantize(v, range_V, bits)
    assert np.all(np.abs(out - v) <= q / 2 * (1 + 1e-9))
    assert not over.any()


@pytest.mark.parametrize("bits", [8, 16, 24])
def test_top_half_lsb_below_full_scale_saturates_at_the_top_code_without_a_flag(bits):
    # Two's-complement codes: -2^(b-1) q = -range exists, +range does not; the top code is range - q.
    range_V = 1.0
    q = _lsb(range_V, bits)
    v = np.array([range_V - q / 4, range_V])
    out, over = quantize(v, range_V, bits)
    np.testing.assert_array_equal(out, [range_V - q, range_V - q])
    assert not over.any()
    out, over = quantize(np.array([-range_V]), range_V, bits)
    assert out[0] == -range_V and not over[0]


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
@FAST
@given(any_float_arrays, ranges_s, bits_s)
def test_overrange_is_flagged_exactly_when_beyond_full_scale_or_not_finite(v, range_V, bits):
    _, over = quantize(v, range_V, bits)
    with np.errstate(invalid="ignore"):
        expected = ~np.isfinite(v) | (np.abs(v) > range_V)
    np.testing.assert_array_equal(over, expected)


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
@FAST
@given(
    st.lists(
        st.floats(allow_nan=False, allow_infinity=True) | st.sampled_from([1e308, -1e308, 1e30]),
        min_size=1,
        max_size=30,
    ),
    ranges_s,
    bits_s,
)
def test_values_beyond_full_scale_clip_to_the_end_codes_never_wrap(values, range_V, bits):
    v = np.array(values, float)
    out, _ = quantize(v, range_V, bits)
    q = _lsb(range_V, bits)
    top, bottom = (2 ** (bits - 1) - 1) * q, -(2 ** (bits - 1)) * q
    np.testing.assert_array_equal(out[v > range_V], top)
    np.testing.assert_array_equal(out[v < -range_V], bottom)
    # Never wrapped: the converter is monotone in its input.
    order = np.argsort(v, kind="stable")
    assert np.all(np.diff(out[order]) >= 0)


def test_nan_is_flagged_and_reads_as_a_finite_code():
    out, over = quantize(np.array([np.nan, 0.5, np.nan]), 1.0, 16)
    np.testing.assert_array_equal(over, [True, False, True])
    assert np.all(np.isfinite(out))
    assert out[1] == pytest.approx(0.5, abs=_lsb(1.0, 16) / 2)


def test_lsb_is_two_range_over_two_to_the_bits():
    out, _ = quantize(np.array([0.0, 1e-9, _lsb(10.0, 16) * 0.51]), 10.0, 16)
    np.testing.assert_array_equal(out, [0.0, 0.0, 20.0 / 65536])


# --------------------------------------------------------------------------- ranges
@pytest.mark.parametrize("range_V", ADC_RANGES_V)
def test_check_range_accepts_every_converter_range(range_V):
    assert check_range("gyro_x", range_V) == range_V


@pytest.mark.parametrize("range_V", [3.0, 0.0, -10.0, 20.0, 0.3])
def test_check_range_rejects_unknown_range_naming_channel_and_value(range_V):
    with pytest.raises(RangeError) as exc:
        check_range("ac_x_ctl", range_V)
    msg = str(exc.value)
    assert "ac_x_ctl" in msg and repr(range_V) in msg
    assert "10.0" in msg and "0.01" in msg  # lists the available ranges
    assert isinstance(exc.value, ValueError)


def test_set_range_changes_the_full_scale_of_one_channel():
    chain = SamplingChain(("a", "b"), 1000.0, 2)
    chain.set_range("b", 0.1)
    _, volts, over = chain.process(np.full((4000, 2), 0.5))
    assert not over[-1, 0] and over[-1, 1]
    assert volts[-1, 0] == pytest.approx(0.5, abs=_lsb(10.0, 16))
    assert volts[-1, 1] == pytest.approx(0.1, abs=_lsb(0.1, 16))


def test_set_range_rejects_unknown_channel_and_unknown_range():
    chain = SamplingChain(("a",), 1000.0, 2)
    with pytest.raises(KeyError, match="'z'"):
        chain.set_range("z", 1.0)
    with pytest.raises(RangeError, match="a"):
        chain.set_range("a", 3.0)
    assert chain.ranges["a"] == 10.0


# --------------------------------------------------------------------------- sampling chain
def _tone_gain(freq_hz, rate_hz=1000.0, oversample=2, bits=16, range_V=1.0, amp=0.5, poles=3):
    """Gain of the chain at freq_hz, by least squares on the settled decimated output."""
    chain = SamplingChain(("s",), rate_hz, oversample, poles=poles, bits=bits)
    chain.set_range("s", range_V)
    dt = 1.0 / (rate_hz * oversample)
    n = int(4.0 * rate_hz * oversample)
    k = np.arange(n)
    keep, volts, _ = chain.process((amp * np.sin(2 * math.pi * freq_hz * dt * k))[:, None])
    t = keep * dt
    settled = t > 0.5
    basis = np.column_stack(
        [np.sin(2 * math.pi * freq_hz * t), np.cos(2 * math.pi * freq_hz * t), np.ones_like(t)]
    )[settled]
    coef, *_ = np.linalg.lstsq(basis, volts[settled, 0], rcond=None)
    return math.hypot(coef[0], coef[1]) / amp


def _db(g):
    return 20 * math.log10(g)


def _butterworth_db(f, fc, fs, poles):
    """Digital Butterworth (bilinear, prewarped at fc) magnitude in dB."""
    r = math.tan(math.pi * f / fs) / math.tan(math.pi * fc / fs)
    return -10 * math.log10(1 + r ** (2 * poles))


@pytest.mark.parametrize("oversample", [1, 2, 3])
def test_dc_passes_with_unit_gain(oversample):
    chain = SamplingChain(("a", "b"), 500.0, oversample)
    keep, volts, over = chain.process(np.tile([0.7, -2.3], (3000, 1)))
    settled = volts[len(volts) // 2 :]
    q = _lsb(10.0, 16)
    np.testing.assert_allclose(settled[:, 0], 0.7, atol=q / 2 + 1e-12)
    np.testing.assert_allclose(settled[:, 1], -2.3, atol=q / 2 + 1e-12)
    assert not over.any()


def test_tone_at_the_anti_alias_cutoff_is_attenuated_3_dB():
    assert _db(_tone_gain(300.0)) == pytest.approx(-3.01, abs=0.05)


def test_tone_near_nyquist_is_attenuated_more_as_a_3_pole_butterworth():
    g450 = _db(_tone_gain(450.0))
    assert g450 < _db(_tone_gain(300.0)) - 6.0
    assert g450 == pytest.approx(_butterworth_db(450.0, 300.0, 2000.0, 3), abs=0.1)


def test_tone_well_below_cutoff_passes_with_nearly_unit_gain():
    assert _db(_tone_gain(30.0)) == pytest.approx(0.0, abs=0.01)


@pytest.mark.parametrize("poles", [1, 5])
def test_pole_count_sets_the_rolloff(poles):
    assert _db(_tone_gain(450.0, poles=poles)) == pytest.approx(
        _butterworth_db(450.0, 300.0, 2000.0, poles), abs=0.1
    )


def test_process_keeps_every_oversample_th_internal_sample():
    chain = SamplingChain(("a",), 100.0, 4)
    keep, volts, over = chain.process(np.zeros((10, 1)))
    np.testing.assert_array_equal(keep, [0, 4, 8])
    assert volts.shape == (3, 1) and over.shape == (3, 1)


@settings(max_examples=60, deadline=None)
@given(
    sizes=st.lists(st.integers(1, 120), min_size=1, max_size=10),
    oversample=st.integers(1, 5),
    seed=st.integers(0, 2**32 - 1),
)
def test_chunked_processing_equals_one_call(sizes, oversample, seed):
    channels = ("a", "b", "c")
    x = np.random.default_rng(seed).normal(0.0, 3.0, (sum(sizes), len(channels)))
    x[::17, 2] = 25.0  # some overrange samples too
    ref = SamplingChain(channels, 200.0, oversample)
    keep_all, volts_all, over_all = ref.process(x)
    chain = SamplingChain(channels, 200.0, oversample)
    keeps, volts, overs, start = [], [], [], 0
    for n in sizes:
        keep, v, o = chain.process(x[start : start + n])
        keeps.append(keep + start)
        volts.append(v)
        overs.append(o)
        start += n
    np.testing.assert_array_equal(np.concatenate(keeps), keep_all)
    np.testing.assert_array_equal(np.concatenate(volts), volts_all)
    np.testing.assert_array_equal(np.concatenate(overs), over_all)


def test_processing_an_empty_block_gives_no_samples_and_keeps_the_state():
    ref = SamplingChain(("a", "b"), 1000.0, 3)
    x = np.random.default_rng(0).normal(size=(50, 2))
    _, v_ref, _ = ref.process(x)
    chain = SamplingChain(("a", "b"), 1000.0, 3)
    keep, volts, over = chain.process(np.zeros((0, 2)))
    assert keep.shape == (0,) and volts.shape == (0, 2) and over.shape == (0, 2)
    _, v1, _ = chain.process(x[:7])
    chain.process(np.zeros((0, 2)))
    _, v2, _ = chain.process(x[7:])
    np.testing.assert_array_equal(np.concatenate([v1, v2]), v_ref)


def test_anti_alias_filter_starts_settled_on_the_first_sample():
    chain = SamplingChain(("a", "b"), 1000.0, 2)
    chain.set_range("b", 0.1)
    _, volts, over = chain.process(np.tile([3.3, -0.05], (40, 1)))
    np.testing.assert_allclose(volts[:, 0], 3.3, atol=_lsb(10.0, 16) / 2)
    np.testing.assert_allclose(volts[:, 1], -0.05, atol=_lsb(0.1, 16) / 2)
    assert not over.any()


@settings(max_examples=40, deadline=None)
@given(
    x=hnp.arrays(
        np.float64,
        st.tuples(st.integers(1, 60), st.integers(1, 5)),
        elements=st.floats(-20.0, 20.0, allow_nan=False),
    ),
    cut=st.integers(0, 60),
)
def test_the_chain_filters_as_scipy_sosfilt_does_to_the_bit(x, cut):
    """The chain's own filter loop (``_sosfilt_cols``) against ``scipy.signal.sosfilt``, the
    state carried over a cut of the block."""
    import scipy.signal

    from simhw.sampling import _sosfilt_cols, anti_alias_sos

    sos = anti_alias_sos(3, 0.3, 1000.0, 10)
    zi0 = scipy.signal.sosfilt_zi(sos)[:, :, None] * x[0][None, None, :]
    want, want_zi = scipy.signal.sosfilt(sos, x, axis=0, zi=zi0)
    zi = np.ascontiguousarray(zi0)
    got = np.concatenate([_sosfilt_cols(sos, x[:cut], zi), _sosfilt_cols(sos, x[cut:], zi)])
    assert np.array_equal(got, want) and np.array_equal(zi, want_zi)
