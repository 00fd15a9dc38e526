"""``bench/coverage_all.py``'s own parts (issue 38 acceptance A): the rig distribution it
documents gives valid sim configs that really vary what it says, and its table counts what the
records hold. (The harness's campaigns are a benchmark, hours long: never run here.)"""

from __future__ import annotations

import importlib
import json
import subprocess
import sys
from pathlib import Path

import pytest

from drivers.rig_datasheet import VISCOUS_COUPLING_TOLERANCE
from simhw.config import SimConfig, load_config

BENCH = Path(__file__).resolve().parents[2] / "bench"


@pytest.fixture(scope="module")
def harness():
    sys.path.insert(0, str(BENCH))
    try:
        yield importlib.import_module("coverage_all")
    finally:
        sys.path.remove(str(BENCH))


def test_the_drawn_rigs_are_valid_and_span_the_documented_distribution(harness, tmp_path):
    nom = SimConfig()
    cfgs = []
    for seed in range(60):  # as the harness hands each rig to the sim: a TOML file
        path = tmp_path / f"rig{seed}.toml"
        path.write_text(harness.toml_of(harness.draw_rig(seed)))
        cfgs.append(load_config(path))
    lat = [c.site.latitude_deg for c in cfgs]
    assert min(lat) < -30 and max(lat) > 50  # southern and northern sites
    assert max(abs(c.table.base_azimuth_offset_deg) for c in cfgs) > 4
    for axis in ("X", "Y", "Z"):  # every bearing model on every axis
        assert {c.bearing[axis].model for c in cfgs} == {"none", "viscous", "spring", "dahl"}
    knees = [c.autocollimator["X"].flicker_knee for c in cfgs]
    assert min(knees) < 0.2 and max(knees) == 1.0  # both knee forms and between
    assert max(c.autocollimator["X"].common_noise_fraction for c in cfgs) > 0.4
    for c in cfgs:
        assert (
            c.autocollimator["X"].common_noise_fraction
            == c.autocollimator["Y"].common_noise_fraction
        )
        for ch in ("X", "Y", "Z", "XRD"):
            g, g0 = c.gyro[ch], nom.gyro[ch]
            assert (
                0.85 <= g.torquer_scale_urad_per_s_per_V / g0.torquer_scale_urad_per_s_per_V <= 1.15
            )
            assert all(
                abs(f - f0) <= 1.0 for (f, _), (f0, _) in zip(g.pickoff_lines, g0.pickoff_lines)
            )
    # the floats' viscous coupling over the data sheet's tolerance, which the intervals carry
    coupling = [
        c.gyro[ch].viscous_coupling_h_over_c / nom.gyro[ch].viscous_coupling_h_over_c
        for c in cfgs
        for ch in ("X", "Y", "Z", "XRD")
    ]
    tol = VISCOUS_COUPLING_TOLERANCE
    assert 1 - tol <= min(coupling) < 0.8 and 1.2 < max(coupling) <= 1 + tol
    assert harness.draw_rig(7) == harness.draw_rig(7)  # a seed is one rig


def _row(q, measured, iv, truth, resolved=True, exact=True):
    covered = None if iv is None else iv[0] <= truth <= iv[1]
    return {
        "quantity": q,
        "measured": measured,
        "interval": iv,
        "resolved": resolved,
        "truth": truth,
        "truth_kind": "parameter" if exact else "describing function",
        "truth_exact": exact,
        "covered": covered,
    }


def test_the_table_counts_coverage_errors_and_unresolved_per_figure(harness):
    recs = [
        {
            "seed": 0,
            "rows": [
                _row("K_TO X", 1.01, [0.99, 1.03], 1.0),
                _row("bearing stiffness at 2.1 urad rms X", 100.0, [90.0, 110.0], 120.0),
                _row("c1 X", 5.0, [4.0, 6.0], 5.5, exact=False),
            ],
        },
        {
            "seed": 1,
            "rows": [
                _row("K_TO X", 1.10, [1.05, 1.15], 1.0),
                _row("bearing stiffness at 1.9 urad rms X", None, [0.0, 300.0], 120.0, False),
            ],
        },
        {"seed": 2, "error": "RuntimeError: boom"},
    ]
    text = harness.table(recs)
    lines = {ln.split(" | ")[0].lstrip("| "): ln for ln in text.splitlines() if ln.startswith("|")}
    assert "| 2 | 2 | 1/2 | 5.5 / 10 % |" in lines["K_TO X"]
    # the run's own amplitude is not part of the figure's name
    assert "| 2 | 2 | 1/2 |" in lines["bearing stiffness at the test amplitude X"]
    assert lines["bearing stiffness at the test amplitude X"].endswith("| 1/2 |")
    assert "c1 X" in lines and "describing" in text
    assert "figures with an interval and an exact truth: 4, covered 2" in text
    assert "1 ended in an error" in text and "seed 2: RuntimeError: boom" in text
    assert "seed 1: K_TO X" in harness.misses(recs)


def test_an_extended_campaign_keeps_the_records_already_in_its_out_file(tmp_path):
    """``--first`` extends a campaign into the same ``--out``: the pool appends. It opened the
    file for writing, and a 33-rig campaign's records were gone when 7 more rigs were added."""
    out = tmp_path / "campaign.jsonl"
    out.write_text(json.dumps({"seed": 1, "verdict": "kept"}) + "\n")
    code = (
        "import sys; sys.path.insert(0, sys.argv[1]); from coverage_pool import run_cases; "
        "run_cases(dict, [([('seed', 2)],)], 1, sys.argv[2])"
    )
    subprocess.run(
        [sys.executable, "-c", code, str(BENCH), str(out)], check=True, capture_output=True
    )
    assert [json.loads(line)["seed"] for line in out.read_text().splitlines()] == [1, 2]
