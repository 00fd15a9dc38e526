"""``fbs run`` through the real console script: exit codes and ``--json`` keys exactly as
DESIGN.md section 7 (acceptance D), a real SIGINT and ``--resume`` (C), the default rig's
K_TO and K_g (A); and Ctrl-C or a device fault during every procedure (C)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from pathlib import Path

import pytest

from daq.reader import RunFile
from drivers.rig import open_rig
from procedures.calibrations import catalogue
from procedures.params import parse_params
from procedures.runner import run_procedure
from tests.fbs.commands import FBS, RIG
from tests.result_schema import assert_valid_result

KTO = {"X": 31.6, "Y": 33.4, "Z": 34.1, "XRD": 32.0}
KG = {"X": 6.03, "Y": 6.70, "Z": 7.51, "XRD": 5.74}
#: what every --json result starts with (issue 37: what ran, how it ended, on which rig)
HEAD = ["procedure", "status", "verdict", "rig", "simulated", "sim_config", "software", "time"]


def fbs(*args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    return subprocess.run([*FBS, *args], capture_output=True, text=True, timeout=timeout)


def test_bad_parameters_exit_2_before_the_rig_moves(tmp_path):
    r = fbs("run", "earth-rate", "--out", str(tmp_path), "--param", "n_spindle=2")
    assert r.returncode == 2 and "n_spindle = 2 must be 4..36" in r.stderr
    r = fbs("run", "stopwatch", "--out", str(tmp_path), "--param", "nonsense=1")
    assert r.returncode == 2 and "unknown parameter(s) nonsense" in r.stderr
    r = fbs("run", "earth-rate", "--out", str(tmp_path), "--axis", "X")
    assert r.returncode == 2 and "--axis does not apply" in r.stderr
    r = fbs(
        "run", "earth-rate", "--rig", "serial:///dev/null?can=virtual:x", "--sim-config", "a.toml"
    )
    assert r.returncode == 2 and "--sim-config applies to the simulated rig only" in r.stderr
    assert not list(tmp_path.glob("*.h5"))


@pytest.mark.slow
def test_limits_failed_exits_1_with_the_json_keys(tmp_path):
    r = fbs(
        "run",
        "earth-rate",
        "--rig",
        RIG,
        "--out",
        str(tmp_path),
        "--json",
        "--param",
        "n_spindle=4",
        "--param",
        "tilts_deg=[0, 90, 45]",
        "--param",
        "average_s=20",
        "--param",
        "kto_tolerance=1e-6",
    )
    assert r.returncode == 1, r.stderr
    out = json.loads(r.stdout)
    figures = [
        "K_TO_urad_per_s_per_V",
        "drift_urad_per_s",
        "g_drift_x_urad_per_s_per_g",
        "g_drift_y_urad_per_s_per_g",
        "g_drift_z_urad_per_s_per_g",
    ]
    assert list(out) == [*HEAD, *figures, "file", *(f"{k}_ci95" for k in figures), "resolved"]
    assert (out["procedure"], out["verdict"], out["status"]) == ("earth-rate", "fail", "complete")
    assert out["rig"] == RIG and out["simulated"] is True
    assert_valid_result(out)
    for k in figures:
        assert (
            set(out[f"{k}_ci95"])
            == set(out[k])
            == set(out["resolved"][k])
            == {"X", "Y", "Z", "XRD"}
        )
        for ch, v in out[k].items():
            assert (v is None) == (
                not out["resolved"][k][ch]
            )  # an unresolved figure is no bare number
    assert Path(out["file"]).exists()


@pytest.mark.slow
def test_sigint_resume_and_the_default_rig(tmp_path):
    """Ctrl-C mid-run -> exit 2, file aborted, rig safe; --resume completes it; K_TO within 0.5 %
    and (stopwatch, using that K_TO from --out) K_g within 2 % of the default rig's values."""
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    with subprocess.Popen(
        [*FBS, "run", "earth-rate", "--rig", RIG, "--out", str(tmp_path), "--json"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    ) as p:
        try:
            path = tmp_path / "earth-rate.h5"
            t_end = time.monotonic() + 300
            done = 0
            while done < 4 and time.monotonic() < t_end and p.poll() is None:
                time.sleep(0.5)
                if path.exists():
                    try:
                        with RunFile(path) as rf:
                            done = sum(e.kind == "step-done" for e in rf.events)
                    except OSError:
                        pass  # between the file's creation and its first flush
            assert done >= 4, "the run did not get going"
            p.send_signal(signal.SIGINT)
            stdout, stderr = p.communicate(timeout=120)
        finally:
            p.kill()  # a failure above must not leave the run going
    assert p.returncode == 2, stderr
    figures = [
        "K_TO_urad_per_s_per_V",
        "drift_urad_per_s",
        "g_drift_x_urad_per_s_per_g",
        "g_drift_y_urad_per_s_per_g",
        "g_drift_z_urad_per_s_per_g",
    ]
    # an abort keeps every figure's shape: per channel, each None, unresolved (issue 37)
    out = json.loads(stdout)
    assert_valid_result(out)
    assert (out["verdict"], out["status"]) == ("aborted", "aborted: interrupted")
    assert out["file"] == str(path)
    for k in figures:
        assert out[k] == dict.fromkeys(KTO) and out[f"{k}_ci95"] == dict.fromkeys(KTO)
        assert out["resolved"][k] == dict.fromkeys(KTO, False)
    with RunFile(path) as rf:
        assert rf.status == "aborted: interrupted"
        safe = [e for e in rf.events if e.kind == "safe"]
        n_done = sum(e.kind == "step-done" for e in rf.events)
    assert safe and safe[-1].text == "safe state reached"
    summary = json.loads((tmp_path / "earth-rate.json").read_text())
    assert summary["verdict"] == "aborted" and len(summary["steps_done"]) == n_done

    r = fbs(
        "run", "earth-rate", "--rig", RIG, "--out", str(tmp_path), "--json", "--resume", str(path)
    )
    assert r.returncode == 0, r.stderr
    er = json.loads(r.stdout)
    assert_valid_result(er)
    assert list(er)[: len(HEAD) + len(figures) + 1] == [*HEAD, *figures, "file"]
    assert er["file"].endswith("earth-rate-2.h5")
    resumed = json.loads((tmp_path / "earth-rate-2.json").read_text())
    assert len(resumed["steps_resumed"]) == n_done - 1  # every data step done before the abort
    for ch, kto in KTO.items():
        assert er["K_TO_urad_per_s_per_V"][ch] == pytest.approx(kto, rel=5e-3)

    r = fbs("run", "stopwatch", "--rig", RIG, "--out", str(tmp_path), "--json")
    assert r.returncode == 0, r.stderr
    sw = json.loads(r.stdout)
    assert list(sw)[len(HEAD) : len(HEAD) + 3] == ["K_g_mV_per_urad", "h_over_k_s", "file"]
    assert_valid_result(sw)
    for ch, kg in KG.items():
        assert sw["K_g_mV_per_urad"][ch] == pytest.approx(kg, rel=2e-2)
        assert sw["K_g_mV_per_urad_ci95"][ch][0] <= kg <= sw["K_g_mV_per_urad_ci95"][ch][1]
        assert sw["resolved"]["K_g_mV_per_urad"][ch] and not sw["resolved"]["h_over_k_s"][ch]
    assert "(earth-rate)" in (tmp_path / "stopwatch.md").read_text()  # the measured K_TO was used


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(catalogue()))
@pytest.mark.parametrize("how", ["ctrl-c", "fault"])
def test_every_procedure_aborts_to_the_safe_state(tmp_path, name, how):
    """Ctrl-C (a KeyboardInterrupt on the procedure's thread, as SIGINT raises it) or a device
    fault during the first data step: rig safe, file "aborted: <why>", summary says what was done."""
    cls = catalogue()[name]
    with open_rig(RIG) as rig:
        proc = cls(parse_params(cls, [], None))
        calls = []

        def interrupt(p):
            calls.append(p.index)
            if p.index >= 1 and len([i for i in calls if i >= 1]) >= 2:
                if how == "ctrl-c":
                    raise KeyboardInterrupt
                rig.emulator.inject("adc", "disconnect")

        s = run_procedure(proc, rig, tmp_path, progress=interrupt)
        assert s.exit_code == 2 and s.verdict == "aborted"
        # what `fbs run --json` prints: every figure in its shape, {channel: None} (issue 37)
        out = s.json_result(proc)
        assert_valid_result(out)
        assert out["simulated"] is True and out["rig"] == RIG and out["procedure"] == name
        assert all(v is None for k in proc.headline() for v in out[k].values())
        assert rig.is_safe() and rig.emulator.nodes.nodes["relay"].mode == 1
        assert s.status == ("aborted: interrupted" if how == "ctrl-c" else s.status)
        assert s.status.startswith("aborted: ") and (how == "ctrl-c" or "DeviceLost" in s.status)
        with RunFile(s.file) as rf:
            assert rf.status == s.status
        assert s.steps_done and len(s.steps_done) < len(s.steps_planned)
        assert "Steps not done" in s.report.read_text()
