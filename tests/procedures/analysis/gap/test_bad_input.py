"""Acceptance D: bad input to ``fbs gap`` is a clear error naming the problem (exit 2)."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from daq.runfile import RunWriter
from fbs.cli import main
from procedures.analysis.gap.grid import GapInputError
from procedures.analysis.gap.workflow import analyse


def _write(
    path,
    channels: dict[str, np.ndarray],
    *,
    axis: str | None = "X",
    mode: int = 3,
    rate: float = 1000.0,
    events: list[tuple[float, str, str]] = (),
):
    with RunWriter(
        path,
        rig="test",
        mode=mode,
        rate_hz=rate,
        channels=dict.fromkeys(channels, "V"),
        axis=axis,
        overwrite=True,
    ) as w:
        for t, kind, text in events:
            w.event(t, kind, text)
        w.append(channels)
    return path


def _noise(n: int, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).normal(0, 1e-3, n)


def _expect(path, *words, axis=None, capsys=None):
    with pytest.raises(GapInputError) as e:
        analyse(path, axis=axis)
    for w in words:
        assert w in str(e.value), str(e.value)
    argv = ["gap", str(path)] + (["--axis", axis] if axis else [])
    assert main(argv) == 2
    if capsys is not None:
        err = capsys.readouterr().err
        assert words[0] in err


def test_missing_channels_are_named(tmp_path, capsys):
    p = _write(tmp_path / "f.h5", {"ac_y_ctl": _noise(100_000), "cmd_x": np.zeros(100_000)})
    _expect(p, "missing channels", "ac_x_ctl", "gyro_x", "ac_y_ctl", capsys=capsys)


def test_unknown_axis_is_named(tmp_path, capsys):
    p = _write(tmp_path / "f.h5", {"ac_x_ctl": _noise(100_000)}, axis="Q")
    _expect(p, "unknown axis 'Q'", "X, Y and Z", capsys=capsys)
    p2 = _write(tmp_path / "g.h5", {"ac_x_ctl": _noise(100_000)})
    _expect(p2, "unknown axis 'W'", axis="W")


def test_a_file_without_axis_asks_for_one(tmp_path):
    p = _write(tmp_path / "f.h5", {"ac_x_ctl": _noise(100_000)}, axis=None)
    _expect(p, "no 'axis' attribute", "--axis")


def test_too_short_a_record_names_the_lowest_band_and_the_length_needed(tmp_path, capsys):
    p = _write(tmp_path / "f.h5", {"ac_x_ctl": _noise(30_000)})
    _expect(p, "record too short", "30.0 s", "0.25 Hz", "at least 73.7 s", capsys=capsys)


def test_nans_are_named_with_their_channel_count_and_time(tmp_path, capsys):
    x = _noise(100_000)
    x[12_345:12_355] = np.nan
    p = _write(tmp_path / "f.h5", {"ac_x_ctl": _noise(100_000, 1), "gyro_x": x})
    _expect(
        p,
        "gyro_x has 10 lost (NaN) samples: samples 12345..12354",
        "(12.345..12.354 s)",
        capsys=capsys,
    )


def test_a_mode_change_inside_the_record_is_refused(tmp_path):
    p = _write(
        tmp_path / "f.h5",
        {"ac_x_ctl": _noise(100_000)},
        events=[(0.0, "mode", "mode 3"), (42.0, "mode", "mode 4")],
    )
    _expect(p, "mode changes during the record", "42.000 s")


def test_not_a_run_file_and_no_file(tmp_path):
    bad = tmp_path / "x.h5"
    with h5py.File(bad, "w") as f:
        f["data"] = np.zeros(10)
    _expect(bad, "not a readable fbs-run file")
    _expect(tmp_path / "nope.h5", "no such file")


def test_a_channel_below_the_adc_resolution_is_excluded_with_a_warning(tmp_path):
    q = 20.0 / 65536
    rng = np.random.default_rng(3)
    coarse = np.round(rng.normal(0, 0.4 * q, 100_000) / q) * q  # mostly one code
    p = _write(tmp_path / "f.h5", {"pa_x": coarse})
    _expect(p, "no usable channel", "pa_x excluded", "within 3 LSB")
