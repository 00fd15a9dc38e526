"""``fbs demo``'s campaign report: every figure beside the thesis's (with where the thesis states
it) and the simulated rig's truth at the conditions measured, with its 95 % interval and whether
that holds the truth; a header naming the date, software, commit and rig.
(The campaign itself is the procedures run in order; `make demo` runs it end to end. The coverage
test reads a recorded campaign's summaries, ``tests/data/demo``, instead of running it again.)"""

from __future__ import annotations

import json
import math
import re
import shutil
from pathlib import Path

import pytest

from fbs.demo import (
    SimTruth,
    campaign,
    coverage,
    figure_rows,
    load_summaries,
    write_campaign_report,
)
from fbs.demo_truth import binomial_tail, dahl_equivalent_linear, in_interval, max_misses
from procedures.procedure import Verdict
from procedures.reports import thesis
from procedures.runner import RunSummary
from simhw.config import SimConfig
from simhw.plant import linearized_poles

RECORDED = Path(__file__).resolve().parent.parent / "data" / "demo"


def _summary(name: str, values: dict, **params) -> RunSummary:
    return RunSummary(
        name,
        Path(f"{name}.h5"),
        "complete",
        Verdict.PASS,
        values=values,
        params=params,
        report=Path(f"{name}.md"),
    )


def _row(text: str, quantity: str) -> list[str]:
    """The cells of the report's row for ``quantity`` (after the row number)."""
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip("|").split("|")]
        if len(cells) > 2 and cells[1] == quantity:
            return cells[1:]
    raise AssertionError(f"no row {quantity!r} in the report")


def test_report_sets_each_figure_beside_thesis_and_sim(tmp_path):
    cfg = SimConfig()
    cfg.gyro["X"].torquer_scale_urad_per_s_per_V = 30.0
    runs = [
        _summary(
            "earth-rate",
            {
                "K_TO_urad_per_s_per_V": {"X": 30.3},
                "drift_urad_per_s": {"X": 0.3},
                "K_TO_urad_per_s_per_V_ci95": {"X": [30.0, 30.6]},
            },
        ),
        _summary(
            "hysteresis",
            {
                "To_Nm": {"Y": 0.0158},
                "eta_per_Nm": {"Y": 1.7e6},
                "stiffness_Nm_per_rad": {"Y": 424.0},
            },
            axis="Y",
        ),
        _summary("survey", {"platform_rms_urad": {"X": 1.3}, "dip_hz": {"X": 3.84}}),
    ]
    text = write_campaign_report(tmp_path, runs, SimTruth(cfg), 100.0, 0).read_text()
    assert _row(text, "K_TO X")[:8] == [
        "K_TO X",
        "urad/s/V",
        "30.3",
        "[30, 30.6]",
        "31.6",
        "30",
        "+1.00 %",
        "yes",
    ]
    assert _row(text, "To Y")[2:7] == ["0.0158", "-", "0.016", "0.016", "-1.25 %"]
    assert _row(text, "closed-loop dip X")[2:4] == ["3.84", "-"]
    assert _row(text, "closed-loop dip X")[4] == "3.5"
    # the platform rms has its simulated truth: the true angle's rms from an offline run of the rig
    rms = _row(text, "gyro-deduced platform rms X (thesis method)")
    assert rms[2] == "1.3" and rms[4] == "1.6" and 0.3 < float(rms[5]) < 0.6
    assert "Ch. V E.2, p. 138" in text and "Ch. II C.1.a(1)" in text


def test_campaign_covers_every_procedure_in_the_order_their_results_need():
    """Issue 40 item 1: the campaign is the catalogue's, each procedure saying its runs and its
    place (``demo_runs``, ``demo_order``); nothing else lists them."""
    from procedures.calibrations import catalogue

    runs = campaign()
    assert {name for name, _, _ in runs} == set(catalogue())
    order = [name for name, _, _ in runs]
    assert order == [
        "earth-rate",
        "stopwatch",
        "hysteresis",
        "hysteresis",
        "baseline",
        "survey",
        "excitation",
        "excitation",
        "drift",
    ]
    assert runs[7] == (
        "excitation",
        "X",
        ("mode=4", "quiet_s=64", "excite_s=160", "mode_settle_s=40"),
    )


def test_report_sets_the_baseline_beside_table_1(tmp_path):
    """Issue 37 item 11: the X instrumentation NEA's thesis value is Table 1's X figure (0.610),
    not its Y one (0.550, which Ch. V B.3 also gives for X: the report says so); the simulated
    instrumentation NEA is the rig's noise through that channel's filters."""
    values = {
        "nea_urad": {"ctl": 0.447, "inst": 0.567, "z": 2.79},
        "nea_urad_ci95": {"ctl": [0.443, 0.451], "inst": [0.56, 0.57], "z": [2.7, 2.9]},
        "pickoff_lines_hz": [70.6, 71.4, 102.0, 187.0],
    }
    text = write_campaign_report(
        tmp_path, [_summary("baseline", values, axis="X")], SimTruth(SimConfig()), 1.0, 0
    ).read_text()
    assert _row(text, "autocollimator NEA 0.1-100 Hz X ctl")[2:6] == [
        "0.447",
        "[0.443, 0.451]",
        "0.451",
        "0.451",
    ]
    inst = _row(text, "autocollimator NEA 0.1-100 Hz X inst")
    assert (
        inst[4] == "0.61" and 0.55 < float(inst[5]) < 0.6
    )  # wider filters than the control channel's
    assert "Table 1, p. 40" in text and "the thesis is inconsistent for X" in text
    assert "found 70.600, 71.400, 102.000, 187.000" in text
    assert (
        thesis.BASELINE["nea_urad"]["X"]["inst"] == 0.610
        and thesis.BASELINE["nea_urad"]["Y"]["inst"] == 0.550
    )


def test_the_survey_runs_after_the_baseline_and_sets_its_net_figure_beside_the_thesis(tmp_path):
    """Issue 22 part 6: the survey takes the baseline's pickoff spectrum out of the gyro's, so the
    baseline runs first; the report sets the thesis method, the net figure and the coherent part
    beside the thesis's 1.6 / 3.6 urad, an unresolved one as such."""
    order = [name for name, _, _ in campaign()]
    assert order.index("baseline") < order.index("survey")
    values = {
        "platform_rms_urad": {"X": 0.73, "Y": 3.21},
        "platform_rms_baseline_net_urad": {"X": 0.447, "Y": None},
        "platform_rms_baseline_net_urad_ci95": {"X": [0.42, 0.472], "Y": [0.0, 1.13]},
        "resolved": {"platform_rms_baseline_net_urad": {"X": True, "Y": False}},
        "baseline": {"file": "baseline.h5", "axis": "X"},
        "record_s": 60.0,
    }
    text = write_campaign_report(
        tmp_path, [_summary("survey", values)], SimTruth(SimConfig()), 1.0, 0
    ).read_text()
    assert _row(text, "gyro-deduced platform rms X (thesis method)")[2] == "0.73"
    net = _row(text, "platform rms X, net of the baseline's pickoff noise")
    assert net[2:5] == ["0.447", "[0.42, 0.472]", "1.6"]
    assert _row(text, "platform rms Y, net of the baseline's pickoff noise")[2:5] == [
        "-",
        "not resolved: [0, 1.13]",
        "3.6",
    ]


def test_the_recorded_campaigns_intervals_cover_the_simulated_truth(tmp_path):
    """Issue 37 item 11 and issue 38 item 8: on a whole campaign's figures (recorded from `fbs
    demo`, seed 0), every figure row with a measured value or a bound has a simulated truth (the
    platform rms included), and the rows whose interval excludes their exact truth are no more
    than 95 % intervals allow (binomial, 1 % level); the describing-function rows are counted
    apart. The header names the date, software version and commit, and the rig."""
    shutil.copytree(RECORDED, tmp_path, dirs_exist_ok=True)
    summaries = load_summaries(tmp_path)
    assert [s.procedure for s in summaries] == [name for name, _, _ in campaign()]
    sim = SimTruth(SimConfig(), 0)
    rows = figure_rows(summaries, sim)
    figures = [r for r in rows if r.measured is not None or r.interval is not None]
    # the only rows with no truth are comparisons, not figures of the rig: the network against its
    # design, the cross-axis coherence
    untrue = [r.quantity for r in figures if r.simulated is None]
    assert all(
        q.startswith(("compensation network vs design", "X-Y autocollimator coherence"))
        for q in untrue
    ), untrue
    assert all(r.simulated is not None for r in rows if "platform rms" in r.quantity)
    exact, missed, approx, _ = coverage(rows)
    n, k = len(exact), len(missed)
    assert n >= 50
    assert k <= max_misses(n), [(r.quantity, r.measured, r.interval, r.simulated) for r in missed]
    # the Mode-3 stiffness is counted: its truth is what the run's fit measures on the bearing at
    # the run's own level (an offline run); the Mode-4 one, the six roots and the two Dahl
    # dampings (no viscous damping describes hysteretic friction) are approximate
    stiffness = [r for r in exact if r.quantity.startswith("bearing stiffness")]
    assert len(stiffness) == 1 and stiffness[0].truth.kind == "offline"
    assert len(approx) == 9
    text = write_campaign_report(tmp_path, summaries, sim, 209.0, 0).read_text()
    assert f"{n} rows have a 95 % interval and an exact simulated truth" in text
    assert re.search(r"^- rig: `sim\?seed=0&watchdog=5` \(\*\*simulated\*\*\)$", text, re.M)
    assert re.search(r"^- software: fbs-hil \S+, commit \S+$", text, re.M)
    assert re.search(r"^- time: \d{4}-\d\d-\d\dT", text, re.M)
    # every thesis value in a row names where it stands
    assert all(r.thesis_source for r in rows if r.thesis is not None)


def test_amplitude_dependent_rows_take_the_bearing_at_the_test_amplitude():
    """Issue 38 item 8: the excitation's stiffness and the closed-loop roots are set beside the
    rig's Dahl bearing at the test's amplitude, not its small-motion spring eta To^2: the
    stiffness as the run's own fit measures the bearing at the run's own V_Td level (an offline
    run, ``dahl_equivalent_linear``), the roots with its describing function."""
    recorded = load_summaries(RECORDED)
    sim = SimTruth(SimConfig(), 0)
    excitation = [s for s in recorded if s.procedure == "excitation"]
    rows = {r.quantity: r for r in figure_rows(excitation, sim)}
    k0 = 1.6e6 * 0.016**2
    # labelled with the motion the run measured (its ``excitation_amplitude_urad``)
    stiff = next(
        r
        for q, r in rows.items()
        if q.startswith("bearing stiffness at ") and q.endswith(" urad rms X")
    )
    moved = excitation[0].values["excitation_amplitude_urad"]["X"]
    assert 1.0 < moved < 4.0 and "about" not in stiff.quantity
    assert stiff.truth is not None and stiff.truth.kind == "offline"
    eq = dahl_equivalent_linear(SimConfig(), "X", float(excitation[0].values["level_V_rms"]))
    assert (
        stiff.simulated == pytest.approx(eq.stiffness_Nm_per_rad)
        and eq.stiffness_Nm_per_rad < 0.995 * k0
    )
    small = sorted(abs(p) for p in linearized_poles(SimConfig(), 3, "X") if 100 < abs(p) < 150)
    c4 = rows["closed-loop root c4 X (Mode 3)"].simulated
    assert c4 is not None and abs(c4 - small[0]) > 0.1


def test_a_linear_loops_roots_have_an_exact_truth_the_loop_alone():
    """Issue 38: on a rig whose bearing is linear the closed-loop roots do not depend on the
    amplitude, and their truth is exact and counted: the nearest root of the axis's loop alone
    (``linearized_poles`` with the axis; in Mode 4 without the gyro's cross-axis coupling, as
    the procedure closes it). They were all filed as describing-function approximations, kept
    out of the coverage, with the Mode-4 pair's covered on 1 of 11 drawn linear rigs."""
    recorded = load_summaries(RECORDED)
    excitation = [s for s in recorded if s.procedure == "excitation"]
    cfg = SimConfig()
    cfg.bearing["X"].model = "spring"
    rows = figure_rows(excitation, SimTruth(cfg, 0))
    roots = [r for r in rows if r.quantity.startswith("closed-loop root")]
    assert len(roots) == 6
    for r in roots:
        mode = 4 if "(Mode 4)" in r.quantity else 3
        lin = linearized_poles(cfg, mode, "X")
        assert r.truth is not None and r.truth.kind == "computed" and r.truth.exact, r
        assert "loop alone" in r.truth.how
        assert any(abs(abs(p) - r.simulated) < 1e-9 for p in lin), (r.quantity, r.simulated)


def test_max_misses_is_the_binomial_bound():
    assert max_misses(53) == 7 and binomial_tail(8, 53) <= 0.01 < binomial_tail(7, 53)
    assert math.isclose(binomial_tail(0, 10), 1.0)


def test_an_open_ended_interval_is_not_counted_as_covering():
    """Hysteresis on a bearing without friction gives [0, inf): the data bound nothing, and
    such an "interval" holds every truth by construction. The report's coverage leaves it out
    (None), in memory (inf) and read back from a summary file (null) alike; a finite interval
    is counted either way."""
    assert in_interval(0.0, (0.0, math.inf)) is None
    assert in_interval(0.0, (0.0, None)) is None
    assert in_interval(-1.0, (-math.inf, 0.0)) is None
    assert in_interval(0.5, (0.0, 1.0)) is True and in_interval(2.0, (0.0, 1.0)) is False


def test_the_figures_table_is_strict_json_with_open_ends_null(tmp_path):
    """``figures.json`` (what a coverage audit reads) parses with any JSON reader: the
    hysteresis's "interval" [0, inf) on a bearing without friction is [0, null] there, and
    not counted as covering."""
    run = _summary(
        "hysteresis",
        {
            "To_Nm": {"X": None},
            "stiffness_Nm_per_rad": {"X": None},
            "stiffness_Nm_per_rad_ci95": {"X": [0.0, math.inf]},
            "resolved": {"stiffness_Nm_per_rad": {"X": False}},
        },
        axis="X",
    )
    write_campaign_report(tmp_path, [run], SimTruth(SimConfig()), 10.0, 0)

    def refuse(token: str) -> None:
        raise AssertionError(f"{token} in figures.json: not JSON")

    rows = json.loads((tmp_path / "figures.json").read_text(), parse_constant=refuse)
    open_ended = [r for r in rows if r["interval"] and r["interval"][1] is None]
    assert open_ended and all(r["covered"] is None for r in open_ended)
