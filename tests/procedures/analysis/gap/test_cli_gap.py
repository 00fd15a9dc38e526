"""``fbs gap`` on the command line: JSON keys, the report's model files and plots."""

from __future__ import annotations

import json

import pytest

from daq.reader import RunFile
from fbs.cli import main

pytestmark = pytest.mark.slow

KEYS = {
    "effect",
    "parameters",
    "significant",
    "gap_before_db",
    "gap_after_db",
    "candidates",
    "file",
}


def test_json_and_report(hidden, tmp_path, capsys):
    run = hidden(tmp_path / "run.h5", ["pickup_line:freq_hz=60,amplitude_V=0.005"], seed=9)
    report = tmp_path / "rep"
    assert main(["gap", str(run), "--json", "--report", str(report)]) == 0
    out = json.loads(capsys.readouterr().out)
    assert KEYS <= set(out)
    assert out["effect"] == "pickup_line" and out["significant"] is True
    assert out["parameters"]["freq_hz"] == pytest.approx(60, rel=0.01)
    assert out["parameters"]["amplitude_V"] == pytest.approx(0.005, rel=0.1)
    assert out["candidates"][0] == {"effect": "pickup_line", "score": out["candidates"][0]["score"]}
    assert [e["effect"] for e in out["effects"]] == ["pickup_line"]
    with RunFile(run) as measured:
        for name in ("model_before.h5", "model_after.h5"):
            with RunFile(report / name) as model:
                assert model.channels == measured.channels
                assert model.rate_hz == measured.rate_hz
                assert model.n_samples == measured.n_samples
                assert model.status == "complete"
                assert model.attrs["axis"] == "X"
    for name in ("spectra.png", "ratio.png", "gap.md"):
        assert (report / name).stat().st_size > 1000
    assert "pickup_line" in (report / "gap.md").read_text()


def test_text_output_on_a_nominal_run(hidden, tmp_path, capsys):
    run = hidden(tmp_path / "run.h5", seed=10)
    assert main(["gap", str(run)]) == 0
    out = capsys.readouterr().out
    assert "no significant departure" in out and "effect none" in out
