"""Prewhitening as App. A.3: line and sine removed by least squares, 4-sigma points listed and
replaced by the residual mean, repeated until none remain."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from daq.prewhiten import prewhiten

FS = 200.0


def record(n=4000, seed=0, offset=0.3, slope=-0.02, amp=2.0, freq=7.3, phase=0.4, noise=0.1):
    rng = np.random.default_rng(seed)
    t = np.arange(n) / FS
    return t, offset + slope * t + amp * np.sin(
        2 * np.pi * freq * t + phase
    ) + noise * rng.standard_normal(n)


def test_line_and_sine_are_recovered_and_the_residual_is_the_noise():
    t, x = record()
    p = prewhiten(x, FS, sine_hz="auto")
    off, slope = p.line
    f, a, ph = p.sine
    assert off == pytest.approx(0.3, abs=0.01) and slope == pytest.approx(-0.02, abs=0.001)
    assert (
        f == pytest.approx(7.3, abs=1e-3)
        and a == pytest.approx(2.0, rel=0.01)
        and ph == pytest.approx(0.4, abs=0.02)
    )
    assert np.std(p.residual) == pytest.approx(0.1, rel=0.05)
    assert abs(np.mean(p.residual)) < 0.01


def test_known_frequency_and_line_only():
    t, x = record(amp=0.0)
    p = prewhiten(x, FS)
    assert p.sine is None and p.line[1] == pytest.approx(-0.02, abs=0.001)
    p = prewhiten(x - 0.3 + 0.02 * t, FS, line=False, sine_hz=5.0)
    assert p.line is None and p.sine[1] < 0.01  # nothing at 5 Hz


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), n_bad=st.integers(1, 6), size=st.floats(8.0, 50.0))
def test_bad_points_are_listed_exactly_and_set_to_the_residual_mean(seed, n_bad, size):
    t, x = record(n=2000, seed=seed, noise=0.1)
    rng = np.random.default_rng(seed + 1)
    idx = np.sort(rng.choice(len(x), n_bad, replace=False))
    signs = rng.choice([-1.0, 1.0], n_bad)
    x[idx] += signs * size * 0.1 * 4  # 32 to 200 sigma
    p = prewhiten(x, FS, sine_hz=7.3)
    found = [i for i, _ in p.outliers]
    assert set(idx.tolist()) <= set(found)
    # A Gaussian record of 2000 points may hold a genuine 4-sigma point or two; no more.
    assert len(found) - n_bad <= 3
    for i, v in p.outliers:
        assert v == x[i]
    assert p.passes >= 2
    good = np.setdiff1d(np.arange(len(x)), found)
    assert np.allclose(p.residual[found], np.mean(p.residual[good]))
    assert np.max(np.abs(p.residual)) < 0.6


def test_without_the_outlier_step_a_spike_would_stay():
    """The test above could fail: a spike left in is far beyond 4 sigma of the residual."""
    t, x = record(n=2000, noise=0.1)
    x[500] += 10.0
    p = prewhiten(x, FS, sine_hz=7.3)
    assert p.outliers[0] == (500, x[500]) and abs(p.residual[500]) < 0.5


def test_bad_input_is_named():
    with pytest.raises(ValueError, match="NaN or infinite"):
        prewhiten(np.array([1.0, np.nan, 2.0, 3.0, 4.0]), FS)
    with pytest.raises(ValueError, match="at least 4 samples"):
        prewhiten(np.ones(3), FS)
    with pytest.raises(ValueError, match="sample rate"):
        prewhiten(np.ones(10), 0.0)
