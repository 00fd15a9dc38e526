"""Acceptance B: the workflow on data it did not generate: runs from ``independent.py``
(Tustin integrator, FFT-synthesized noise, exact 1/f, its own ADC at +-10 V)."""

from __future__ import annotations

import pytest

from procedures.analysis.gap.workflow import analyse

pytestmark = pytest.mark.slow


def test_nominal_independent_runs_are_not_significant(independent, tmp_path):
    for seed in (1, 2):
        res = analyse(independent.generate(tmp_path / f"n{seed}.h5", seed=seed))
        j = res.to_json()
        assert (j["significant"], j["effect"]) == (False, "none"), [res.located[:3], res.steps]
        assert any("pa_x excluded" in w for w in res.warnings)  # 0.19 mV rms on a +-10 V range


@pytest.mark.parametrize(
    "kw, effect, key, value",
    [
        ({"stiffness_Nm_per_rad": 600.0}, "bearing_friction", "stiffness_Nm_per_rad", 600.0),
        ({"pickup": [(150.0, 0.004)]}, "pickup_line", "freq_hz", 150.0),
        ({"mount_freq_hz": 40.0, "mount_damping": 0.03}, "mount_resonance", "freq_hz", 40.0),
        ({"extra_flicker_corner_hz": 20.0}, "flicker_noise", "corner_hz", 20.0),
        (
            {"offset_jump_urad": 10.0, "offset_jump_interval_s": 40.0},
            "offset_jumps",
            "amplitude_urad",
            10.0,
        ),
    ],
)
def test_effects_in_independent_runs_are_named_and_closed(
    independent, tmp_path, kw, effect, key, value
):
    res = analyse(independent.generate(tmp_path / "run.h5", seed=3, **kw))
    j = res.to_json()
    assert j["effect"] == effect, (j["candidates"][:3], res.located[:3])
    assert j["parameters"][key] == pytest.approx(value, rel=0.15)
    assert j["gap_after_db"] <= 0.5 * j["gap_before_db"]


def test_three_mains_lines_are_three_pickup_lines(independent, tmp_path):
    """Issue 34 item 7: an effect may be present more than once; 60, 180 and 250 Hz lines are
    three ``pickup_line`` entries at their frequencies, and nothing else is named."""
    lines = [(60.0, 0.003), (180.0, 0.003), (250.0, 0.002)]
    j = analyse(independent.generate(tmp_path / "mains.h5", seed=4, pickup=lines)).to_json()
    assert [e["effect"] for e in j["effects"]] == ["pickup_line"] * 3, j["effects"]
    found = sorted(
        (e["parameters"]["freq_hz"], e["parameters"]["amplitude_V"]) for e in j["effects"]
    )
    for (f, a), (f_true, a_true) in zip(found, lines):
        assert f == pytest.approx(f_true, rel=0.01)
        assert a == pytest.approx(a_true, rel=0.15)
    assert j["explained"]
