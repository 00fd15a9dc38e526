"""The open-loop baseline's numerics (``procedures.analysis.baseline``) on data from a generator
written here from DESIGN.md section 3, not from ``simhw``: an autocollimator angle noise white
plus 1/f at drawn levels and corners, seen through the Table 1 filters; a pickoff noise white
plus lines at drawn frequencies. The NEA within 10 % and its interval covering the truth over
many draws; the lines found where they were put."""

from __future__ import annotations

import math

import numpy as np
import pytest

from drivers.rig_datasheet import AutocollimatorConstants
from procedures.analysis.baseline import (
    NEA_BAND_HZ,
    array_blocks,
    band_rms,
    nea_truth,
    pickoff_lines,
    psd_of,
    white_flicker,
)
from procedures.analysis.transfer import sensor_filter

FS = 250.0
SEG_S = 40.0
N_BLOCKS = 8
T_S = 400.0
AC = AutocollimatorConstants(5.70, 5.63)
SCALE = {
    "ac_x_ctl": AC.control_mV_per_urad * 1e-3,
    "ac_x_inst": AC.inst_mV_per_urad * 1e-3,
}  # V/urad


def angle_noise_through_filters(rng, white_urad2_per_hz, corner_hz, n, knee=1.0, slope=1.0):
    """White + 1/f angle noise (one-sided PSD S_w (1 + f_c/f) above 1 mHz; with ``knee`` and
    ``slope`` the nominal unit's S_w (knee (1 + r) + (1 - knee) max(1, r)), r = (f_c/f)^slope,
    DESIGN.md section 8), synthesized in the frequency domain, and the two channels' outputs (V)
    through their filters."""
    f = np.fft.rfftfreq(n, 1 / FS)
    S = np.zeros_like(f)
    r = (corner_hz / np.maximum(f[1:], 1e-3)) ** slope
    S[1:] = white_urad2_per_hz * (knee * (1 + r) + (1 - knee) * np.maximum(1.0, r))
    # one-sided S: a bin's complex amplitude has E|X|^2 = S fs n / 2
    X = (rng.standard_normal(len(f)) + 1j * rng.standard_normal(len(f))) * np.sqrt(S * FS * n / 4)
    X[0] = 0.0
    out = {c: np.fft.irfft(X * sensor_filter(f, AC, c) * _aa(f), n) * SCALE[c] for c in SCALE}
    return f, S, out


def _aa(f, fs=FS):
    """The recorder's anti-alias filter every record passes (DESIGN.md section 5): a 3-pole
    Butterworth at 0.3 fs, its magnitude written here from the Butterworth form (zero phase:
    only |H| matters to a PSD)."""
    return 1.0 / np.sqrt(1.0 + (np.asarray(f) / (0.3 * fs)) ** 6)


def test_nea_within_ten_percent_and_its_interval_covers_over_many_draws():
    rng = np.random.default_rng(2201)
    n = int(T_S * FS)
    draws, covered, worst = 40, {c: 0 for c in SCALE}, 0.0
    for _ in range(draws):
        nea = rng.uniform(0.3, 0.8)  # urad in 0.1-100 Hz on the control channel
        corner = rng.uniform(1.0, 6.0)
        fg = np.geomspace(*NEA_BAND_HZ, 4000)
        unit = nea_truth(fg, 1 + corner / fg, np.abs(sensor_filter(fg, AC, "ac_x_ctl")) ** 2)
        white = (nea / unit) ** 2
        f, S, out = angle_noise_through_filters(rng, white, corner, n)
        x = np.column_stack([out[c] for c in SCALE])
        blocks = array_blocks(x, FS, tuple(SCALE), SEG_S, N_BLOCKS)
        for c in SCALE:
            truth = nea_truth(fg, white * (1 + corner / fg), np.abs(sensor_filter(fg, AC, c)) ** 2)
            e = band_rms(blocks, c, SCALE[c], *NEA_BAND_HZ)
            assert e.resolved
            worst = max(worst, abs(e.value / truth - 1))
            covered[c] += e.covers(truth)
    assert worst < 0.10
    # 95 % intervals: at least 34 of 40 (binomial 2.5 % tail at p = 0.95 is 35)
    assert all(k >= 34 for k in covered.values()), covered


def test_white_level_and_corner_are_found_with_intervals():
    rng = np.random.default_rng(2202)
    n = int(T_S * FS)
    hits_w = hits_c = 0
    draws = 12
    for _ in range(draws):
        white = rng.uniform(1e-3, 4e-3)  # urad^2/Hz
        corner = rng.uniform(1.5, 5.0)
        f, S, out = angle_noise_through_filters(rng, white, corner, n)
        blocks = array_blocks(out["ac_x_ctl"][:, None], FS, ("ac_x_ctl",), SEG_S, N_BLOCKS)
        h2 = np.abs(sensor_filter(blocks.f, AC, "ac_x_ctl")) ** 2
        wf = white_flicker(blocks, "ac_x_ctl", SCALE["ac_x_ctl"], h2, 0.1, 35.0)
        assert wf.white_urad_per_rtHz.value == pytest.approx(math.sqrt(white), rel=0.05)
        assert wf.corner_hz.value == pytest.approx(corner, rel=0.25)
        hits_w += wf.white_urad_per_rtHz.covers(math.sqrt(white))
        hits_c += wf.corner_hz.covers(corner)
    assert hits_w >= 10 and hits_c >= 10


def test_white_level_and_corner_cover_the_truth_on_every_knee_a_nominal_unit_allows():
    """Issue 38 item 5: on a sharp or part-soft knee and a slope of 0.8-1.2 (DESIGN.md section 8)
    the thesis's S_w (1 + f_c/f) reads the white level up to 13 % off and the corner up to 58 %,
    with intervals that held neither (white 19/40, corner 18/40 on drawn rigs). The white
    level's interval spans the forms the data do not reject and covers the truth; so does the
    corner's over the forms (``corner_hz``), unresolved with that finite interval where it is
    wider than the corner, never a bare number."""
    rng = np.random.default_rng(3805)
    n = int(480 * FS)
    hits_w = hits_c = 0
    forms = [(0.0, 1.2), (0.0, 0.8), (0.3, 1.15), (0.0, 1.0), (0.6, 0.85), (0.0, 1.1)] * 2
    for knee, slope in forms:
        white = rng.uniform(1e-3, 4e-3)  # urad^2/Hz
        corner = rng.uniform(1.5, 5.0)
        f, S, out = angle_noise_through_filters(rng, white, corner, n, knee, slope)
        blocks = array_blocks(out["ac_x_ctl"][:, None], FS, ("ac_x_ctl",), SEG_S, N_BLOCKS)
        h2 = np.abs(sensor_filter(blocks.f, AC, "ac_x_ctl")) ** 2
        wf = white_flicker(blocks, "ac_x_ctl", SCALE["ac_x_ctl"], h2, 0.1, 35.0)
        hits_w += wf.white_urad_per_rtHz.covers(math.sqrt(white))
        c = wf.corner_hz
        assert c is not None
        hits_c += c.covers(corner)
        assert math.isfinite(c.lo) and math.isfinite(c.hi) and c.lo < c.hi
        assert c.resolved or c.why
    assert hits_w >= 11 and hits_c >= 11, (hits_w, hits_c)


def test_a_band_the_segments_cannot_reach_is_unresolved():
    rng = np.random.default_rng(5)
    x = rng.standard_normal((int(80 * FS), 1))
    blocks = array_blocks(x, FS, ("ac_x_ctl",), 8.0, 8)
    e = band_rms(blocks, "ac_x_ctl", 1.0, *NEA_BAND_HZ)
    assert not e.resolved and "segments" in e.why


def test_pickoff_band_rms_and_lines_where_they_were_put():
    rng = np.random.default_rng(2203)
    kg = 6.03e-3  # V/urad
    fs, T = 1000.0, 240.0
    n = int(fs * T)
    t = np.arange(n) / fs
    hits = 0
    for _ in range(6):
        white = rng.uniform(0.05, 0.3)  # urad^2/Hz one-sided
        f71 = rng.uniform(70.3, 71.0)
        lines = [
            (f71, rng.uniform(2, 4)),
            (f71 + rng.uniform(0.7, 0.9), rng.uniform(2, 4)),
            (rng.uniform(101.5, 102.5), rng.uniform(3, 5)),
            (rng.uniform(186.5, 187.5), rng.uniform(1.5, 3)),
        ]
        x = rng.standard_normal(n) * math.sqrt(white * fs / 2)
        for fl, a in lines:
            x += a * np.sin(2 * np.pi * fl * t + rng.uniform(0, 2 * np.pi))
        blocks = array_blocks((x * kg)[:, None], fs, ("gyro_x",), 20.0, 8)
        e = band_rms(blocks, "gyro_x", kg, 1.0, 50.0)
        truth = math.sqrt(white * 49.0)
        assert e.value == pytest.approx(truth, rel=0.05)
        hits += e.covers(truth)
        found = pickoff_lines(x * kg, fs, blocks.f, psd_of(blocks, "gyro_x"), kg, 1.0, 0.4 * fs)
        assert len(found) == len(lines)
        for ln, (fl, a) in zip(found, sorted(lines)):
            assert abs(ln.freq_hz - fl) < 0.01
            lo, hi = ln.ci95_hz
            assert lo - 1e-3 <= fl <= hi + 1e-3
            assert ln.amplitude_urad == pytest.approx(a, rel=0.1)
    assert hits >= 5


def test_the_pickoff_rms_divides_out_the_recorder_s_anti_alias_filter():
    """Issue 38: a pickoff-like record (white 0.1-200 Hz plus lines at 71, 102 and 187 Hz) through
    the recorder's 3-pole anti-alias filter at 0.3 fs, 1 kHz: the 0.1-200 Hz rms is the sensor's,
    within 0.5 %, and its interval holds it (the filter cut the 187 Hz line by 3 % and the rms by
    0.2-0.4 %, which intervals of +-0.1-0.2 % did not hold: 6 of 40 drawn rigs covered)."""
    fs, n = 1000.0, int(480 * 1000)
    rng = np.random.default_rng(3801)
    f = np.fft.rfftfreq(n, 1 / fs)
    white = 0.04  # urad^2/Hz
    X = (rng.standard_normal(len(f)) + 1j * rng.standard_normal(len(f))) * np.sqrt(
        white * fs * n / 4
    )
    X[0] = 0.0
    t = np.arange(n) / fs
    lines = [(71.0, 4.0), (71.8, 4.0), (102.0, 3.0), (187.0, 5.0)]
    x = np.fft.irfft(X, n) + sum(
        a * np.sin(2 * np.pi * fl * t + k) for k, (fl, a) in enumerate(lines)
    )
    # the filter applied to the whole record, lines included, in the frequency domain
    x = np.fft.irfft(np.fft.rfft(x) * _aa(f, fs), n)
    truth = math.sqrt(white * (200.0 - 0.1) + sum(a * a / 2 for _, a in lines))
    blocks = array_blocks(x[:, None], fs, ("gyro_x",), 40.0, 8)
    e = band_rms(blocks, "gyro_x", 1.0, 0.1, 200.0)
    assert e.resolved and e.value == pytest.approx(truth, rel=5e-3) and e.covers(truth), (e, truth)
    # what the recorder's filter takes: 1 % of this rms (the strong 187 Hz line loses 6 % of its power)
    raw = band_rms(blocks, "gyro_x", 1.0, 0.1, 200.0, anti_alias=False)
    assert 1 - raw.value / e.value == pytest.approx(0.0098, abs=0.002)
