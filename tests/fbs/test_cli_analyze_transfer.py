"""``fbs analyze transfer`` (DESIGN.md section 7): H1 or the injected-signal estimate, the
tabulated response with intervals, the fitted model, and its errors; on a file made here
without ``simhw`` (white noise through eq. 3.28 written out again, in the frequency domain)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from daq.runfile import RunWriter
from fbs.cli import main

FS = 1000.0


def _network(f):
    s = 2j * np.pi * f
    return (
        -(s / 10 + 1)
        * (s / 30 + 1)
        / ((s / 0.15 + 1) * (s / 200 + 1) * (s / 1200 + 1) * (s / 5000 + 1))
    )


@pytest.fixture
def net_file(tmp_path):
    n = int(96 * FS)
    rng = np.random.default_rng(4)
    ac = rng.standard_normal(n) * 3e-3
    pa = (
        np.fft.irfft(np.fft.rfft(ac) * _network(np.fft.rfftfreq(n, 1 / FS)), n)
        + rng.standard_normal(n) * 1e-6
    )
    path = tmp_path / "net.h5"
    with RunWriter(
        path, rig="test", mode=3, rate_hz=FS, channels={"ac_x_ctl": "V", "pa_x": "V"}
    ) as w:
        w.append({"ac_x_ctl": ac, "pa_x": pa})
    return path


def test_transfer_json_has_the_measured_table_and_the_network_fit(net_file, capsys):
    assert (
        main(["analyze", "transfer", str(net_file), "--from", "ac_x_ctl", "--to", "pa_x", "--json"])
        == 0
    )
    out = json.loads(capsys.readouterr().out)
    assert out["model"] == "network" and out["via"] is None and out["blocks"] == 8
    m = out["measured"]
    f = np.array(m["f_hz"])
    truth = 20 * np.log10(np.abs(_network(f)))
    lo, hi = np.array(m["gain_db_ci95"]).T
    assert np.mean((lo <= truth) & (truth <= hi)) > 0.8
    table = out["fit"]["response"]
    d = np.array(table["gain_db"]) - 20 * np.log10(np.abs(_network(np.array(table["f_hz"]))))
    assert np.max(np.abs(d)) < 0.5
    assert out["fit"]["resolved"]["gain"] is False and out["fit"]["gain"] is None


def test_transfer_text_and_plot(net_file, tmp_path, capsys):
    assert (
        main(
            [
                "analyze",
                "transfer",
                str(net_file),
                "--from",
                "ac_x_ctl",
                "--to",
                "pa_x",
                "--fit",
                "none",
                "--out",
                str(tmp_path / "o"),
            ]
        )
        == 0
    )
    text = capsys.readouterr().out
    assert "ac_x_ctl -> pa_x" in text and "fit over" not in text
    assert (tmp_path / "o" / "net-ac_x_ctl-pa_x.png").stat().st_size > 0


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--to", "pa_q"], "no channel pa_q"),
        (["--to", "pa_x", "--seg-s", "32"], "fewer than 8 blocks"),
        (["--to", "pa_x", "--start", "200"], "leave no samples"),
        (["--to", "pa_x", "--period", "16", "--blocks", "8"], "period"),
    ],
)
def test_transfer_bad_input_is_exit_2_naming_it(net_file, capsys, extra, message):
    assert main(["analyze", "transfer", str(net_file), "--from", "ac_x_ctl", *extra]) == 2
    assert message in capsys.readouterr().err
