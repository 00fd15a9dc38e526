"""A line's frequency measured on the record (``lines.refine_line``): exact far below a band's
width, and its sigma the scatter it really has."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.signal
from hypothesis import given, settings
from hypothesis import strategies as st

from procedures.analysis.gap.pickoff_lines import refine_line

FS, T = 1000.0, 60.0


def _line(rng, f, a, noise_rms):
    t = np.arange(int(FS * T)) / FS
    return a * np.sin(
        2 * math.pi * f * t + rng.uniform(0, 2 * math.pi)
    ) + noise_rms * rng.standard_normal(len(t))


def test_the_sigma_is_the_scatter_and_the_interval_covers():
    rng = np.random.default_rng(17)
    errors, sigmas = [], []
    for _ in range(40):
        f = 123.4 + rng.uniform(-0.05, 0.05)
        x = _line(rng, f, 0.003, 0.02)
        m = refine_line(x, FS, 123.4, 0.5, 2 * 0.02**2 / FS)
        errors.append(m.freq_hz - f)
        sigmas.append(m.sigma_hz)
        assert m.amplitude == pytest.approx(0.003, rel=0.25)  # biased up by the noise in its bin
        assert m.is_line
    errors, sigmas = np.array(errors), np.array(sigmas)
    assert np.std(errors) == pytest.approx(np.mean(sigmas), rel=0.3)
    assert np.mean(np.abs(errors) <= 1.96 * sigmas) >= 0.85


@settings(max_examples=15, deadline=None)
@given(f=st.floats(5.0, 400.0), offset=st.floats(-0.4, 0.4))
def test_a_clear_line_is_found_far_inside_its_bin(f, offset):
    x = _line(np.random.default_rng(1), f, 0.01, 0.01)
    m = refine_line(x, FS, f + offset, 0.5, 2 * 0.01**2 / FS)
    assert abs(m.freq_hz - f) < max(5 * m.sigma_hz, 1e-3)
    assert m.sigma_hz < 1e-3
    assert m.is_line


@pytest.mark.parametrize("seed", range(5))
def test_a_resonance_and_plain_noise_are_not_lines(seed):
    """A lightly damped mode driven by white noise (zeta 0.02 at 60 Hz: 2.4 Hz wide) peaks as
    wide as its damping, and noise alone has no peak as narrow as the window's."""
    rng = np.random.default_rng(seed)
    n = int(FS * T)
    w0, z = 2 * math.pi * 60.0, 0.02
    b, a = scipy.signal.bilinear([w0 * w0], [1.0, 2 * z * w0, w0 * w0], FS)
    x = scipy.signal.lfilter(b, a, rng.standard_normal(n))
    for f0 in (60.0, 150.0):
        assert not refine_line(x, FS, f0, 0.5, 1e-6).is_line
