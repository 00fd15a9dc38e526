"""The clamped-platform (loop-open) state of the simulated rig (Ch. V B): the gimbals held, the
motor drive open, the sensors reading their own noise; a rig never clamped unchanged."""

from __future__ import annotations

import numpy as np
import pytest

from daq.spectral import band_rms, psd
from simhw.config import SimConfig
from simhw.simulator import Simulator


def test_clamp_holds_every_axis_and_the_autocollimator_reads_its_noise():
    cfg = SimConfig()
    sim = Simulator(cfg, rate_hz=1000.0, seed=4, mode=3, truth=True)
    sim.advance(1000)
    sim.set_clamp(True)
    assert sim.clamped and sim.relays.clamped
    b = sim.advance(30000)
    for name in ("theta_x", "theta_y", "theta_z"):
        assert np.ptp(b[name]) == 0.0
    f, p = psd(
        b["ac_x_ctl"] / (cfg.autocollimator["X"].control_scale_mV_per_urad * 1e-3),
        1000.0,
        seg_s=10.0,
    )
    assert band_rms(f, p, 0.1, 100.0) == pytest.approx(cfg.autocollimator["X"].nea_urad, rel=0.1)
    # the network still answers the autocollimator (pa_* reads), the pickoff its own noise
    assert np.std(b["pa_x"]) > 0 and np.std(b["gyro_x"]) > 0


def test_release_gives_the_platform_back_to_the_loops():
    sim = Simulator(rate_hz=500.0, seed=5, mode=3, truth=True)
    sim.set_clamp(True)
    sim.advance(500)
    sim.set_clamp(False)
    assert not sim.clamped
    b = sim.advance(2000)
    assert np.ptp(b["theta_x"]) > 0 and np.all(np.isfinite(b.volts))


def test_a_rig_never_clamped_is_unchanged_by_a_release_request():
    a = Simulator(rate_hz=500.0, seed=6, mode=3, truth=True)
    b = Simulator(rate_hz=500.0, seed=6, mode=3, truth=True)
    b.set_clamp(False)  # already released: nothing happens
    ba, bb = a.advance(1500), b.advance(1500)
    assert np.array_equal(ba.volts, bb.volts) and np.array_equal(ba["theta_x"], bb["theta_x"])


def test_the_reduced_simulator_clamps_alike():
    full = Simulator(rate_hz=500.0, seed=8, mode=3)
    part = Simulator(rate_hz=500.0, seed=8, mode=3, channels=("ac_x_ctl", "gyro_x"))
    for s in (full, part):
        s.advance(250)
        s.set_clamp(True)
    bf, bp = full.advance(1000), part.advance(1000)
    assert np.array_equal(bf["ac_x_ctl"], bp["ac_x_ctl"]) and np.array_equal(
        bf["gyro_x"], bp["gyro_x"]
    )
