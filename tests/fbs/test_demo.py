"""``fbs demo``'s campaign report: every figure beside the thesis's and the simulated rig's value.
(The campaign itself is the procedures run in order; `make demo` runs it end to end.)"""

from __future__ import annotations

from pathlib import Path

from fbs.demo import CAMPAIGN, sim_values, write_campaign_report
from procedures.runner import RunSummary
from simhw.params import SimConfig


def _summary(name: str, values: dict, **params) -> RunSummary:
    return RunSummary(name, Path(f"{name}.h5"), "complete", "pass", values=values, params=params,
                      report=Path(f"{name}.md"))


def test_report_sets_each_figure_beside_thesis_and_sim(tmp_path):
    cfg = SimConfig()
    cfg.gyro["X"].torquer_scale_urad_per_s_per_V = 30.0
    runs = [_summary("earth-rate", {"K_TO_urad_per_s_per_V": {"X": 30.3}, "drift_urad_per_s": {"X": 0.3}}),
            _summary("hysteresis", {"To_Nm": {"Y": 0.0158}, "eta_per_Nm": {"Y": 1.7e6},
                                    "stiffness_Nm_per_rad": {"Y": 424.0}}, axis="Y"),
            _summary("survey", {"platform_rms_urad": {"X": 1.3}, "dip_hz": {"X": 3.84}})]
    text = write_campaign_report(tmp_path, runs, sim_values(cfg), 100.0, 0).read_text()
    assert "| K_TO X | urad/s/V | 30.3 | 31.6 | 30 | +1.00 % |" in text
    assert "| To Y | N m | 0.0158 | 0.016 | 0.016 | -1.25 % |" in text
    assert "| closed-loop dip X | Hz | 3.84 | 3.5 |" in text
    assert "| gyro-deduced platform rms X | urad | 1.3 | 1.6 |" in text


def test_campaign_covers_every_procedure():
    from procedures.calibrations import catalogue
    assert {name for name, _, _ in CAMPAIGN} == set(catalogue())


def test_report_sets_the_baseline_beside_table_1(tmp_path):
    values = {"nea_urad": {"ctl": 0.447, "inst": 0.567, "z": 2.79},
              "nea_urad_ci95": {"ctl": [0.443, 0.451], "inst": [0.56, 0.57], "z": [2.7, 2.9]},
              "pickoff_lines_hz": [70.6, 71.4, 102.0, 187.0]}
    text = write_campaign_report(tmp_path, [_summary("baseline", values, axis="X")], sim_values(SimConfig()), 1.0,
                                 0).read_text()
    assert "| autocollimator NEA 0.1-100 Hz X ctl | urad | 0.447 | 0.451 | 0.451 |" in text
    assert "found 70.600, 71.400, 102.000, 187.000" in text


def test_the_survey_runs_after_the_baseline_and_sets_its_net_figure_beside_the_thesis(tmp_path):
    """Issue 22 part 6: the survey takes the baseline's pickoff spectrum out of the gyro's, so the
    baseline runs first; the report sets the thesis method, the net figure and the coherent part
    beside the thesis's 1.6 / 3.6 urad, an unresolved one as such."""
    order = [name for name, _, _ in CAMPAIGN]
    assert order.index("baseline") < order.index("survey")
    values = {"platform_rms_urad": {"X": 0.73, "Y": 3.21},
              "platform_rms_baseline_net_urad": {"X": 0.447, "Y": None},
              "platform_rms_baseline_net_urad_ci95": {"X": [0.42, 0.472], "Y": [0.0, 1.13]},
              "resolved": {"platform_rms_baseline_net_urad": {"X": True, "Y": False}},
              "baseline": {"file": "baseline.h5", "axis": "X"}}
    text = write_campaign_report(tmp_path, [_summary("survey", values)], sim_values(SimConfig()), 1.0, 0).read_text()
    assert "| gyro-deduced platform rms X | urad | 0.73 | 1.6 |" in text
    assert "| platform rms X, net of the baseline's pickoff noise | urad | 0.447 | 1.6 |" in text
    assert "95 % [0.42, 0.472]" in text
    assert "| platform rms Y, net of the baseline's pickoff noise | urad | - | 3.6 |" in text
    assert "not resolved: 95 % [0, 1.13]" in text
