"""The ``hysteresis`` procedure and ``fbs analyze hysteresis`` (thesis Ch. V F).

Acceptance (issue 5 point 5):
A. against the default simulated rig, To within 10 %, eta within 25 %, stiffness within 10 %
   of eta To^2 (sim defaults: X To 0.016 N m, eta 1.6e6 /N m);
B. the same tolerances against sim configs with other (To, eta), drawn at random.
Issue 18: at the thesis's defaults eta and the stiffness within 1 % with the angle's lag
measured by the procedure (on the record, never typed in); every figure with its 95 % interval
and resolved verdict. The intervals' coverage over seeds and random bearings is measured by
``bench/hysteresis_coverage.py`` (too slow for the suite).
No thesis constant in the procedure: every instrument constant from ``rig.calibration`` (or
the file's ``/meta/calibration``), which the fast tests vary.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import math
import time

import numpy as np
import pytest

from daq.reader import RunFile
from daq.runfile import RunWriter
from drivers.rig_datasheet import AutocollimatorConstants, PlatformConstants, RigCalibration
from fbs import analyze
from procedures.analysis import dahl
from procedures.analysis.hysteresis import analyze_file, calibration_from_meta
from procedures.calibrations import catalogue
from procedures.calibrations.hysteresis import Hysteresis, Params
from procedures.reports.hysteresis import (
    plot_describing_function,
    plot_history,
    plot_loops,
    plot_scan,
)
from tests.result_schema import assert_valid_result

TO_TOL, ETA_TOL, K_TOL = 0.10, 0.25, 0.10
#: issue 18 acceptance B: eta and the stiffness within 1 % at the thesis's defaults, the lag measured
THESIS_TOL = 0.01
#: the synthetic files' instrumentation lag (s)
LAG_S = 2.5e-3


# ---------------------------------------------------------------------------- synthetic run files
#: a rig unlike the thesis's in every constant the analysis uses
ODD_CAL = RigCalibration(
    platform={
        "X": PlatformConstants(1.3, 0.8, 250.0, 0.61, 0.61, 19.0),
        "Y": PlatformConstants(0.4, 0.3, 120.0, 0.5, 0.5, 25.0),
        "Z": PlatformConstants(0.5, 0.5, 300.0, 0.5, 0.5, 23.0),
    },
    autocollimator={"X": AutocollimatorConstants(4.2, 3.9), "Y": AutocollimatorConstants(6.5, 6.1)},
)


def write_sweep(
    path,
    *,
    To=0.012,
    eta=2.2e6,
    cal: RigCalibration | None = ODD_CAL,
    axis="X",
    fs=400.0,
    f0=0.4,
    amplitudes_urad=(500, 200, 60, 20, 6),
    cycles=5,
    lead_s=2.0,
    noise_Nm=0.0,
    seed=0,
    meta_cal=True,
    nan_at=None,
    channels=None,
    lag_s=LAG_S,
    updates=100,
):
    """A run file as the rig would record it, from Dahl's model on a known platform: the angle
    a ladder of sines, the power-amplifier input what drives it (bearing + viscous + inertia).
    The command is a DAC staircase of ``updates`` steps a cycle (0: a smooth sine) and the
    platform carries a small ripple of it; the recorded angle lags the true one by ``lag_s``."""
    c = cal or RigCalibration()
    p, ac = c.platform[axis], c.autocollimator[axis]
    n_per = int(round(fs / f0))
    t = np.arange(n_per * cycles * len(amplitudes_urad)) / fs
    amp = np.repeat(np.asarray(amplitudes_urad, float) * 1e-6, n_per * cycles)
    w = 2 * math.pi * f0
    lead = np.zeros(int(lead_s * fs))
    smooth = np.concatenate([lead, amp * np.sin(w * t)])
    if updates:
        k = np.floor(t * f0 * updates)
        stair = np.concatenate([lead, amp * np.sin(2 * math.pi * (k + 0.5) / updates)])
        ripple = 2e-3 * dahl.lowpass(
            stair - smooth, fs, 60.0
        )  # the platform's small answer to the steps
    else:
        stair, ripple = smooth, np.zeros_like(smooth)
    theta = smooth + ripple
    omega = np.gradient(theta) * fs
    alpha = np.gradient(omega) * fs
    T = dahl.dahl_torque(theta, To, eta)
    rng = np.random.default_rng(seed)
    pa = (
        T + p.viscous_Nms * omega + p.inertia_kg_m2 * alpha + noise_Nm * rng.standard_normal(len(T))
    ) / p.torque_per_pa_V + 1e-4  # an amplifier offset
    seen = dahl.shift(theta, fs, -lag_s)  # the instrumentation channel's lag
    a = axis.lower()
    cols = {
        f"cmd_{a}": -stair / 1e-6 * ac.control_mV_per_urad * 1e-3,
        f"ac_{a}_inst": seen / 1e-6 * ac.inst_mV_per_urad * 1e-3 + 0.02,  # an autocollimator offset
        f"pa_{a}": pa,
    }
    if nan_at is not None:
        cols[f"pa_{a}"][nan_at] = np.nan
    if channels is not None:
        cols = {k: v for k, v in cols.items() if k in channels}
    meta = {"calibration": dataclasses.asdict(c)} if meta_cal else {}
    with RunWriter(
        path,
        rig="synthetic",
        mode=3,
        rate_hz=fs,
        channels=dict.fromkeys(cols, "V"),
        axis=axis,
        meta=meta,
    ) as wr:
        wr.append(cols)
    return path


# ---------------------------------------------------------------------------- fast: analysis of a file
def test_analysis_recovers_the_model_with_the_files_own_calibration(tmp_path):
    """Constants from /meta/calibration, none of them the thesis's: To and eta come back."""
    path = write_sweep(tmp_path / "sweep.h5", noise_Nm=2e-4)
    res = analyze_file(path, "X")
    assert res.calibration_source == "file"
    assert res.To_Nm == pytest.approx(0.012, rel=0.01)
    assert res.eta_per_Nm == pytest.approx(2.2e6, rel=0.03)
    assert res.stiffness_Nm_per_rad == pytest.approx(2.2e6 * 0.012**2, rel=0.03)
    assert res.frequency_hz == pytest.approx(0.4, rel=1e-5)
    assert [round(lp.amplitude_urad) for lp in res.loops] == [500, 200, 60, 20, 6]
    assert all(lp.n_cycles == 4 for lp in res.loops)
    assert res.relative_residual < 0.05
    # the measured describing function follows eq. 5.12 (the angle here is a pure sine)
    for lp in res.loops:
        assert abs(lp.describing_Nm_per_rad - lp.model_describing_Nm_per_rad) < 0.05 * abs(
            lp.model_describing_Nm_per_rad
        )
    assert res.lag_source == "measured" and res.angle_lag_s == pytest.approx(LAG_S, abs=0.05e-3)
    assert res.lag is not None and res.lag.frequencies_hz[0] == pytest.approx(40.0, abs=0.5)
    for key, true in (
        ("To_Nm", 0.012),
        ("eta_per_Nm", 2.2e6),
        ("stiffness_Nm_per_rad", 2.2e6 * 0.012**2),
    ):
        assert res.estimates[key].resolved and res.estimates[key].covers(true), (
            key,
            res.estimates[key],
        )


def test_the_lag_is_measured_not_assumed(tmp_path):
    """The instrumentation lag (not in the data sheet) is measured on the record and taken
    out: files lagging by 1 and 4 ms give the same To and eta. Left in (a given lag of 0), a
    4 ms lag biases eta high. A smooth command (no DAC lines) has the lag fitted with To and
    eta (issue 38 item 7; it had been left unmeasured and every figure unresolved)."""
    res = {
        lag: analyze_file(write_sweep(tmp_path / f"l{lag}.h5", lag_s=lag, noise_Nm=1e-4), "X")
        for lag in (1e-3, 4e-3)
    }
    for lag, r in res.items():
        assert r.angle_lag_s == pytest.approx(lag, abs=0.05e-3) and r.angle_lag_se_s < 0.05e-3
        assert r.eta_per_Nm == pytest.approx(2.2e6, rel=THESIS_TOL)
    raw = analyze_file(tmp_path / "l0.004.h5", "X", angle_lag_s=0.0)
    assert raw.lag_source == "given" and raw.eta_per_Nm > 1.02 * res[4e-3].eta_per_Nm
    smooth = analyze_file(write_sweep(tmp_path / "smooth.h5", updates=0, noise_Nm=1e-4), "X")
    assert smooth.lag_source == "fitted" and smooth.angle_lag_s == pytest.approx(LAG_S, abs=0.3e-3)
    assert smooth.eta_per_Nm == pytest.approx(2.2e6, rel=0.02)
    v = smooth.values()
    assert v["resolved"] == {
        k: {"X": True} for k in ("To_Nm", "eta_per_Nm", "stiffness_Nm_per_rad")
    }


def test_analysis_uses_the_calibration_it_is_given_over_the_files(tmp_path):
    """The torque scale is the data sheet's Kp Km / Ra: a calibration with twice that gain
    doubles To and halves eta (eta To^2 doubles). Nothing is a hidden constant."""
    path = write_sweep(tmp_path / "sweep.h5")
    base = analyze_file(path, "X")
    p = ODD_CAL.platform["X"]
    doubled = dataclasses.replace(
        ODD_CAL,
        platform=ODD_CAL.platform
        | {
            "X": dataclasses.replace(
                p,
                amp_gain=2 * p.amp_gain,
                damping_Nms=2 * p.damping_Nms + p.motor_Nm_per_A * p.back_emf_V_s / p.armature_ohm,
                inertia_kg_m2=2 * p.inertia_kg_m2,
            )
        },
    )
    assert doubled.platform["X"].viscous_Nms == pytest.approx(2 * p.viscous_Nms)
    res = analyze_file(path, "X", doubled)
    assert res.calibration_source == "given"
    assert res.To_Nm == pytest.approx(2 * base.To_Nm, rel=2e-3)
    assert res.eta_per_Nm == pytest.approx(base.eta_per_Nm / 2, rel=2e-3)


def test_a_file_without_calibration_falls_back_to_the_data_sheet_with_a_warning(tmp_path, caplog):
    path = write_sweep(tmp_path / "sweep.h5", cal=None, meta_cal=False)
    with caplog.at_level(logging.WARNING):
        res = analyze_file(path, "X")
    assert res.calibration_source == "defaults"
    assert any("no rig calibration" in r.getMessage() for r in caplog.records)
    assert res.warnings and res.To_Nm == pytest.approx(0.012, rel=0.01)


def test_calibration_from_meta_round_trips_and_ignores_unknown_keys():
    data = dataclasses.asdict(ODD_CAL)
    data["platform"]["X"]["future_key"] = 1.0
    data["new_section"] = {}
    assert calibration_from_meta(data) == ODD_CAL
    assert calibration_from_meta({}) is None and calibration_from_meta(None) is None
    with pytest.raises(ValueError, match="not a rig calibration"):
        calibration_from_meta({"platform": {"X": {"inertia_kg_m2": 1.0}}})


def test_y_axis_file(tmp_path):
    path = write_sweep(tmp_path / "y.h5", axis="Y", To=0.02, eta=1.0e6)
    res = analyze_file(path, "y")
    assert res.axis == "Y" and res.To_Nm == pytest.approx(0.02, rel=0.01)


@pytest.mark.parametrize(
    "kw, axis, match",
    [
        ({}, "Q", "unknown axis"),
        ({}, "Z", "no instrumentation autocollimator"),
        ({}, "Y", r"no channel\(s\) cmd_y, ac_y_inst, pa_y"),
        ({"channels": ("cmd_x", "ac_x_inst")}, "X", r"no channel\(s\) pa_x"),
        ({"cycles": 2, "amplitudes_urad": (300,)}, "X", "no run of at least 3 cycles"),
        (
            {"nan_at": [1300 + 1000 * k for k in range(25)]},
            "X",
            r"pa_x has 25 lost \(NaN\) samples.*no run of at least 2",
        ),
    ],
)
def test_analysis_errors_name_the_problem(tmp_path, kw, axis, match):
    path = write_sweep(tmp_path / "bad.h5", **kw)
    with pytest.raises(ValueError, match=match):
        analyze_file(path, axis)


def test_a_lost_frame_inside_the_cycles_is_analysed_around(tmp_path):
    """Issue 36 item 2: a dropped ADC frame (6 samples lost) inside the kept cycles lost the
    whole sweep. Now the cycles within the filters' reach of it are left out, the rest
    analysed: the same To and eta, and the warning says what was lost and left out."""
    whole = analyze_file(write_sweep(tmp_path / "whole.h5", noise_Nm=2e-4), "X")
    res = analyze_file(
        write_sweep(tmp_path / "lost.h5", noise_Nm=2e-4, nan_at=slice(4000, 4006)), "X"
    )
    assert res.To_Nm == pytest.approx(whole.To_Nm, rel=0.02) and res.To_Nm == pytest.approx(
        0.012, rel=0.02
    )
    assert res.eta_per_Nm == pytest.approx(whole.eta_per_Nm, rel=0.05)
    assert [lp.n_cycles for lp in res.loops] == [
        2,
        4,
        4,
        4,
        4,
    ]  # the frame was in the 500 urad cycles
    assert any(
        "pa_x has 6 lost (NaN) samples" in w and "2 of 4 cycles" in w for w in res.warnings
    ), res.warnings


def test_hostile_content_in_a_valid_file_is_refused_by_name(tmp_path):
    """Issue 36 item 7: a string inertia in /meta/calibration (TypeError deep in the fit) and a
    channel scaled by 1e300 (OverflowError) crashed ``fbs analyze hysteresis``."""
    import h5py

    path = write_sweep(tmp_path / "string.h5", meta_cal=False)
    odd = dataclasses.asdict(ODD_CAL)
    odd["platform"]["X"]["inertia_kg_m2"] = "heavy"
    with h5py.File(path, "a") as f:
        f.require_group("meta").attrs["calibration"] = json.dumps(odd)
    with pytest.raises(
        ValueError, match=r"platform.X.inertia_kg_m2 = 'heavy' must be a finite positive number"
    ):
        analyze_file(path, "X")
    path = tmp_path / "huge.h5"
    with RunWriter(
        path,
        rig="synthetic",
        mode=3,
        rate_hz=100.0,
        channels={"cmd_x": "V", "ac_x_inst": "V", "pa_x": "V"},
    ) as wr:
        x = np.sin(np.arange(4000) * 0.0251)
        wr.append(np.column_stack([x, x, 1e300 * x]))
    with pytest.raises(ValueError, match="pa_x reaches 1e.300 V"):
        analyze_file(path, "X")


def test_a_constant_command_is_not_a_sweep(tmp_path):
    path = tmp_path / "flat.h5"
    with RunWriter(
        path,
        rig="synthetic",
        mode=3,
        rate_hz=100.0,
        channels={"cmd_x": "V", "ac_x_inst": "V", "pa_x": "V"},
    ) as wr:
        wr.append(np.zeros((2000, 3)))
    with pytest.raises(ValueError, match="no sinusoid"):
        analyze_file(path, "X")
    with pytest.raises(ValueError, match="not an fbs-run file|no such file|cannot|No such"):
        analyze_file(tmp_path / "missing.h5", "X")


def test_figures_are_written(tmp_path):
    res = analyze_file(write_sweep(tmp_path / "s.h5", noise_Nm=1e-4), "X")
    for draw in (plot_loops, plot_describing_function, plot_history, plot_scan):
        out = draw(tmp_path / f"{draw.__name__}.png", res)
        assert out.stat().st_size > 10_000 and out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


# ---------------------------------------------------------------------------- fast: the CLI
def cli(argv: list[str]) -> int:
    """``fbs ...`` through the real parser once ``analyze`` is registered there, else through
    this module's ``add_parser`` on a parser of its own (the same dispatch as cli.main)."""
    from fbs import cli as fbs_cli

    parser = fbs_cli.build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    if "analyze" in sub.choices:
        return fbs_cli.main(argv)
    parser = argparse.ArgumentParser(prog="fbs")
    analyze.add_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except ValueError as exc:
        print(f"fbs {args.command}: error: {exc}")
        return 2


def test_cli_json_prints_the_figures_their_intervals_and_the_lag(tmp_path, capsys):
    path = write_sweep(tmp_path / "s.h5")
    assert cli(["analyze", "hysteresis", str(path), "--axis", "X", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    keys = ["To_Nm", "eta_per_Nm", "stiffness_Nm_per_rad"]
    head = [
        "analysis",
        "procedure",
        "status",
        "verdict",
        "rig",
        "simulated",
        "sim_config",
        "software",
        "time",
    ]
    assert list(out) == [
        *head,
        *keys,
        *(f"{k}_ci95" for k in keys),
        "resolved",
        "angle_lag_ms",
        "file",
    ]
    assert_valid_result(out)
    # a file written without a rig's provenance: its rig attribute, simulated not stated
    assert out["verdict"] == "pass" and out["procedure"] is None and out["simulated"] is None
    To, eta, stiff = (out[key]["X"] for key in keys)  # per axis, as resolved (issue 37)
    assert out["file"] == str(path) and To == pytest.approx(0.012, rel=0.01)
    assert stiff == pytest.approx(eta * To**2)
    assert out["resolved"] == {k: {"X": True} for k in keys}
    for k in keys:
        lo, hi = out[f"{k}_ci95"]["X"]
        assert lo < out[k]["X"] < hi
    assert out["angle_lag_ms"] == pytest.approx(LAG_S * 1e3, abs=0.05)


def test_cli_human_output_and_out_dir(tmp_path, capsys):
    path = write_sweep(tmp_path / "s.h5")
    assert cli(["analyze", "hysteresis", str(path), "--out", str(tmp_path / "o")]) == 0
    text = capsys.readouterr().out
    assert "To" in text and "eta" in text and "stiffness eta To^2" in text and "500 urad" in text
    names = sorted(p.name for p in (tmp_path / "o").iterdir())
    assert names == [
        "s-x-describing-function.png",
        "s-x-history.png",
        "s-x-loops.png",
        "s-x-path-scan.png",
        "s-x.md",
    ]


def test_cli_errors_exit_2(tmp_path, capsys):
    path = write_sweep(tmp_path / "s.h5")
    assert cli(["analyze", "hysteresis", str(path), "--axis", "Z"]) == 2
    cap = capsys.readouterr()
    assert "no instrumentation autocollimator" in cap.out + cap.err


# ---------------------------------------------------------------------------- fast: the procedure
def test_procedure_is_catalogued_and_plans_a_ladder():
    assert catalogue()["hysteresis"] is Hysteresis
    proc = Hysteresis(Params(axis="y", amplitudes_urad=[400, 40, 4], cycles=3))
    assert proc.axis == "Y" and proc.channels() == ("cmd_y", "ac_y_inst", "pa_y", "ac_y_ctl")
    assert proc.json_keys == ("To_Nm", "eta_per_Nm", "stiffness_Nm_per_rad", "angle_lag_ms", "file")
    assert proc.update_s * proc.rate_hz == pytest.approx(round(proc.update_s * proc.rate_hz))
    steps = list(proc.plan())
    assert [s.name for s in steps] == ["mode 3", "400 urad", "40 urad", "4 urad", "bias off"]
    # every step runs again on --resume: the fit needs the whole ladder in one recording
    assert all(s.setup for s in steps)
    assert steps[1].expected_s == pytest.approx(4 / 0.4)


@pytest.mark.parametrize(
    "kw, match",
    [
        ({"axis": "Z"}, "no instrumentation"),
        ({"amplitudes_urad": []}, "non-empty"),
        ({"amplitudes_urad": [10, -1]}, "positive"),
        ({"cycles": 1}, "cycles"),
        ({"updates_per_cycle": 3}, "too coarse"),
        ({"rate_hz": 500.0}, "whole number"),
        ({"angle_lag_ms": 80.0}, "angle_lag_ms"),
    ],
)
def test_params_are_checked(kw, match):
    with pytest.raises(ValueError, match=match):
        Params(**kw)


# ---------------------------------------------------------------------------- slow: the rig
def run_on_sim(tmp_path, config_text: str | None = None, axis="X", seed=3):
    from drivers.rig import open_rig
    from procedures.runner import run_procedure

    url = f"sim?warm=1&seed={seed}"
    if config_text is not None:
        cfg = tmp_path / "sim.toml"
        cfg.write_text(config_text)
        url += f"&config={cfg}"
    wall = time.monotonic()
    with open_rig(url) as rig:
        s = run_procedure(Hysteresis(Params(axis=axis)), rig, tmp_path / "out")
    wall = time.monotonic() - wall
    assert s.file is not None, s.error
    with RunFile(s.file) as rf:
        rig_s = rf.duration_s
    print(f"hysteresis {axis}: {s.values} in {rig_s:.0f} s of rig time, {wall:.1f} s wall")
    return s, rig_s, wall


def check(values, To, eta, axis="X"):
    assert values["To_Nm"][axis] == pytest.approx(To, rel=TO_TOL)
    assert values["eta_per_Nm"][axis] == pytest.approx(eta, rel=ETA_TOL)
    assert values["stiffness_Nm_per_rad"][axis] == pytest.approx(eta * To * To, rel=K_TOL)


def sim_lag_s(axis: str, freq_hz: float = 40.0) -> float:
    """The sim's instrument lag as the lines near ``freq_hz`` see it: the instrumentation
    channel's filters (eq. 3.22) and the motor's La/Ra, phase over w (for checking only: the
    procedure never reads the simulator)."""
    from simhw.config import SimConfig

    cfg = SimConfig()
    ac, pl = cfg.autocollimator[axis], cfg.platform[axis]
    w = 2 * math.pi * freq_hz
    r = w / ac.inst_filter2_rad_per_s
    phase = (
        math.atan(w / ac.inst_filter1_rad_per_s)
        + math.atan2(2 * ac.inst_filter2_zeta * r, 1 - r * r)
        + math.atan(w * pl.armature_H / pl.armature_ohm)
    )
    return phase / w


@pytest.mark.slow
def test_default_rig_acceptance_a(tmp_path, capsys):
    s, rig_s, wall = run_on_sim(tmp_path)
    assert s.status == "complete" and s.exit_code == 0, s.error
    check(s.values, 0.016, 1.6e6)
    # issue 18 acceptance B: with the lag measured by the procedure, eta and the stiffness within 1 %
    assert s.values["eta_per_Nm"]["X"] == pytest.approx(1.6e6, rel=THESIS_TOL)
    assert s.values["stiffness_Nm_per_rad"]["X"] == pytest.approx(1.6e6 * 0.016**2, rel=THESIS_TOL)
    assert s.values["angle_lag_ms"] == pytest.approx(sim_lag_s("X") * 1e3, abs=0.4)
    for key in ("To_Nm", "eta_per_Nm", "stiffness_Nm_per_rad"):
        assert s.values["resolved"][key] == {"X": True}
        lo, hi = s.values[f"{key}_ci95"]["X"]
        assert lo < s.values[key]["X"] < hi and hi - lo < 0.1 * s.values[key]["X"]
    # what `fbs run --json` prints (issue 37, acceptance A)
    printed = s.json_result(Hysteresis(Params(axis="X")))
    assert_valid_result(printed)
    assert printed["verdict"] == "pass" and printed["simulated"] is True
    assert rig_s < 300
    assert [m.passed for m in s.measurements if m.passed is not None] == [True] * 8
    assert any(
        m.name.startswith("angle lag") and m.value == pytest.approx(s.values["angle_lag_ms"])
        for m in s.measurements
    )
    # what was applied is on the file's time base: the command channel carries the ladder
    with RunFile(s.file) as rf:
        assert rf.attrs["axis"] == "X" and rf.meta["calibration"]["platform"]["X"]["amp_gain"] > 0
        cmd = rf.read(["cmd_x"])[0]
        assert np.max(np.abs(cmd)) == pytest.approx(500 * 5.70e-3, rel=0.01)
        assert abs(cmd[-100:]).max() == 0.0  # bias off at the end
    assert s.report.exists() and (s.report.parent / "hysteresis-loops.png").exists()
    # the analysis alone on the run's file gives the same numbers
    capsys.readouterr()
    assert cli(["analyze", "hysteresis", str(s.file), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert_valid_result(out)
    assert out["procedure"] == "hysteresis" and out["simulated"] is True
    assert out["rig"] == printed["rig"]
    assert out["To_Nm"]["X"] == pytest.approx(s.values["To_Nm"]["X"], rel=1e-9)
    assert out["eta_per_Nm_ci95"]["X"] == pytest.approx(s.values["eta_per_Nm_ci95"]["X"], rel=1e-9)
    with capsys.disabled():
        print(
            f"hysteresis X (default rig): {s.values} in {rig_s:.0f} s of rig time, {wall:.1f} s wall"
        )


def _random_configs(n: int, seed: int) -> list[tuple[str, float, float]]:
    rng = np.random.default_rng(seed)
    axes = ["X", "Y", "X"]
    return [
        (
            axes[i % 3],
            float(rng.uniform(0.008, 0.03)),
            float(math.exp(rng.uniform(math.log(0.8e6), math.log(3e6)))),
        )
        for i in range(n)
    ]


@pytest.mark.slow
@pytest.mark.parametrize("axis, To, eta", _random_configs(3, seed=20260521))
def test_random_bearings_acceptance_b(tmp_path, axis, To, eta):
    s, _, _ = run_on_sim(
        tmp_path, f"[bearing.{axis}]\nTo_Nm = {To!r}\neta_per_Nm = {eta!r}\n", axis=axis, seed=7
    )
    assert s.status == "complete", s.error
    check(s.values, To, eta, axis)


@pytest.mark.slow
def test_the_intervals_hold_a_stiff_light_axis_the_path_reads_high(tmp_path):
    """A stiff bearing on a light Y axis (a rig of ``bench/coverage_all.py``, seed 139): the
    angle path of least residual read the stiffness +2.7 % and eta +3.5 % high, both outside
    their intervals (the path drops the platform's motion above its bandwidth). The path with
    that motion taken from the drive bounds it (``hysteresis._drive_choice``)."""
    To, eta = 0.026918681612994683, 799623.0377466711
    s, _, _ = run_on_sim(
        tmp_path,
        f"[bearing.Y]\nTo_Nm = {To!r}\neta_per_Nm = {eta!r}\n"
        "[platform.Y]\ninertia_kg_m2 = 0.23841143635715306\n",
        axis="Y",
        seed=5,
    )
    assert s.status == "complete", s.error
    truth = {"To_Nm": To, "eta_per_Nm": eta, "stiffness_Nm_per_rad": eta * To * To}
    for key, value in truth.items():
        assert s.values["resolved"][key] == {"Y": True}
        lo, hi = s.values[f"{key}_ci95"]["Y"]
        assert lo <= value <= hi, (key, value, lo, hi)


@pytest.mark.slow
def test_abort_and_resume_runs_the_whole_ladder_again(tmp_path):
    """An interrupted sweep is redone on --resume: the fit needs one continuous ladder."""
    import threading

    from drivers.rig import open_rig
    from procedures.resume import load_resume
    from procedures.runner import run_procedure

    params = Params(amplitudes_urad=[400, 40, 8], cycles=2)
    abort = threading.Event()

    def listener(p):
        if p.step == "40 urad":
            abort.set()

    with open_rig("sim?warm=1&seed=5") as rig:
        s1 = run_procedure(Hysteresis(params), rig, tmp_path, progress=listener, abort=abort)
        assert s1.verdict == "aborted" and s1.status.startswith("aborted")
        assert s1.steps_done == ["mode 3", "400 urad"]
        assert rig.is_safe()
        resume = load_resume(s1.file, Hysteresis)
        s2 = run_procedure(
            Hysteresis(Hysteresis.params_from(resume.params)), rig, tmp_path, resume=resume
        )
    assert s2.status == "complete" and s2.steps_resumed == []
    assert s2.steps_done == ["mode 3", "400 urad", "40 urad", "8 urad", "bias off"]
    assert s2.values["To_Nm"]["X"] == pytest.approx(0.016, rel=TO_TOL)


def test_the_half_width_is_t_at_the_welch_satterthwaite_dof():
    """GUM G.4: one part gives its own t; equal parts pool their degrees of freedom; a bound
    (infinite dof) gives the normal quantile."""
    from scipy import stats

    from procedures.analysis.hysteresis import _half_width

    assert _half_width([(1.0, 5)]) == pytest.approx(stats.t.ppf(0.975, 5))
    assert _half_width([(1.0, 5), (1.0, 5)]) == pytest.approx(stats.t.ppf(0.975, 10) * math.sqrt(2))
    assert _half_width([(0.3, math.inf)]) == pytest.approx(0.3 * stats.norm.ppf(0.975))
    assert _half_width([(1.0, 5), (2.0, math.inf)]) == pytest.approx(
        stats.t.ppf(0.975, 25 * 5) * math.sqrt(5)
    )
