"""``fbs analyze hysteresis`` on records it did not make (issue 38 items 1 and 7).

Item 7: a sweep recorded by another system - a smooth sinusoidal command (no DAC staircase),
float32, its own chunking - came back with every figure unresolved ("the angle's lag ... could
not be measured"); at another drive frequency the smooth command's leakage was taken for lines
and an 8.9 ms lag (3.5 ms true) biased eta 4 % low outside its interval. Item 1: on an axis
without bearing friction the fit pinned To to the edge of its search and printed it resolved
with the value on its interval's edge. The files come from ``hysteresis_holdout`` (the offline
simulator's plant, written with plain h5py), none through our procedure.
"""

from __future__ import annotations

import json
import math

import pytest

from procedures.analysis.hysteresis import analyze_file
from procedures.analysis.intervals import judged
from procedures.calibrations.hysteresis import HysteresisParams, fit_quality
from tests.procedures.hysteresis_holdout import write_smooth_sweep
from tests.procedures.test_hysteresis import cli

KEYS = ("To_Nm", "eta_per_Nm", "stiffness_Nm_per_rad")


@pytest.mark.parametrize(
    "kw",
    [
        # the hold-out's bearing and drive (DESIGN.md section 3 defaults, 0.4 Hz)
        {"To_Nm": 0.016, "eta_per_Nm": 1.6e6},
        # another bearing, drive, ladder, rate and recorder; no /meta/calibration (the data sheet's)
        {
            "To_Nm": 0.009,
            "eta_per_Nm": 2.8e6,
            "freq_hz": 0.25,
            "amplitudes_urad": (900, 400, 150, 50, 20, 8),
            "cycles": 5,
            "rate_hz": 500.0,
            "seed": 5,
            "meta_calibration": False,
            "chunk": 777,
            "compression": None,
        },
    ],
    ids=["holdout", "other-drive"],
)
def test_a_smooth_sweep_from_another_recorder_is_resolved(tmp_path, kw, capsys, monkeypatch):
    path = write_smooth_sweep(tmp_path / "sweep.h5", **kw)
    truth = {
        "To_Nm": kw["To_Nm"],
        "eta_per_Nm": kw["eta_per_Nm"],
        "stiffness_Nm_per_rad": kw["eta_per_Nm"] * kw["To_Nm"] ** 2,
    }
    res = analyze_file(path, "X")
    # no line in a smooth command: the lag is fitted with To and eta, near the instruments' own
    # (the filters' and La/Ra's 3.5 ms; the simulator's held friction torque adds ~0.5 ms)
    assert res.lag_source == "fitted" and res.lag is None
    assert 2.5e-3 < res.angle_lag_s < 5e-3, res.angle_lag_s
    for key in KEYS:
        e = res.estimates[key]
        assert e.resolved, (key, e)
        assert e.lo < e.value < e.hi
        print(f"{key}: {e.value:.5g} [{e.lo:.5g}, {e.hi:.5g}] truth {truth[key]:.5g}")
    # eta and the stiffness (what the lag moves) cover the truth; To, which the lag hardly
    # moves, lies within 1 % (our simulator holds the friction torque over its step: +0.4 %)
    for key in ("eta_per_Nm", "stiffness_Nm_per_rad"):
        assert res.estimates[key].covers(truth[key]), (key, res.estimates[key], truth[key])
    assert res.To_Nm == pytest.approx(truth["To_Nm"], rel=0.01)
    capsys.readouterr()
    monkeypatch.setenv("OMP_NUM_THREADS", "2")  # the jackknife's replicates on two threads
    assert cli(["analyze", "hysteresis", str(path), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["resolved"] == {k: {"X": True} for k in KEYS}
    # the suite's one thread above, two here: the same figures and intervals to the bit
    one = json.loads(json.dumps(res.values()))
    assert {k: out[k] for k in one} == one


@pytest.mark.parametrize("model, extra", [("none", {}), ("viscous", {"damping_Nms": 0.05})])
def test_no_dahl_friction_resolves_nothing(tmp_path, model, extra, capsys):
    """A bearing without friction, or a viscous one, driven by our procedure's staircase (so
    the lag is measured at its lines): To, eta and eta To^2 unresolved, the reason given, the
    interval [0, inf] - never a figure at the edge of a zero-width interval."""
    path = write_smooth_sweep(
        tmp_path / "sweep.h5",
        bearing_model=model,
        updates_per_cycle=100,
        cycles=4,
        amplitudes_urad=(500, 100, 20, 5),
        **extra,
    )
    res = analyze_file(path, "X")
    for key in KEYS:
        e = res.estimates[key]
        assert not e.resolved and (
            "no friction of eq. 5.2" in e.why or "edge of its search" in e.why
        ), (key, e)
        assert e.lo == 0.0 and e.hi == math.inf
    v = res.values()
    assert all(v[k] == {"X": None} for k in KEYS) and v["resolved"] == {
        k: {"X": False} for k in KEYS
    }
    # the procedure's checks judge no error of a figure it did not resolve (a zero-width fit
    # once read "To relative standard error 0 ... pass" on a rig without friction)
    quality = {m.name: m for m in fit_quality(res, HysteresisParams(axis="X"))}
    for name in ("To relative standard error", "eta relative standard error"):
        assert quality[name].value is None and quality[name].passed is not True, quality[name]
    capsys.readouterr()
    assert cli(["analyze", "hysteresis", str(path), "--json"]) == 1
    out = json.loads(capsys.readouterr().out)
    assert out["To_Nm_ci95"] == {"X": [0.0, None]}


@pytest.mark.parametrize(
    "lo, hi, why",
    [
        (2.0, 2.0, "zero width"),
        (2.0, 2.5, "on the edge"),
        (1.0, 2.0, "on the edge"),
        (2.5, 3.0, "outside"),
    ],
)
def test_a_degenerate_interval_is_never_resolved(lo, hi, why):
    """Issue 38 item 1: [v, v] passed the rule (its width 0 is under the magnitude)."""
    e = judged(2.0, lo, hi)
    assert not e.resolved and why in e.why
    assert judged(2.0, 1.9, 2.1).resolved
