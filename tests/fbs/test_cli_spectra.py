"""``fbs spectra FILE --channels a,b --out DIR`` (issue acceptance: App. A.8 plots).

Proved here: on a run with a 3.5 Hz tone (the X-axis dip frequency of Ch. V E) the command
writes decodable PSD and coherence PNGs and a CSV whose columns and numbers are those of
the Welch estimate; the tone's bin is among the points kept above three times their
octave band's average, while plain noise keeps almost nothing; the segment length follows
its rule; errors name what is wrong; the plots never import pyplot.
"""

from __future__ import annotations

import argparse
import csv
import sys

import matplotlib.image
import numpy as np
import pytest
import scipy.signal

from daq.plots import plot_coherence, plot_psd
from daq.runfile import RunWriter
from fbs import spectra
from procedures.analysis.channel_spectra import choose_nperseg, spectra_command

FS = 200.0
TONE_HZ = 3.5
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def tone_file(tmp_path_factory):
    """120 s at 200 Hz: a = 3.5 Hz tone + white noise (V); b = a low-passed + its own noise (rad)."""
    n = int(120 * FS)
    rng = np.random.default_rng(11)
    t = np.arange(n) / FS
    a = 0.02 * np.sin(2 * np.pi * TONE_HZ * t) + 0.01 * rng.standard_normal(n)
    num, den = scipy.signal.butter(2, 20.0, fs=FS)
    b = scipy.signal.lfilter(num, den, a) + 0.01 * rng.standard_normal(n)
    path = tmp_path_factory.mktemp("spectra") / "tone run.h5"
    with RunWriter(path, rig="test", mode=3, rate_hz=FS, channels={"a": "V", "b": "rad"}) as w:
        w.append(np.column_stack([a, b]))
    return path


@pytest.fixture(scope="module")
def result(tone_file, tmp_path_factory):
    return spectra_command(tone_file, ["a", "b"], tmp_path_factory.mktemp("out") / "plots")


def _assert_png(path, min_bytes=15_000):
    raw = path.read_bytes()
    assert raw[:8] == PNG_MAGIC
    assert len(raw) > min_bytes, f"{path.name} is only {len(raw)} bytes"
    img = matplotlib.image.imread(path)  # decodes the whole image
    assert img.shape[0] > 400 and img.shape[1] > 600
    assert img[..., :3].std() > 0.05  # not a blank canvas


def test_writes_psd_and_coherence_pngs(result):
    assert set(result.psd_png) == {"a", "b"} and set(result.coherence_png) == {("a", "b")}
    for p in [*result.psd_png.values(), *result.coherence_png.values()]:
        assert p.parent == result.out_dir
        _assert_png(p)
    assert sorted(p.name for p in result.out_dir.iterdir()) == [
        "coherence_a_b.png",
        "psd_a.png",
        "psd_b.png",
        "spectra.csv",
    ]


def test_csv_has_the_columns_and_numbers_of_the_estimate(result):
    with open(result.csv, newline="") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["f_hz", "psd_a", "psd_b", "coherence_a_b"]
    data = np.array(rows[1:], dtype=float)
    c = result.csd
    assert data.shape == (c.nfft // 2 + 1, 4)
    np.testing.assert_allclose(data[:, 0], c.f, rtol=1e-9)
    np.testing.assert_allclose(data[:, 1], c.psd("a"), rtol=1e-9)
    np.testing.assert_allclose(data[:, 2], c.psd("b"), rtol=1e-9)
    np.testing.assert_allclose(data[:, 3], c.coherence()[:, 0, 1], rtol=1e-9)


def test_the_tone_survives_as_a_kept_point_and_noise_keeps_almost_nothing(result):
    c = result.csd
    tone_bin = c.f[np.argmin(np.abs(c.f - TONE_HZ))]
    for ch in ("a", "b"):
        b = result.bands[ch]
        assert tone_bin in b.kept_f, f"{ch}: kept {b.kept_f}"
        assert np.all(np.abs(b.kept_f - TONE_HZ) < 4 * c.resolution_hz)  # only the tone's main lobe
    coh = c.coherence()[:, 0, 1]
    assert coh[np.argmin(np.abs(c.f - TONE_HZ))] > 0.95
    # the defaults: 2048-sample (10.24 s) segments, 22 of them at 50 % overlap
    assert (c.nperseg, c.segments_used, c.segments_skipped) == (2048, 22, 0)


def test_cli_func_prints_files_and_summary_and_defaults_the_out_dir(tone_file, capsys):
    p = argparse.ArgumentParser(prog="fbs")
    sub = p.add_subparsers(dest="command", required=True)
    spectra.add_parser(sub)
    args = p.parse_args(["spectra", str(tone_file), "--channels", "a,b", "--seg-s", "5"])
    assert args.func(args) == 0
    out = capsys.readouterr().out
    default = tone_file.with_name("tone run_spectra")
    for name in ("psd_a.png", "psd_b.png", "coherence_a_b.png", "spectra.csv"):
        assert f"wrote {default / name}" in out
        assert (default / name).exists()
    assert "1000-sample segments (5 s" in out and "resolution 0.2 Hz" in out
    assert "47 of 47 segments averaged, none skipped" in out


def test_unknown_channel_names_the_available_ones(tone_file, tmp_path):
    with pytest.raises(ValueError, match=r"has no channel gyro_x; its channels are a, b"):
        spectra_command(tone_file, ["a", "gyro_x"], tmp_path / "o")
    assert not (tmp_path / "o").exists()


def test_too_short_a_file_is_an_error(tmp_path):
    path = tmp_path / "short.h5"
    with RunWriter(path, rig="test", mode=3, rate_hz=FS, channels={"a": "V"}) as w:
        w.append(np.zeros((100, 1)))
    with pytest.raises(ValueError, match=r"100 samples .* fewer than one segment of 256"):
        spectra_command(path, ["a"], tmp_path / "o")
    with pytest.raises(OSError, match="no such file"):
        spectra_command(tmp_path / "missing.h5", ["a"], tmp_path / "o")


def test_segment_length_rule():
    assert choose_nperseg(3_600_000, 1000.0) == 8192  # nearest 2^k to 10 s
    assert choose_nperseg(30_000, 1000.0) == 4096  # 8192 gives only 6 segments
    assert choose_nperseg(1_000, 1000.0) == 256  # never below 256
    assert choose_nperseg(10**6, 1000.0, seg_s=2.5) == 2500  # --seg-s is taken as asked
    with pytest.raises(ValueError):
        choose_nperseg(10**6, 1000.0, seg_s=0)


def test_registered_in_fbs_main_exits_2_naming_channels(tone_file, tmp_path, capsys):
    from fbs import cli

    sub = next(a for a in cli.build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    assert "spectra" in sub.choices
    assert (
        cli.main(["spectra", str(tone_file), "--channels", "a,nope", "--out", str(tmp_path / "o")])
        == 2
    )
    err = capsys.readouterr().err
    assert "fbs spectra: error:" in err and "its channels are a, b" in err


def test_plots_leave_no_pyplot_state(tmp_path):
    had_pyplot = "matplotlib.pyplot" in sys.modules
    figures = len(sys.modules["matplotlib._pylab_helpers"].Gcf.figs) if had_pyplot else 0
    f = np.arange(513) * 0.5
    p = 1.0 + np.random.default_rng(0).exponential(1.0, f.size)
    _assert_png(
        plot_psd(tmp_path / "p.png", f, p, channel="x", units="m/s", dof=20.0, nperseg=1024),
        min_bytes=10_000,
    )
    _assert_png(
        plot_coherence(tmp_path / "c.png", f, p / p.max(), pair=("x", "y"), n_segments=10),
        min_bytes=10_000,
    )
    if had_pyplot:  # someone else imported it: at least no figure of ours is registered there
        assert len(sys.modules["matplotlib._pylab_helpers"].Gcf.figs) == figures
    else:
        assert "matplotlib.pyplot" not in sys.modules
