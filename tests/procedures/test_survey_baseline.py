"""The survey's platform rms net of the baseline's pickoff noise (issue 22 part 6): the gyro's
0.4-15 Hz spectrum less the clamped platform's pickoff spectrum (Ch. V E.2 less Ch. V B, Fig. 33).

(a) the numerics (``baseline_net_rms``) on a generator written here, not simhw: a platform angle
    of known band rms (white noise through a 4 Hz resonance), white pickoff noise and a 71 Hz
    line, and a separate baseline record of the pickoff noise alone;
(b) the baseline file's checks, before anything is recorded;
(c) end to end on one drawn sim rig: baseline, then survey with the baseline found as
    ``fbs run`` finds it (the prior summary's run file), against the simulator's true rms.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import scipy.signal

from daq.runfile import RunWriter
from procedures.analysis.baseline import array_blocks
from procedures.analysis.survey import baseline_net_rms
from procedures.calibrations.baseline import BaselineFileError
from procedures.calibrations.survey import Params, Survey
from procedures.params import find_prior, parse_params
from tests.result_schema import assert_valid_result

FS = 200.0
KG = 6.03e-3  # V/urad
BAND = (0.4, 15.0)
RMS_TOL = 0.20


# ---------------------------------------------------------------------------- (a) the generator
def _resonance(f0: float = 4.0, zeta: float = 0.3):
    w0 = 2 * math.pi * f0
    return scipy.signal.bilinear([w0 * w0], [1, 2 * zeta * w0, w0 * w0], FS)


B, A = _resonance()
_W, _H = scipy.signal.freqz(B, A, worN=200_000, fs=FS)
_SEL = (_W >= BAND[0]) & (_W <= BAND[1])
#: band variance (urad^2) of the filter's output for unit-variance white input (one-sided PSD 2/fs |H|^2)
UNIT_BAND_VAR = float(np.trapezoid(np.abs(_H[_SEL]) ** 2 * 2 / FS, _W[_SEL]))


def _draw(
    rng, platform_rms: float, noise_rms: float, survey_s: float = 300.0, baseline_s: float = 480.0
):
    """One survey record (platform + pickoff noise + a 71 Hz line) and one baseline record (the
    pickoff alone), in volts; ``platform_rms`` and ``noise_rms`` are the band's (urad)."""
    sigma_p = platform_rms / math.sqrt(UNIT_BAND_VAR)
    sigma_n = math.sqrt(noise_rms**2 / (BAND[1] - BAND[0]) * FS / 2)  # white: one-sided PSD * fs/2
    ns, nb = int(survey_s * FS), int(baseline_s * FS)
    theta = scipy.signal.lfilter(B, A, rng.standard_normal(ns + 2000) * sigma_p)[2000:]

    def line(n: int) -> np.ndarray:
        return 3.0 * np.sin(2 * math.pi * 71.0 * np.arange(n) / FS + rng.uniform(0, 2 * math.pi))

    survey = (theta + sigma_n * rng.standard_normal(ns) + line(ns)) * KG
    baseline = (sigma_n * rng.standard_normal(nb) + line(nb)) * KG
    s = array_blocks(survey[:, None], FS, ("gyro_x",), 8.0, 8)
    b = array_blocks(baseline[:, None], FS, ("gyro_x",), 8.0, 8)
    return baseline_net_rms(s, "gyro_x", b, "gyro_x", KG, *BAND)


def test_generator_net_rms_within_20_percent_and_its_interval_covers():
    """The X rig's proportions (docs/procedures/survey.md: 0.44 urad true, 1.19 urad pickoff noise
    in the band): 400 draws; measured 392 of 400 within 20 %, 381 of 400 intervals covering."""
    rng = np.random.default_rng(22)
    n, within, cover = 400, 0, 0
    for _ in range(n):
        e = _draw(rng, 0.45, 1.2).estimate
        assert e.resolved, e
        within += abs(e.value / 0.45 - 1) < RMS_TOL
        cover += e.covers(0.45)
    print(f"within 20 %: {within} of {n}; intervals covering: {cover} of {n}")
    assert within >= 0.97 * n
    assert 0.92 * n <= cover <= 0.98 * n  # 95 % nominal; +-2.7 binomial sigma


def test_generator_without_platform_motion_is_unresolved_and_covers_zero():
    """Measured: 99 of 100 unresolved (97 not above zero, 2 wider than their value), 97 covering 0."""
    rng = np.random.default_rng(23)
    got = [_draw(rng, 0.0, 1.2).estimate for _ in range(100)]
    unresolved = sum(not e.resolved for e in got)
    cover = sum(e.lo <= 0.0 for e in got)
    print(f"no motion: {unresolved} of 100 unresolved, {cover} covering zero")
    assert unresolved >= 93 and cover >= 93
    assert all(e.value is not None and 0.0 <= e.lo <= e.hi for e in got)


# ---------------------------------------------------------------------------- (b) the file's checks
def _fake_run(path, procedure, channels=("gyro_x", "gyro_y")):
    with RunWriter(
        path,
        rig="test",
        mode=3,
        rate_hz=100.0,
        channels=dict.fromkeys(channels, "V"),
        procedure=procedure,
        axis="X",
    ) as w:
        w.append({c: np.zeros(100) for c in channels})
    return path


def test_a_bad_baseline_file_is_refused_by_name_before_anything_is_recorded(tmp_path):
    cases = [
        (tmp_path / "missing.h5", "no such file"),
        (tmp_path / "notes.txt", "not a readable fbs-run file"),
        (_fake_run(tmp_path / "survey.h5", "survey"), "a 'survey' run, not a 'baseline' run"),
        (
            _fake_run(tmp_path / "baseline.h5", "baseline"),
            "holds no completed 'clamped record' step",
        ),
    ]
    (tmp_path / "notes.txt").write_text("not HDF5")
    for path, why in cases:
        # a missing file is refused by the parameter's declared limit (an existing regular file),
        # the rest by reading it
        with pytest.raises(ValueError) as exc:
            Params(baseline_file=str(path))
        text = str(exc.value)
        if path.exists():
            assert isinstance(exc.value, BaselineFileError)
            assert f"survey: baseline_file {str(path)!r}" in text and why in text, text
        else:
            assert (
                f"survey: baseline_file = {str(path)!r} must be" in text and why in text.lower()
            ), text
        # `fbs run survey --param baseline_file=...` refuses it the same way (a ValueError: exit 2)
        with pytest.raises(ValueError, match="baseline_file"):
            parse_params(Survey, [f"baseline_file={path}"], None)


def test_an_unusable_prior_baseline_is_left_out_with_the_reason(tmp_path):
    s = Survey(prior={"baseline": {"_file": str(tmp_path / "gone.h5")}})
    rec, why = s.find_baseline()
    assert rec is None and "prior baseline" in why and "no such file" in why
    rec, why = Survey().find_baseline()
    assert rec is None and "no baseline run given" in why


# ---------------------------------------------------------------------------- (c) the sim rig
@pytest.mark.slow
def test_baseline_then_survey_on_one_drawn_rig_nets_the_true_platform_rms(tmp_path):
    """A drawn gyro-X pickoff noise (the data sheet's lines for it, 85 % of its variance, out of
    band). Measured (seed 2260): X 0.445 [0.423, 0.467] against the simulator's true 0.432
    (+3.0 %; the thesis method 0.674); Y 0.637 [0.524, 0.732] against 0.579. (With the old
    default lines, 4.4 urad rms, Y's pickoff noise had ~30x the platform's power and was not
    resolved; over six such rigs X read 0.87-1.03 of the truth, 4 of 6 intervals covering,
    docs/procedures/survey.md.)"""
    from drivers.rig import open_rig
    from procedures.calibrations.baseline import Baseline
    from procedures.calibrations.baseline import Params as BaselineParams
    from procedures.runner import run_procedure
    from simhw.config import load_config, nominal_pickoff_lines

    from .test_survey import expected_values

    rng = np.random.default_rng(2260)
    noise_x = round(float(rng.uniform(4.8, 5.6)), 3)  # 0.1-200 Hz; the lines hold 85 % of its rms^2
    cfg_path = tmp_path / "cfg.toml"
    cfg_path.write_text(
        f"[gyro.X]\npickoff_noise_rms_urad = {noise_x}\npickoff_lines = {nominal_pickoff_lines(noise_x)!r}\n"
    )
    out = tmp_path / "out"
    params = Params()
    with open_rig(f"sim?warm=1&seed=50&config={cfg_path}") as rig:
        b = run_procedure(
            Baseline(BaselineParams(axis="X", settle_s=5.0, record_s=320.0)), rig, out, report=False
        )
        assert b.exit_code == 0, b.error
        prior = find_prior(out)  # as `fbs run survey --out` finds it: the summary's run file
        assert prior["baseline"]["_file"] == str(b.file)
        s = run_procedure(Survey(params, prior=prior), rig, out)
    assert s.exit_code == 0, s.error
    exp = expected_values(load_config(cfg_path), params, seed=60)
    v = s.values
    assert v["baseline"]["file"] == str(b.file) and v["baseline"]["axis"] == "X"
    net, ci, resolved = (
        v["platform_rms_baseline_net_urad"],
        v["platform_rms_baseline_net_urad_ci95"],
        v["resolved"]["platform_rms_baseline_net_urad"],
    )
    for a in "XY":
        print(
            f"{a}: net of baseline {net[a]} {ci[a]} (resolved {resolved[a]}), "
            f"coherent {v['platform_rms_net_urad'][a]}, "
            f"thesis method {v['platform_rms_urad'][a]:.4g}; true {exp['true_rms_urad'][a]:.4g}"
        )
        assert ci[a][0] <= exp["true_rms_urad"][a] <= ci[a][1]
    assert resolved["X"] and abs(net["X"] / exp["true_rms_urad"]["X"] - 1) < RMS_TOL
    # the JSON `fbs run --json` prints carries it; the report sets the three beside the thesis
    printed = s.json_result(Survey(params))
    assert printed["platform_rms_baseline_net_urad"] == net
    assert_valid_result(printed)
    md = (out / "survey.md").read_text()
    assert "net of the baseline's pickoff noise" in md and "| X | " in md and "| 1.6 |" in md
    assert json.loads((out / "survey.json").read_text())["values"]["baseline"]["file"] == str(
        b.file
    )
    # the same file named as the parameter passes its checks
    assert Params(baseline_file=str(b.file)).baseline_file == str(b.file)
