"""Requirement 5: the catalogue is open. An effect module the search has never seen, dropped
into the effects package's path, is found, fitted and named without any other edit."""

from __future__ import annotations

import sys
import textwrap

import pytest

from procedures.analysis.gap.workflow import analyse
from simhw import effects

pytestmark = pytest.mark.slow

MODULE = '''
"""``gyro_pickup``: electrical pickup on the axis's gyro pickoff channel (a test's effect)."""
from simhw.effects import Effect, Param
from simhw.config import PickupLine


def _apply(cfg, axis, freq_hz, amplitude_V):
    cfg.pickup.append(PickupLine(f"gyro_{axis.lower()}", freq_hz, amplitude_V))
    return cfg


EFFECT = Effect("gyro_pickup", "pickup on the gyro channel",
                (Param("freq_hz", 50.0, 1.0, 450.0, log=True), Param("amplitude_V", 0.01, 1e-4, 0.1, log=True)),
                _apply, key_param="freq_hz", guess=lambda ev: [{"freq_hz": f} for f in ev.peaks_hz[:4]])
'''


@pytest.fixture
def extra_effect(tmp_path, monkeypatch):
    (tmp_path / "gyro_pickup.py").write_text(textwrap.dedent(MODULE))
    monkeypatch.setattr(effects, "__path__", list(effects.__path__) + [str(tmp_path)])
    yield
    sys.modules.pop("simhw.effects.gyro_pickup", None)


def test_a_new_effect_module_is_found_and_named(extra_effect, hidden, tmp_path):
    assert "gyro_pickup" in effects.catalogue()
    run = hidden(tmp_path / "run.h5", ["gyro_pickup:freq_hz=33,amplitude_V=0.02"], seed=21)
    j = analyse(run).to_json()
    assert j["effect"] == "gyro_pickup", j["candidates"][:3]
    assert j["parameters"]["freq_hz"] == pytest.approx(33, rel=0.02)
    assert "gyro_pickup" in [c["effect"] for c in j["candidates"]]
