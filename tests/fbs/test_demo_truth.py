"""The demo's simulated truths (``fbs.demo_truth``) against closed forms."""

from __future__ import annotations

import math

import pytest

from fbs.demo_truth import baseline_truths, drift_on_the_float_urad2
from simhw.config import SimConfig


def _rig(arw: float) -> SimConfig:
    cfg = SimConfig()
    for g in cfg.gyro.values():
        g.arw_urad_per_sqrt_s = arw
        g.bias_instability_urad_per_s = 0.0
        g.rrw_urad_per_s_per_sqrt_s = 0.0
    return cfg


def test_the_float_integrates_the_angle_random_walk_into_the_pickoffs_band():
    """Far above the caging loop (0.1 rad/s) and the float's restraint (1/424 s) the float angle
    is the drift rate integrated: an angle random walk N (one-sided rate PSD 2 N^2) gives
    2 N^2 / (2 pi f)^2, so 2 N^2 (1/lo - 1/hi) / (4 pi^2) over lo..hi - times what the X-Y
    gyro's viscous coupling (II C.4.d) makes of it: sigma_X' = (w_X + k_Y w_Y) / (1 + k_X k_Y),
    k = 1 / (h/c), so (1 + k_Y^2) / (1 + k_X k_Y)^2 for two drifts alike (0.955 here)."""
    n = 0.5
    cfg = _rig(n)
    kx, ky = (1.0 / cfg.gyro[c].viscous_coupling_h_over_c for c in ("X", "Y"))
    closed = 2 * n * n * (1.0 - 1.0 / 50.0) / (4 * math.pi**2) * (1 + ky**2) / (1 + kx * ky) ** 2
    assert drift_on_the_float_urad2(cfg, "X", 1.0, 50.0) == pytest.approx(closed, rel=0.005)
    assert drift_on_the_float_urad2(_rig(0.0), "X", 1.0, 50.0) == 0.0


def test_the_baselines_pickoff_rms_counts_the_drift_the_pickoff_shows():
    """Issue 38 item 5's pickoff rms: the record is made with the gyros spinning, so the truth is
    the pickoff's noise and the gyro's drift on the float (a drawn rig with N = 0.5 read 2.2 %
    above the pickoff's noise alone, 3.9 of its standard errors)."""
    quiet, loud = (baseline_truths(_rig(n), "X")["pickoff_rms_urad"] for n in (0.0, 0.5))
    for band in ("1-50 Hz", "0.1-200 Hz"):
        assert loud[band].value > quiet[band].value
    extra = loud["1-50 Hz"].value ** 2 - quiet["1-50 Hz"].value ** 2
    assert extra == pytest.approx(drift_on_the_float_urad2(_rig(0.5), "X", 1.0, 50.0), rel=1e-9)
    assert quiet["0.1-200 Hz"].value == pytest.approx(SimConfig().gyro["X"].pickoff_noise_rms_urad)
