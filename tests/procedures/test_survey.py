"""The ``survey`` procedure (Ch. V E): dip of the autocollimator control spectrum and the
gyro-deduced platform rms, against the simulated rig's own truth.

Acceptance (issue 5 point 6):
A. default sim rig: the dip within 0.3 Hz of sqrt(eta To^2 / I) / 2 pi, the gyro-deduced
   rms within 20 % of sqrt(true^2 + pickoff noise^2) in the same band (0.4-15 Hz); the
   report sets both beside the thesis's 1.6 / 3.6 urad and 3.5 Hz.
B. the same tolerances on sim configs with other bearing (eta, To) and pickoff-noise values.
"""

from __future__ import annotations

import json
import math
import threading

import numpy as np
import pytest

from daq.spectral import band_rms, psd
from procedures.analysis.survey import cross_axis_coherence, find_dip, spans_csd
from procedures.calibrations import catalogue
from procedures.calibrations.survey import Params, Survey, pickoff_scales
from procedures.resume import load_resume
from procedures.runner import run_procedure
from simhw.config import SimConfig, load_config, nominal_pickoff_lines
from simhw.simulator import Simulator, pickoff_white_psd
from tests.result_schema import assert_valid_result

from .conftest import assert_spans_are_the_record_steps

DIP_TOL_HZ = 0.3
RMS_TOL = 0.20


# ---------------------------------------------------------------------------- fast: pieces
def _notch_psd(f, f0, zeta_num=0.02, zeta_den=0.4, slope=1.0):
    """A notch at f0 on a gentle slope: |(s^2 + 2 zn w0 s + w0^2) / (s^2 + 2 zd w0 s + w0^2)|^2."""
    s = 2j * np.pi * f
    w0 = 2 * np.pi * f0
    h = (s * s + 2 * zeta_num * w0 * s + w0 * w0) / (s * s + 2 * zeta_den * w0 * s + w0 * w0)
    return np.abs(h) ** 2 * (1.0 + f) ** slope


@pytest.mark.parametrize("f0", [1.7, 3.85, 6.2, 11.3])
def test_find_dip_locates_a_noisy_notch_below_the_bin_spacing(f0):
    f = np.arange(0, 500, 1 / 16)
    rng = np.random.default_rng(1)
    p = _notch_psd(f, f0) * rng.chisquare(68, f.size) / 68  # a Welch estimate with 68 EDOF
    d = find_dip(f, p, 0.5, 30.0, 0.5)
    assert d is not None
    assert abs(d.freq_hz - f0) < 0.1
    assert d.depth_db > 10


def test_find_dip_reports_no_notch_on_a_sloping_spectrum():
    f = np.arange(0, 500, 1 / 16)
    rng = np.random.default_rng(2)
    p = (1.0 + (f / 8.0) ** 2) ** -1 * rng.chisquare(68, f.size) / 68
    d = find_dip(f, p, 0.5, 30.0, 0.5)
    assert d is None or d.depth_db < 3.0


def test_pickoff_scale_comes_from_the_stopwatch_else_nominal():
    nominal = {"X": 6.03, "Y": 6.70, "Z": 7.51, "XRD": 5.74}
    assert pickoff_scales({}, nominal) == ({"X": 6.03, "Y": 6.70}, {"X": "nominal", "Y": "nominal"})
    prior = {"stopwatch": {"K_g_mV_per_urad": {"X": 7.1, "Y": None, "Z": 7.0, "XRD": 5.0}}}
    assert pickoff_scales(prior, nominal) == (
        {"X": 7.1, "Y": 6.70},
        {"X": "stopwatch", "Y": "nominal"},
    )


def test_procedure_is_catalogued_with_the_design_json_keys():
    assert catalogue()["survey"] is Survey
    # DESIGN.md's keys, and the platform rms net of the baseline's pickoff noise (issue 22 part 6)
    assert Survey.json_keys == (
        "platform_rms_urad",
        "platform_rms_baseline_net_urad",
        "dip_hz",
        "file",
    )
    s = Survey()
    assert s.rate_hz == 1000.0 and s.mode == 3
    assert {"ac_x_ctl", "ac_y_ctl", "gyro_x", "gyro_y"} <= set(s.channels())


def test_params_are_checked():
    with pytest.raises(ValueError, match="band"):
        Params(band_lo_hz=20.0, band_hi_hz=15.0)
    with pytest.raises(ValueError, match="segment"):
        Params(duration_s=10.0, seg_s=16.0)


# ---------------------------------------------------------------------------- truth
def expected_values(cfg: SimConfig, params: Params, seed: int = 11) -> dict:
    """What the survey should find on ``cfg``: the bearing resonance sqrt(eta To^2 / I) / 2 pi,
    and sqrt(true platform rms^2 + pickoff noise rms^2) in the survey's band, the truth from an
    offline simulation of the same config (another noise realization)."""
    lo, hi = params.band_lo_hz, params.band_hi_hz
    sim = Simulator(cfg, rate_hz=params.rate_hz, seed=seed, mode=3, truth=True)
    theta = {a: [] for a in "XY"}
    for block in sim.run(params.duration_s, 10.0):
        for a in "XY":
            theta[a].append(block[f"theta_{a.lower()}"])
    out: dict = {
        "resonance_hz": {},
        "true_rms_urad": {},
        "noise_rms_urad": {},
        "expected_rms_urad": {},
    }
    for a in "XY":
        b = cfg.bearing[a]
        out["resonance_hz"][a] = math.sqrt(
            b.eta_per_Nm * b.To_Nm**2 / cfg.platform[a].inertia_kg_m2
        ) / (2 * math.pi)
        f, p = psd(np.concatenate(theta[a]) * 1e6, params.rate_hz, seg_s=params.seg_s)
        true = band_rms(f, p, lo, hi)
        g = cfg.gyro[a]
        white = pickoff_white_psd(g.pickoff_noise_rms_urad, g.pickoff_lines) * 1e12  # urad^2/Hz
        lines = sum(amp**2 / 2 for fl, amp in g.pickoff_lines if lo <= fl <= hi)
        noise = math.sqrt(white * (hi - lo) + lines)
        out["true_rms_urad"][a], out["noise_rms_urad"][a] = true, noise
        out["expected_rms_urad"][a] = math.hypot(true, noise)
    return out


def check(summary, expected, label=""):
    assert summary.exit_code == 0, (summary.error, [m.to_json() for m in summary.measurements])
    v = summary.json_values(Survey.json_keys)
    assert_valid_result(summary.json_result(Survey()))  # what `fbs run --json` prints (issue 37)
    # without a baseline the net-of-baseline figure is printed unresolved, with why in the summary
    assert set(v) == {
        "platform_rms_urad",
        "platform_rms_baseline_net_urad",
        "platform_rms_baseline_net_urad_ci95",
        "resolved",
        "dip_hz",
        "file",
    }
    assert v["resolved"] == {"platform_rms_baseline_net_urad": {"X": False, "Y": False}}
    lines = [label]
    for a in "XY":
        dip, res = v["dip_hz"][a], expected["resonance_hz"][a]
        rms, exp = v["platform_rms_urad"][a], expected["expected_rms_urad"][a]
        lines.append(
            f"{a}: dip {dip:.3f} Hz vs sqrt(k/I)/2pi {res:.3f} Hz ({dip - res:+.3f}); gyro-deduced "
            f"{rms:.3f} urad vs expected {exp:.3f} (true {expected['true_rms_urad'][a]:.3f}, pickoff noise "
            f"{expected['noise_rms_urad'][a]:.3f}) ratio {rms / exp:.3f}"
        )
    print("\n".join(lines))
    net = summary.values["platform_rms_net_urad"]
    net_ci = summary.values["platform_rms_net_urad_ci95"]
    print(
        "net of pickoff noise: "
        + ", ".join(
            f"{a} {net[a]} {net_ci[a]} vs true {expected['true_rms_urad'][a]:.3f}" for a in "XY"
        )
    )
    for a in "XY":
        assert abs(v["dip_hz"][a] - expected["resonance_hz"][a]) < DIP_TOL_HZ, lines
        assert abs(v["platform_rms_urad"][a] / expected["expected_rms_urad"][a] - 1) < RMS_TOL, (
            lines
        )
        # issue 22 D: the platform's own rms, net of pickoff noise, within 20 % of the truth
        assert net[a] is not None and abs(net[a] / expected["true_rms_urad"][a] - 1) < RMS_TOL, (
            net,
            expected,
        )
    return v


# ---------------------------------------------------------------------------- slow: the sim rig
@pytest.mark.slow
def test_acceptance_a_default_rig(tmp_path):
    from drivers.rig import open_rig

    params = Params()
    with open_rig("sim?warm=1&seed=3") as rig:
        s = run_procedure(Survey(params), rig, tmp_path)
    check(s, expected_values(SimConfig(), params), "default rig")
    # the JSON summary the CLI prints has exactly the design keys
    saved = json.loads((tmp_path / "survey.json").read_text())
    assert saved["verdict"] == "pass"
    # the report sets the results beside the thesis's figures, and says the Kg was nominal
    md = (tmp_path / "survey.md").read_text()
    assert "| 1.6 | 3.6 |" in md and "| 3.5 |" in md
    assert "nominal" in md and "no stopwatch result" in md
    assert (tmp_path / "survey-dip.png").stat().st_size > 10_000
    assert (tmp_path / "survey-coherence-ac_x_ctl-gyro_x.png").exists()


def _random_configs(n: int = 3, seed: int = 20250):
    """Per axis: bearing resonance f and To (so eta = I (2 pi f)^2 / To^2) and the pickoff noise,
    drawn once. In config 1 the true motion matters as much as the pickoff noise: no pickoff
    lines and a low white level. Config 2 has other pickoff scale factors, measured by a
    (pretend) stopwatch run passed as the prior."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        quiet = k == 1
        c = {
            "fX": rng.uniform(2.0, 7.0),
            "fY": rng.uniform(3.5, 11.0),
            "ToX": rng.uniform(0.010, 0.025),
            "ToY": rng.uniform(0.010, 0.025),
            "nX": rng.uniform(0.8, 2.0) if quiet else rng.uniform(5.0, 12.0),
            "nY": rng.uniform(0.8, 2.0) if quiet else rng.uniform(6.0, 20.0),
            "MdX": 0.0,
            "MdY": 0.0,
            "KgX": 7.2 if k == 2 else None,
            "KgY": 5.4 if k == 2 else None,
        }
        out.append(c)
    return out


def _toml(c: dict) -> str:
    inertia = {"X": 0.70, "Y": 0.25}
    parts = []
    for a in "XY":
        f, to = c[f"f{a}"], c[f"To{a}"]
        eta = inertia[a] * (2 * math.pi * f) ** 2 / to**2
        parts.append(f"[bearing.{a}]\nTo_Nm = {to!r}\neta_per_Nm = {eta!r}\n")
        g = f"[gyro.{a}]\npickoff_noise_rms_urad = {c[f'n{a}']!r}\n"
        # the data sheet's lines for that rms (85 % of its variance), none on a quiet pickoff
        lines = [] if c[f"n{a}"] < 4.5 else nominal_pickoff_lines(c[f"n{a}"])
        g += f"pickoff_lines = {lines!r}\n"
        if c[f"Kg{a}"] is not None:
            g += f"pickoff_scale_mV_per_urad = {c[f'Kg{a}']!r}\n"
        parts.append(g)
        if c[f"Md{a}"]:
            parts.append(f"[platform.{a}]\ndisturbance_torque_rms_Nm = {c[f'Md{a}']!r}\n")
    return "\n".join(parts)


@pytest.mark.slow
@pytest.mark.parametrize("k", range(3))
def test_acceptance_b_other_configs(tmp_path, k):
    from drivers.rig import open_rig

    c = _random_configs()[k]
    cfg_path = tmp_path / "cfg.toml"
    cfg_path.write_text(_toml(c))
    cfg = load_config(cfg_path)
    params = Params()
    prior = {}
    if c["KgX"] is not None:
        prior = {
            "stopwatch": {"K_g_mV_per_urad": {"X": c["KgX"], "Y": c["KgY"], "Z": 7.51, "XRD": 5.74}}
        }
    reference = {
        "source": "test reference",
        "platform_rms_urad": {"X": 9.87, "Y": 6.54},
        "dip_hz": {"X": 1.23},
    }
    with open_rig(f"sim?warm=1&seed={20 + k}&config={cfg_path}") as rig:
        s = run_procedure(Survey(params, prior=prior, reference=reference), rig, tmp_path / "out")
    check(s, expected_values(cfg, params, seed=30 + k), f"config {k}: {c}")
    md = (tmp_path / "out" / "survey.md").read_text()
    assert "test reference" in md and "9.87" in md
    if prior:
        assert s.values["pickoff_scale_source"] == {"X": "stopwatch", "Y": "stopwatch"}
        assert "no stopwatch result" not in md


@pytest.mark.slow
def test_an_aborted_survey_resumes_with_the_pieces_already_recorded(tmp_path):
    """Abort during the third piece; the resumed run records only the rest and analyses all
    300 s, the first pieces from the aborted file."""
    from drivers.rig import open_rig

    params = Params()
    stop = threading.Event()

    def listener(progress):
        if progress.step == "record 3/5":
            stop.set()

    with open_rig("sim?warm=1&seed=4") as rig:
        first = run_procedure(Survey(params), rig, tmp_path, progress=listener, abort=stop)
        assert first.verdict == "aborted"
        assert first.steps_done[-2:] == ["record 1/5", "record 2/5"]
        resumed = load_resume(first.file, Survey)
        second = run_procedure(Survey(params), rig, tmp_path, resume=resumed)
    assert second.exit_code == 0, second.error
    assert second.steps_resumed == ["record 1/5", "record 2/5"]
    assert second.values["record_s"] == pytest.approx(300.0)
    check(second, expected_values(SimConfig(), params), "resumed")
    assert_spans_are_the_record_steps(
        first, second, [f"record {i}/5" for i in range(1, 6)], 2, params.piece_s
    )


@pytest.mark.slow
def test_a_platform_disturbance_torque_keeps_the_rms_right_but_moves_the_dip(tmp_path):
    """Limitation (docs/procedures/survey.md): a torque disturbance drives the platform through a
    path with no zero at the bearing resonance, so it fills the notch and the spectrum's minimum
    moves off sqrt(k/I)/2 pi. The gyro-deduced rms still holds; the dip is only printed."""
    from drivers.rig import open_rig

    c = {
        "fX": 3.85,
        "fY": 6.2,
        "ToX": 0.016,
        "ToY": 0.016,
        "nX": 1.5,
        "nY": 1.5,
        "MdX": 1.0e-3,
        "MdY": 0.8e-3,
        "KgX": None,
        "KgY": None,
    }
    cfg_path = tmp_path / "cfg.toml"
    cfg_path.write_text(_toml(c))
    cfg = load_config(cfg_path)
    params = Params()
    with open_rig(f"sim?warm=1&seed=9&config={cfg_path}") as rig:
        s = run_procedure(Survey(params), rig, tmp_path / "out", report=False)
    exp = expected_values(cfg, params, seed=19)
    v = s.values
    for a in "XY":
        print(
            f"{a}: dip {v['dip_hz'][a]} Hz ({v['dip_depth_db'][a]:.1f} dB) vs {exp['resonance_hz'][a]:.3f}; "
            f"rms {v['platform_rms_urad'][a]:.3f} vs {exp['expected_rms_urad'][a]:.3f} "
            f"(true {exp['true_rms_urad'][a]:.3f})"
        )
        assert exp["true_rms_urad"][a] > 2 * exp["noise_rms_urad"][a]  # truth-dominated
        assert abs(v["platform_rms_urad"][a] / exp["expected_rms_urad"][a] - 1) < RMS_TOL


# ---------------------------------------------------------------------------- cross-axis coherence (Fig. 48)
def _two_axis_file(tmp_path, fraction, seed):
    from daq.runfile import RunWriter

    cfg = SimConfig()
    for a in "XY":
        cfg.autocollimator[a].common_noise_fraction = fraction
    chans = ("ac_x_ctl", "ac_y_ctl")
    sim = Simulator(cfg, 1000.0, seed=seed, mode=3, channels=chans)
    for c in chans:
        sim.set_range(c, 1.0)
    path = tmp_path / f"common-{fraction}-{seed}.h5"
    with RunWriter(
        path, rig="sim-offline", mode=3, rate_hz=1000.0, channels=dict.fromkeys(chans, "V")
    ) as w:
        for block in sim.run(128.0, 16.0):
            w.append({c: block[c] for c in chans})
    return path


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_cross_axis_coherence_is_significant_only_with_a_common_noise(tmp_path, seed):

    found = {}
    for fraction in (0.0, 0.5):
        path = _two_axis_file(tmp_path, fraction, seed)
        csd = spans_csd([(path, 0, 128000)], ("ac_x_ctl", "ac_y_ctl"), 8.0)
        found[fraction] = cross_axis_coherence(csd, "ac_x_ctl", "ac_y_ctl")
    assert not found[0.0].significant, found[0.0]
    assert abs(found[0.0].mean / found[0.0].null_mean - 1) < 0.3, found[0.0]
    assert found[0.5].significant and found[0.5].mean > 0.1, found[0.5]


def test_common_noise_fraction_zero_leaves_the_noise_bit_identical():
    """The common stream is spawned after every other: a rig without it draws what it drew before."""
    a = Simulator(SimConfig(), 1000.0, seed=5, mode=3, channels=("ac_x_ctl", "ac_y_ctl"))
    cfg = SimConfig()
    cfg.autocollimator["Y"].common_noise_fraction = 0.3  # X's own streams must not move either
    b = Simulator(cfg, 1000.0, seed=5, mode=3, channels=("ac_x_ctl", "ac_y_ctl"))
    xa, xb = next(a.run(2.0, 2.0)), next(b.run(2.0, 2.0))
    assert np.array_equal(xa["ac_x_ctl"], xb["ac_x_ctl"])
    assert not np.array_equal(xa["ac_y_ctl"], xb["ac_y_ctl"])


@pytest.mark.slow
@pytest.mark.parametrize("mode", [4, 5])
def test_a_survey_in_the_gyro_modes(tmp_path, mode):
    """Issue 22 part 4: a survey in Mode 4 or 5. The loop closes on the pickoff, so its spectrum
    has the dip at the bearing resonance (the sensitivity's zeros are the open-loop platform
    poles), and the out-of-loop autocollimator gives the platform's rms: within 20 % of the
    simulator's true motion in 0.4-15 Hz (another noise realization of the same rig, in the same
    mode). The in-loop gyro's figures net of pickoff noise are reported unresolved, saying why."""
    from drivers.rig import open_rig

    cfg_path = tmp_path / "spring.toml"
    cfg_path.write_text(
        '[bearing.X]\nmodel = "spring"\nstiffness_Nm_per_rad = 520.0\n'
        '[bearing.Y]\nmodel = "spring"\nstiffness_Nm_per_rad = 300.0\n'
        f"[gyro.Y]\npickoff_noise_rms_urad = 9.0\npickoff_lines = {nominal_pickoff_lines(9.0)!r}\n"
    )
    cfg = load_config(cfg_path)
    params = Params(mode=mode, duration_s=200.0, mode_settle_s=40.0)
    with open_rig(f"sim?warm=1&seed={70 + mode}&config={cfg_path}") as rig:
        s = run_procedure(Survey(params), rig, tmp_path)
        assert rig.relays.status().mode == 3  # handed back in Mode 3
    assert s.exit_code == 0, (s.error, [m.to_json() for m in s.measurements])
    v = s.values
    sim = Simulator(cfg, rate_hz=params.rate_hz, seed=5, mode=mode, truth=True)
    theta = {a: [] for a in "XY"}
    for block in sim.run(params.duration_s, 10.0):
        for a in "XY":
            theta[a].append(block[f"theta_{a.lower()}"])
    for a, k in (("X", 520.0), ("Y", 300.0)):
        f, p = psd(np.concatenate(theta[a]) * 1e6, params.rate_hz, seg_s=params.seg_s)
        true = band_rms(f, p, params.band_lo_hz, params.band_hi_hz)
        got = v["platform_rms_autocollimator_urad"][a]
        resonance = math.sqrt(k / cfg.platform[a].inertia_kg_m2) / (2 * math.pi)
        print(
            f"Mode {mode} {a}: autocollimator {got:.3f} urad vs true {true:.3f}; gyro-deduced "
            f"{v['platform_rms_urad'][a]:.3f}; dip {v['dip_hz'][a]} Hz vs {resonance:.3f}"
        )
        assert abs(got / true - 1) < RMS_TOL, (a, got, true)
        assert abs(v["dip_hz"][a] - resonance) < DIP_TOL_HZ, (a, v["dip_hz"][a], resonance)
        assert v["resolved"]["platform_rms_net_urad"][a] is False
    assert "in-loop sensor" in (tmp_path / "survey.md").read_text()
