"""The ``baseline`` procedure (thesis Ch. V B, Figs. 32-34, Table 1) end to end on the simulated
rig, through the drivers, against sim configs whose autocollimator noise, 1/f corner, azimuth
noise and pickoff lines are drawn here and published nowhere the procedure looks (issue 22,
acceptance B): the autocollimator NEA within 10 % of the simulated, its interval covering it;
the lines found where the rig has them; the clamp released on every way out.

The simulated NEA is what the sim rig's noise sources really make in 0.1-100 Hz through the
channel's filter (``Sources.spectrum``; since issue 38 the 1/f bank follows 1/f to 100 Hz, so
this is the nominal ``nea_urad``, which Table 1's definition sets, to rounding). The analysis alone is tested on
independently generated data in ``tests/procedures/analysis/test_baseline.py``.
"""

from __future__ import annotations

import math
import threading

import numpy as np
import pytest

from daq.reader import RunFile
from drivers.errors import PlatformClamped
from drivers.rig import open_rig
from drivers.rig_datasheet import AutocollimatorConstants
from procedures.analysis.baseline import NEA_BAND_HZ, nea_truth
from procedures.analysis.transfer import sensor_filter
from procedures.calibrations import catalogue, get
from procedures.calibrations.baseline import Baseline, Params
from procedures.procedure import Verdict
from procedures.runner import run_procedure
from simhw.config import load_config
from simhw.simulator import Simulator
from tests.result_schema import assert_valid_result

#: shorter than the defaults (a lab's), long enough for the tolerances
FAST = {"settle_s": 5.0, "record_s": 320.0}


def _config(tmp_path, axis, nea, corner, nea_z, f71):
    tmp_path.mkdir(parents=True, exist_ok=True)
    lines = [
        [f71, 3.0],
        [round(f71 + 0.8, 3), 3.0],
        [round(f71 + 31.2, 3), 4.0],
        [round(f71 + 116.3, 3), 2.0],
    ]
    text = [
        f"[autocollimator.{axis}]",
        f"nea_urad = {nea}",
        f"flicker_corner_hz = {corner}",
        "[azimuth]",
        f"nea_urad = {nea_z}",
        f"[gyro.{axis}]",
        f"pickoff_lines = {lines}",
    ]
    path = tmp_path / "drawn.toml"
    path.write_text("\n".join(text) + "\n")
    return path, [ln[0] for ln in lines]


def simulated_nea(cfg, axis: str, channel: str, rate_hz: float = 1000.0) -> float:
    """The NEA (urad) the sim rig's sources make on ``channel`` in 0.1-100 Hz."""
    sim = Simulator(cfg, rate_hz=rate_hz, mode=1, spin=0.0)
    f = np.geomspace(*NEA_BAND_HZ, 6000)
    name = "nac_Z" if channel == "ac_z" else f"nac_{axis}"
    angle = sum(sim.sources.spectrum(name, f).values()) * 1e12  # urad^2/Hz
    if channel == "ac_z":
        return nea_truth(f, angle, np.ones_like(f))
    ac = cfg.autocollimator[axis]
    h = sensor_filter(
        f,
        AutocollimatorConstants(
            ac.control_scale_mV_per_urad,
            ac.inst_scale_mV_per_urad,
            ac.control_filter_rad_per_s,
            ac.control_filter_zeta,
            ac.inst_filter1_rad_per_s,
            ac.inst_filter2_rad_per_s,
            ac.inst_filter2_zeta,
        ),
        channel,
    )
    return nea_truth(f, angle, np.abs(h) ** 2)


def test_baseline_is_in_the_catalogue_and_checks_its_parameters():
    assert catalogue()["baseline"] is Baseline and get("baseline") is Baseline
    with pytest.raises(ValueError, match="0.1 Hz"):
        Params(seg_s=20.0)
    with pytest.raises(ValueError, match="n_blocks"):
        Params(record_s=100.0)
    with pytest.raises(ValueError, match="anti-alias"):
        Params(rate_hz=250.0)
    with pytest.raises(ValueError, match="axis"):
        Params(axis="Z")


def test_baseline_measures_the_drawn_noise_and_releases_the_clamp(tmp_path):
    """Three drawn rigs (X, Y, X): every NEA within 10 % of the simulated; the nine 95 %
    intervals cover it but for at most one (chance alone misses two or more 7 % of the time)."""
    misses = []
    for k, axis in enumerate("XYX"):
        rng = np.random.default_rng(2230 + k)
        nea = round(float(rng.uniform(0.3, 0.9)), 4)
        corner = round(float(rng.uniform(1.0, 5.0)), 3)
        nea_z = round(float(rng.uniform(1.5, 4.0)), 3)
        f71 = round(float(rng.uniform(70.2, 71.0)), 3)
        path, true_lines = _config(tmp_path / str(k), axis, nea, corner, nea_z, f71)
        cfg = load_config(path)
        with open_rig(f"sim?warm=1&seed={40 + k}&config={path}") as rig:
            s = run_procedure(
                Baseline(Params(axis=axis, **FAST)), rig, tmp_path / str(k) / "out", report=False
            )
            st = rig.relays.status()
            assert s.verdict is Verdict.PASS, s.error
            # what `fbs run --json` prints (issue 37)
            assert_valid_result(s.json_result(Baseline(Params(axis=axis))))
            assert (
                not st.clamped and st.mode == 3
            )  # released; left in mode 3 as its last step left it
        v = s.values
        a = axis.lower()
        for key, ch in (("ctl", f"ac_{a}_ctl"), ("inst", f"ac_{a}_inst"), ("z", "ac_z")):
            truth = simulated_nea(cfg, axis, ch)
            lo, hi = v["nea_urad_ci95"][key]
            assert v["resolved"]["nea_urad"][key]
            assert v["nea_urad"][key] == pytest.approx(truth, rel=0.10), (
                k,
                key,
                v["nea_urad"][key],
                truth,
            )
            if not lo <= truth <= hi:
                misses.append((k, key, lo, truth, hi))
        assert v["nea_urad"]["ctl"] == pytest.approx(
            nea, rel=0.10
        )  # acceptance B, against the parameter
        # the corner over the knee forms a nominal unit allows (issue 38 item 5): within 30 % when
        # resolved, else its interval holds it (a 320 s record often cannot tell the forms apart)
        lo, hi = v["flicker_corner_hz_ci95"]["ctl"]
        if v["resolved"]["flicker_corner_hz"]["ctl"]:
            assert v["flicker_corner_hz"]["ctl"] == pytest.approx(corner, rel=0.3)
        else:
            assert v["flicker_corner_hz"]["ctl"] is None and lo <= corner <= hi
        found = v["pickoff_lines_hz"]
        assert len(found) == len(true_lines)
        for fl, tl in zip(found, sorted(true_lines)):
            assert abs(fl - tl) < 0.01
        with RunFile(s.file) as rf:
            texts = [e.text for e in rf.events if e.kind == "clamp"]
            assert rf.status == "complete"
        assert texts == ["platform clamped, loops open", "platform released, loops closed"]
    assert len(misses) <= 1, misses


def test_an_abort_mid_record_releases_the_clamp_and_leaves_the_rig_safe(tmp_path):
    abort = threading.Event()

    def progress(pr):
        if pr.step == "clamped record" and pr.fraction > 0.5:
            abort.set()

    with open_rig("sim?warm=1&seed=7") as rig:
        s = run_procedure(
            Baseline(Params(settle_s=2.0, record_s=320.0)),
            rig,
            tmp_path,
            abort=abort,
            progress=progress,
        )
        st = rig.relays.status()
        assert s.verdict is Verdict.ABORTED and s.status.startswith("aborted")
        assert not st.clamped and st.mode == 1 and rig.is_safe()
    with RunFile(s.file) as rf:
        assert rf.status.startswith("aborted")
        assert [e.text for e in rf.events if e.kind == "clamp"][
            -1
        ] == "platform released, loops closed"


def test_a_procedure_that_needs_the_loops_refuses_a_clamped_rig(tmp_path):
    with open_rig("sim?warm=1&seed=8") as rig:
        rig.clamp()
        s = run_procedure(
            get("survey")(get("survey").Params(duration_s=20.0, seg_s=4.0, coherent_seg_s=2.0)),
            rig,
            tmp_path,
        )
        assert s.verdict is Verdict.ABORTED
        assert "platform clamped" in (s.error or "") and "fbs clamp off" in (s.error or "")
        assert rig.relays.status().clamped  # nothing moved the clamp, not even the safe state
        assert math.isfinite(rig.now())
    assert PlatformClamped.__doc__
