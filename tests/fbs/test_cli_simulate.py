"""``fbs simulate`` and ``fbs demo`` through the real console script (DESIGN.md section 7)."""

import subprocess

import h5py
import numpy as np
import pytest

from daq.spectral import psd
from simhw.plant import CHANNELS
from tests.fbs.commands import FBS


def run(*args, cwd=None):
    return subprocess.run([*FBS, *args], capture_output=True, text=True, cwd=cwd, timeout=300)


def test_simulate_writes_every_channel_and_the_truth_in_the_run_layout(tmp_path):
    out = tmp_path / "m3.h5"
    r = run(
        "simulate",
        "--mode",
        "3",
        "--duration",
        "20",
        "--rate",
        "500",
        "--truth",
        "--seed",
        "4",
        "--out",
        str(out),
    )
    assert r.returncode == 0, r.stderr
    with h5py.File(out, "r") as f:
        assert f.attrs["format"] == "fbs-run" and f.attrs["format_version"] == 1
        assert f.attrs["mode"] == 3 and f.attrs["status"] == "complete"
        assert "created" in f.attrs and f.attrs["rig"]
        g = f["channels"]
        assert set(CHANNELS) | {"theta_x", "theta_y", "theta_z"} == set(g)
        for name in g:
            assert g[name].shape == (10000,)
            assert g[name].attrs["sample_rate_hz"] == 500.0
        assert g["theta_x"].attrs["units"] == "rad" and g["gyro_x"].attrs["units"] == "V"
        theta = g["theta_x"][()]
        inst = g["ac_x_inst"][()] / 5.63e3  # rad
    # The true angle is what the instrumentation channel sees, up to its noise (0.6 urad).
    assert 1e-8 < theta.std() < 5e-6
    assert np.corrcoef(theta[1000:], inst[1000:])[0, 1] > 0.3


def test_simulate_with_an_injected_pickup_line_shows_it_in_the_spectrum(tmp_path):
    out = tmp_path / "line.h5"
    r = run(
        "simulate",
        "--mode",
        "3",
        "--duration",
        "30",
        "--rate",
        "1000",
        "--out",
        str(out),
        "--effect",
        "pickup_line:freq_hz=200,amplitude_V=0.003",
    )
    assert r.returncode == 0, r.stderr
    with h5py.File(out, "r") as f:
        x = f["channels/ac_x_ctl"][()]
        assert "pickup_line" in f["events"][-1]["text"].decode()
    f_, p = psd(x, 1000.0, seg_s=4.0)
    k = np.argmin(np.abs(f_ - 200.0))
    assert p[k] > 100 * np.median(p[(f_ > 150) & (f_ < 250)])


def test_same_seed_same_file_contents(tmp_path):
    for name in ("a.h5", "b.h5"):
        assert (
            run(
                "simulate",
                "--mode",
                "3",
                "--duration",
                "5",
                "--rate",
                "200",
                "--seed",
                "7",
                "--out",
                str(tmp_path / name),
            ).returncode
            == 0
        )
    with h5py.File(tmp_path / "a.h5") as a, h5py.File(tmp_path / "b.h5") as b:
        for c in CHANNELS:
            assert np.array_equal(a["channels"][c][()], b["channels"][c][()])


@pytest.mark.parametrize(
    "toml, message",
    [
        ("[gyro.X]\nbogus_key = 1\n", "unknown key 'gyro.X.bogus_key'"),
        ('[bearing.Y]\nmodel = "glue"\n', "bearing.Y.model = 'glue'"),
        ("[platform.X]\ninertia_kg_m2 = -0.7\n", "platform.X.inertia_kg_m2 = -0.7 is out of range"),
        ("[wobble]\nx = 1\n", "unknown key 'wobble'"),
    ],
)
def test_bad_sim_config_is_an_error_that_names_the_key(tmp_path, toml, message):
    cfg = tmp_path / "c.toml"
    cfg.write_text(toml)
    r = run(
        "simulate",
        "--mode",
        "3",
        "--duration",
        "1",
        "--rate",
        "100",
        "--sim-config",
        str(cfg),
        "--out",
        str(tmp_path / "x.h5"),
    )
    assert r.returncode == 2
    assert message in r.stderr
    assert not (tmp_path / "x.h5").exists()


def test_sim_config_overrides_reach_the_plant(tmp_path):
    cfg = tmp_path / "c.toml"
    cfg.write_text(
        "[gyro.X]\ntorquer_scale_urad_per_s_per_V = 20.0\nfixed_drift_urad_per_s = 0.0\n"
        "[table]\nbase_azimuth_offset_deg = 0.0\n"
    )
    out = tmp_path / "o.h5"
    assert (
        run(
            "simulate",
            "--mode",
            "3",
            "--duration",
            "2",
            "--rate",
            "50",
            "--sim-config",
            str(cfg),
            "--out",
            str(out),
        ).returncode
        == 0
    )
    with h5py.File(out) as f:
        vt = f["channels/torq_x"][()].mean()
    # Caged: V_T = -Omega cos(lat) / KTO at spindle 0 with KTO = 20 urad/s/V.
    assert vt == pytest.approx(-7.292115e-5 * np.cos(np.radians(37.43)) / 20e-6, rel=2e-3)


@pytest.mark.parametrize(
    "args, message",
    [
        (
            ["--mode", "3", "--duration", "-1", "--rate", "100"],
            "--duration -1.0 must be a finite number > 0",
        ),
        (
            ["--mode", "3", "--duration", "1", "--rate", "0"],
            "--rate 0.0 must be a finite number > 0",
        ),
        (
            ["--mode", "3", "--duration", "nan", "--rate", "100"],
            "--duration nan must be a finite number > 0",
        ),
        (
            ["--mode", "3", "--duration", "inf", "--rate", "100"],
            "--duration inf must be a finite number > 0",
        ),
        (
            ["--mode", "3", "--duration", "1e-4", "--rate", "200"],
            "0.02 samples; at least 2 are needed",
        ),
        (
            ["--mode", "3", "--duration", "1", "--rate", "1e12"],
            "beyond the 100000 Hz this command can deliver",
        ),
        (["--mode", "3", "--duration", "1e12", "--rate", "200"], "GB free"),
        (
            [
                "--mode",
                "3",
                "--duration",
                "1",
                "--rate",
                "100",
                "--effect",
                "bearing_friction:To_Nm=9",
            ],
            "To_Nm = 9.0 outside its range",
        ),
    ],
)
def test_bad_arguments_fail_with_a_clear_message(tmp_path, args, message):
    r = run("simulate", *args, "--out", str(tmp_path / "x.h5"))
    assert r.returncode == 2
    assert message in r.stderr


def test_a_mode_not_among_the_choices_is_a_usage_error(tmp_path):
    """argparse refuses it: the usage code (64), not the 2 of a bad value."""
    r = run(
        "simulate",
        "--mode",
        "7",
        "--duration",
        "1",
        "--rate",
        "100",
        "--out",
        str(tmp_path / "x.h5"),
    )
    assert r.returncode == 64 and "invalid choice" in r.stderr


def test_an_existing_file_is_never_replaced_unless_forced_and_never_one_being_written(tmp_path):
    """Issue 19 item 2: ``--out`` over a finished recording, or one a writer is still filling,
    and a bad argument over an existing file: the file is left as it was."""
    out = tmp_path / "x.h5"
    assert (
        run(
            "simulate", "--mode", "3", "--duration", "2", "--rate", "100", "--out", str(out)
        ).returncode
        == 0
    )
    before = out.read_bytes()
    for extra in ([], ["--duration", "nan"]):
        args = ["--mode", "3", "--duration", "2", "--rate", "100", *extra]
        r = run("simulate", *args, "--out", str(out))
        assert r.returncode == 2 and out.read_bytes() == before, r.stderr
    assert (
        "exists; a recording is never overwritten"
        in run(
            "simulate", "--mode", "3", "--duration", "2", "--rate", "100", "--out", str(out)
        ).stderr
    )
    r = run(
        "simulate",
        "--mode",
        "3",
        "--duration",
        "3",
        "--rate",
        "100",
        "--seed",
        "2",
        "--out",
        str(out),
        "--force",
    )
    assert r.returncode == 0, r.stderr
    with h5py.File(out, "r") as f:
        assert f["channels/gyro_x"].shape == (300,)
    with h5py.File(out, "r+") as f:  # as a writer that has not finished leaves it
        f.attrs["status"] = "recording"
    before = out.read_bytes()
    r = run(
        "simulate", "--mode", "3", "--duration", "2", "--rate", "100", "--out", str(out), "--force"
    )
    assert r.returncode == 2 and "not replaced, even with --force" in r.stderr
    assert out.read_bytes() == before


def test_a_diverging_plant_stops_with_where_and_when(tmp_path):
    """Issue 19 item 4: an unstable configuration used to write NaN as 0.0 V and exit 0."""
    cfg = tmp_path / "unstable.toml"
    cfg.write_text("[platform.X]\namp_gain = 1e9\n")
    out = tmp_path / "x.h5"
    r = run(
        "simulate",
        "--mode",
        "3",
        "--duration",
        "5",
        "--rate",
        "200",
        "--sim-config",
        str(cfg),
        "--out",
        str(out),
    )
    assert r.returncode == 2
    assert "the simulation diverged at t = " in r.stderr and " V (beyond 1e+06 V" in r.stderr
    with h5py.File(out, "r") as f:
        assert f.attrs["status"].startswith("aborted: SimulationDiverged")
