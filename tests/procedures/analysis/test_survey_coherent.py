"""``survey.coherent_platform_rms`` against the true platform angle of an offline run (issue 38
acceptance A, found by ``bench/coverage_all.py``): on a drawn rig the platform rms "net of
pickoff noise" of the Y axis read 5-13 % low on three rigs of seven, its interval +-4 %. The Y
axis moves with the X autocollimator's noise too (the rig's cross-axis coupling), which is not
coherent with Y's own autocollimator; every axis's autocollimator is now an input (the multiple
coherence). The rig below is that drawn rig's, reduced to the sections that make the effect:
one input read Y 10.5 % low on it."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import welch

from daq.reader import RunFile
from fbs.cli import main as cli
from procedures.analysis.survey import coherent_platform_rms
from procedures.analysis.transfer import block_csd

RIG = """
[platform.X]
inertia_kg_m2 = 0.5493
[bearing.Y]
model = "viscous"
damping_Nms = 0.0674
[autocollimator.X]
nea_urad = 0.489
common_noise_fraction = 0.396
flicker_corner_hz = 3.858
flicker_knee = 0.781
flicker_slope = 1.043
[autocollimator.Y]
nea_urad = 0.548
common_noise_fraction = 0.396
flicker_corner_hz = 3.858
flicker_knee = 0.781
flicker_slope = 1.043
"""
KG_MV = {"X": 6.03, "Y": 6.70}  # the data sheet's pickoff scales (the rig keeps them)
BAND = (0.4, 15.0)


@pytest.mark.slow
def test_the_coherent_platform_rms_holds_the_motion_the_other_axis_makes(tmp_path):
    cfg = tmp_path / "rig.toml"
    cfg.write_text(RIG)
    path = tmp_path / "m3.h5"
    argv = ["simulate", "--mode", "3", "--duration", "520", "--rate", "1000", "--truth"]
    assert cli([*argv, "--seed", "5", "--sim-config", str(cfg), "--out", str(path)]) == 0
    with RunFile(path) as rf:
        theta = dict(zip("XY", rf.read(["theta_x", "theta_y"])))
        n, fs = len(theta["X"]), rf.rate_hz
    inputs = ["ac_x_inst", "ac_y_inst"]
    for axis in "XY":
        gyro = f"gyro_{axis.lower()}"
        blocks = block_csd([(path, 0, n)], [gyro, *inputs], 8.0, 8)
        e = coherent_platform_rms(blocks, gyro, inputs, KG_MV[axis] * 1e-3, *BAND)
        f, p = welch(theta[axis] / 1e-6, fs, nperseg=int(8 * fs))
        band = (f >= BAND[0]) & (f <= BAND[1])
        true = float(np.sqrt(np.sum(p[band]) * (f[1] - f[0])))
        assert e.resolved and e.lo <= true <= e.hi, (axis, e, true)
        assert e.value == pytest.approx(true, rel=0.04), (axis, e, true)
